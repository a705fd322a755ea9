"""Random joint configurations: the one sampler used by the CLI, IK restarts, tests and benchmarks.

Configurations are drawn uniformly within each joint's limits. A side of a joint's range is
*unbounded* when it is infinite or its magnitude is at least :data:`UNBOUNDED_LIMIT` (real exported
files carry +-1.8e308 and similar stand-ins for "no limit"). Unbounded sides are replaced by the
finite box below, so a sample is always finite:

* revolute joints: ``[-pi, pi]``; prismatic joints: ``[-1, 1]`` metre;
* a joint bounded on one side only keeps that side and spans ``2 pi`` (or 2 m) from it, e.g.
  ``upper = -4`` with no lower limit gives ``[-4 - 2 pi, -4]``.

Free, ball and planar joints (:mod:`jaxkin.configuration`) are sampled on their manifold: a
uniformly distributed unit quaternion (a normalised Gaussian 4-vector) for free and ball
joints, a uniform angle in ``[-pi, pi)`` as ``(cos, sin)`` for planar joints, and their
translations (always unbounded) uniformly in ``[-1, 1]`` metre, the prismatic box above.
"""

from __future__ import annotations

import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import is_traced
from .errors import JaxkinError
from .model import Robot

__all__ = ["UNBOUNDED_HALF_WIDTH", "UNBOUNDED_LIMIT", "sample_configurations", "sampling_bounds"]

UNBOUNDED_LIMIT = 1e6
"""A joint limit whose magnitude is at least this (radians or metres) counts as no limit."""

UNBOUNDED_HALF_WIDTH = {
    "revolute": math.pi,
    "prismatic": 1.0,
    "free": 1.0,
    "ball": 1.0,
    "planar": 1.0,
}
"""Half width of the sampled range of a joint with no limit on either side (the entries of
free, ball and planar joints: translations in metres; their rotation entries are in [-1, 1])."""


def sampling_bounds(robot: Robot) -> tuple[Any, Any]:
    """The finite box ``(lo, hi)``, each of shape (nq,), that configurations are drawn from: the
    joint limits, with unbounded sides replaced as the module doc says.

    float64 numpy arrays for a concrete robot; JAX arrays of the robot's dtype when its leaves are
    traced (``jit`` over the robot).

    >>> import jaxkin as jk
    >>> lo, hi = jk.sampling_bounds(jk.robots.load("two_link_planar"))
    >>> bool((hi > lo).all())
    True
    """
    if is_traced(robot):
        xp, lo, hi = jnp, robot.lower, robot.upper
    else:
        xp = np
        lo = np.asarray(robot.lower, dtype=np.float64)
        hi = np.asarray(robot.upper, dtype=np.float64)
    w = xp.asarray([UNBOUNDED_HALF_WIDTH[k] for k in robot.joint_kinds], dtype=lo.dtype)
    free_lo = ~(xp.abs(lo) < UNBOUNDED_LIMIT)  # also True for NaN-free infinities
    free_hi = ~(xp.abs(hi) < UNBOUNDED_LIMIT)
    both = free_lo & free_hi
    new_lo = xp.where(both, -w, xp.where(free_lo, hi - 2 * w, lo))
    new_hi = xp.where(both, w, xp.where(free_hi, lo + 2 * w, hi))
    return new_lo, new_hi


def sample_configurations(robot: Robot, n: int, key: Any = 0, *, dtype: Any = None) -> jax.Array:
    """``n`` joint configurations drawn uniformly from :func:`sampling_bounds`; shape (n, nq).

    Free, ball and planar joints are drawn on their manifold (module doc): unit quaternions
    uniform over rotations, planar angles uniform.

    Args:
      robot: the robot.
      n: how many configurations (a Python int; static under ``jit``).
      key: a ``jax.random`` key or an int seed (default 0): the same key gives the same samples.
      dtype: float32 or float64 (default: the robot's).

    Works eagerly and inside ``jit``/``vmap`` (with a traced ``key``).

    >>> import jaxkin as jk
    >>> robot = jk.robots.load("puma560")
    >>> qs = jk.sample_configurations(robot, 1000, key=0)
    >>> qs.shape
    (1000, 6)
    >>> bool(((qs >= robot.lower) & (qs <= robot.upper)).all())
    True
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise JaxkinError(f"n must be a non-negative int (a number of configurations), got {n!r}.")
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        key = jax.random.key(int(key))
    dt = np.dtype(robot.dtype if dtype is None else dtype)
    lo, hi = sampling_bounds(robot)
    if robot.multi_dof_joints:
        key, key_rot = jax.random.split(key)
    u = jax.random.uniform(key, (int(n), robot.nq), dtype=dt)
    lo_, hi_ = jnp.asarray(lo, dtype=dt), jnp.asarray(hi, dtype=dt)
    # lo + (hi - lo) u can round past hi; clip so that bounded joints stay within their limits
    qs = jnp.clip(lo_[None] + (hi_ - lo_)[None] * u, lo_[None], hi_[None])
    if not robot.multi_dof_joints:
        return qs
    return _rotations(robot, qs, key_rot, dt)


def _rotations(robot: Robot, qs: jax.Array, key: Any, dt: Any) -> jax.Array:
    """``qs`` with the rotation entries of free, ball and planar joints drawn on their
    manifold: uniform unit quaternions, uniform planar angles."""
    seen: set = set()
    for j in robot.multi_dof_joints:
        kind, qi = robot.kinds[j], robot.q_index[j]
        if qi in seen:
            continue
        seen.add(qi)
        key, sub = jax.random.split(key)
        if kind == "planar":
            a = jax.random.uniform(sub, (qs.shape[0],), dt, -math.pi, math.pi)
            qs = qs.at[:, qi + 2].set(jnp.cos(a)).at[:, qi + 3].set(jnp.sin(a))
            continue
        g = jax.random.normal(sub, (qs.shape[0], 4), dt)
        g = g / jnp.linalg.norm(g, axis=1, keepdims=True)
        start = qi + 3 if kind == "free" else qi
        qs = qs.at[:, start : start + 4].set(g)
    return qs
