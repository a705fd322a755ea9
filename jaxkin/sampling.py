"""Random joint configurations: the one sampler used by the CLI, IK restarts, tests and benchmarks.

:func:`sample_configurations` draws a batch at once; :func:`sample_rows` draws configurations and
joint velocities block by block as they are read (:class:`SampledRows`), for batches larger than
memory.

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
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import is_traced
from ._jit import eager
from .errors import JaxkinError
from .model import Robot

__all__ = [
    "SAMPLE_BLOCK",
    "UNBOUNDED_HALF_WIDTH",
    "UNBOUNDED_LIMIT",
    "SampledRows",
    "sample_configurations",
    "sample_rows",
    "sampling_bounds",
]

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

SAMPLE_BLOCK = 65536
"""Rows drawn per random key by :func:`sample_rows` (block ``b`` from ``fold_in(key, b)``)."""


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

    Works eagerly (one compiled program per robot, ``n`` and dtype, cached) and inside
    ``jit``/``vmap`` (with a traced ``key``).

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
    return _draw(robot, key, int(n), np.dtype(robot.dtype if dtype is None else dtype))


def _draw_kernel(robot: Robot, key: Any, n: int, dt: np.dtype) -> jax.Array:
    """The draw of :func:`sample_configurations` (arguments checked)."""
    lo, hi = sampling_bounds(robot)
    if robot.multi_dof_joints:
        key, key_rot = jax.random.split(key)
    u = jax.random.uniform(key, (n, robot.nq), dtype=dt)
    lo_, hi_ = jnp.asarray(lo, dtype=dt), jnp.asarray(hi, dtype=dt)
    # lo + (hi - lo) u can round past hi; clip so that bounded joints stay within their limits
    qs = jnp.clip(lo_[None] + (hi_ - lo_)[None] * u, lo_[None], hi_[None])
    if not robot.multi_dof_joints:
        return qs
    return _rotations(robot, qs, key_rot, dt)


_draw = eager(_draw_kernel, ("n", "dt"))
"""Called eagerly, one compiled program per (robot, n, dtype), cached with jaxkin's other
kernels (op by op, each ``jax.random`` primitive compiled on its own, 1-2 s per new shape);
traced inline inside the caller's ``jit``/``vmap``."""


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


# ---------------------------------------------------------------------- block sampling
class SampledRows:
    """``(n, width)`` random rows drawn block by block when read, never all at once.

    Block ``b`` (:data:`SAMPLE_BLOCK` rows) is ``draw(b)``, a function of the block index only,
    so a row depends on ``draw`` (its seed) and its index, not on ``n`` or on how the rows are
    read. Reading is by contiguous slices (``rows[start:stop]``, a numpy array of ``dtype``), as
    :func:`jaxkin.batch.chunked_map` reads a row source; the last block read is kept, so
    reading in order draws each block once. :func:`sample_rows` makes them.
    """

    def __init__(
        self, n: int, width: int, dtype: Any, draw: Callable[[int], Any], start: int = 0
    ) -> None:
        self.shape = (n - start, width)
        self.dtype = np.dtype(dtype)
        self._n, self._draw, self._start = n, draw, start
        self._cache: tuple[int, np.ndarray] | None = None

    def __len__(self) -> int:
        return self.shape[0]

    def tail(self, k: int) -> SampledRows:
        """The rows from ``k`` on (the same rows, drawn from the same blocks)."""
        return SampledRows(self._n, self.shape[1], self.dtype, self._draw, self._start + k)

    def _block(self, b: int) -> np.ndarray:
        if self._cache is None or self._cache[0] != b:
            self._cache = (b, np.asarray(self._draw(b), dtype=self.dtype))
        return self._cache[1]

    def __getitem__(self, rows: slice) -> np.ndarray:
        if not isinstance(rows, slice) or rows.step not in (None, 1):
            raise TypeError("SampledRows reads contiguous slices only, e.g. rows[0:100]")
        start, stop, _ = rows.indices(self.shape[0])
        lo, hi = start + self._start, max(stop, start) + self._start
        blocks = range(lo // SAMPLE_BLOCK, -(-hi // SAMPLE_BLOCK))
        parts = [
            self._block(b)[max(lo - b * SAMPLE_BLOCK, 0) : hi - b * SAMPLE_BLOCK] for b in blocks
        ]
        return np.concatenate([np.empty((0, self.shape[1]), self.dtype), *parts])


def sample_rows(
    robot: Robot, n: int, seed: int, qd_scale: float, dtype: Any
) -> tuple[SampledRows, SampledRows]:
    """``(q, qd)``: ``n`` random configurations ``(n, nq)`` and joint velocities ``(n, nv)``,
    :class:`SampledRows` of ``dtype`` drawn :data:`SAMPLE_BLOCK` rows at a time when read (so
    millions of them never sit in memory), as ``jaxkin velocities`` samples them.

    ``q`` as :func:`sample_configurations` draws it (within the limits; unbounded sides in its
    finite box), ``qd`` uniform in ``[-qd_scale, qd_scale]``; block ``b`` of each from
    ``jax.random.fold_in`` of one of the two halves of ``jax.random.split(jax.random.key(seed))``.
    A row depends on ``seed`` and its index only.

    >>> import numpy as np, jaxkin as jk
    >>> from jaxkin.sampling import sample_rows
    >>> robot = jk.robots.load("two_link_planar")
    >>> q, qd = sample_rows(robot, 10**9, seed=0, qd_scale=0.5, dtype=np.float32)
    >>> q.shape, q[5:8].shape  # a billion rows; reading three draws one block
    ((1000000000, 2), (3, 2))
    >>> bool(np.all(np.abs(qd[0:100]) <= 0.5))
    True
    """
    key_q, key_qd = jax.random.split(jax.random.key(seed))

    def draw_q(b: int) -> jax.Array:
        key = jax.random.fold_in(key_q, b)
        return sample_configurations(robot, SAMPLE_BLOCK, key, dtype=dtype)

    def draw_qd(b: int) -> jax.Array:
        key, shape = jax.random.fold_in(key_qd, b), (SAMPLE_BLOCK, robot.nv)
        return jax.random.uniform(key, shape, dtype, minval=-qd_scale, maxval=qd_scale)

    return SampledRows(n, robot.nq, dtype, draw_q), SampledRows(n, robot.nv, dtype, draw_qd)
