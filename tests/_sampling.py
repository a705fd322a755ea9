"""Shared test helpers: the library's configuration sampler, as float64 numpy arrays, and a numpy
draw for tests where the sampler is not under test (nothing compiled per (n, nq))."""

import numpy as np

import jaxkin as jk


def sample_configurations(robot: jk.Robot, n: int, seed: int) -> np.ndarray:
    """``n`` configurations (n, dof) from :func:`jaxkin.sample_configurations` with key ``seed``."""
    return np.array(jk.sample_configurations(robot, n, seed, dtype=np.float64))


def random_q(robot: jk.Robot, n: int, seed: int = 0) -> np.ndarray:
    """``n`` configurations in the limits (unbounded joints in [-pi, pi], free positions in
    [-1, 1], unit quaternions, unit (cos, sin) pairs), in numpy: nothing to compile."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(np.asarray(robot.lower, dtype=float), -np.pi)
    hi = np.minimum(np.asarray(robot.upper, dtype=float), np.pi)
    Q = rng.uniform(lo, hi, (n, robot.nq))
    for j in robot.multi_dof_joints:
        qi, kind = robot.q_index[j], robot.kinds[j]
        quat = {"free": slice(qi + 3, qi + 7), "ball": slice(qi, qi + 4)}.get(kind)
        if kind == "free":
            Q[:, qi : qi + 3] = rng.uniform(-1.0, 1.0, (n, 3))
        if quat is not None:
            g = rng.normal(size=(n, 4))
            Q[:, quat] = g / np.linalg.norm(g, axis=1, keepdims=True)
        if kind == "planar":
            a = rng.uniform(-np.pi, np.pi, n)
            Q[:, qi + 2], Q[:, qi + 3] = np.cos(a), np.sin(a)
    return Q
