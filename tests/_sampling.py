"""Shared test helper: configurations drawn uniformly within a robot's joint limits."""

import math

import numpy as np

import jaxkin as jk


def sample_configurations(robot: jk.Robot, n: int, seed: int) -> np.ndarray:
    """``n`` configurations uniform within the joint limits; an unlimited revolute joint is drawn
    in [-pi, pi], an unlimited prismatic one in [-0.5, 0.5] m."""
    lo = np.asarray(robot.lower, dtype=np.float64).copy()
    hi = np.asarray(robot.upper, dtype=np.float64).copy()
    for i, kind in enumerate(robot.joint_kinds):
        span = math.pi if kind == "revolute" else 0.5
        lo[i] = lo[i] if np.isfinite(lo[i]) else -span
        hi[i] = hi[i] if np.isfinite(hi[i]) else span
    return lo + (hi - lo) * np.random.default_rng(seed).random((n, robot.dof))
