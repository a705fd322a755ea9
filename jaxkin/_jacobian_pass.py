"""Private: the geometric Jacobian's kernels, unchecked (Table 4.1 from one forward pass).

Kernels take ``(robot, q, frame, ...)``: a checked configuration ``q`` (``_checks.check_q``),
frame indices, a checked ``point`` and ``reference`` (see :mod:`jaxkin.jacobians` for their
meaning); nothing is checked again here, so solvers call them inside their loops.

* :func:`jacobian_pass` ``(robot, q, frame, point, reference) -> FrameJacobian``: one frame;
* :func:`jacobians_pass` ``(robot, q, frames, points=None, reference="world_aligned") ->
  FrameJacobians``: several frames (a tuple of indices) from one shared forward pass;
  ``.matrix()`` (k, 6, nv), ``.pose()`` (k, 4, 4), ``.times(qd)`` (k, 6), ``.rotation()``
  (k, 3, 3); ``points`` None or (k, 3);
* :func:`geometric_pass`: either, by the type of ``frame`` (an index or a tuple);
* :func:`autodiff_jacobian`: the ``jax.jacfwd``/``jax.jacrev`` twins (one frame or several);
* :func:`analytical_jacobian_pass`: ``d[p; phi]/dq`` and the representation margin.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _fold as fold
from . import spatial
from ._checks import is_traced, result_dtype
from ._forward import (
    frame_pose,
    frame_poses,
    scalar_pass,
    scan_joints,
    scan_steps,
    shared_scalar_pass,
)
from ._jit import op_by_op, padded_to_block
from .configuration import integrate_kernel
from .model import Robot
from .representations import from_matrix, representation_margin

__all__ = [
    "FrameJacobian",
    "FrameJacobians",
    "analytical_jacobian_pass",
    "autodiff_jacobian",
    "free_root",
    "geometric_pass",
    "jacobian_pass",
    "jacobians_pass",
    "scan_jacobian_pass",
    "world_jacobian_pass",
]


def _columns(robot: Robot, sp, target, frame: int, joints=None) -> tuple[list, list]:
    """Table 4.1 as scalars: per entry of ``v`` the linear and angular column at point ``target``
    (in the coordinates of ``sp``'s poses: world ones, or those of a relative pass's root), from
    the joints of ``frame``'s path (or those of them in ``joints``).

    A revolute joint i contributes ``[z_i x (target - o_i); z_i]``, a prismatic one ``[z_i; 0]``
    (times its multiplier, summed over joints sharing a q entry); joints off the path give zeros.
    A free joint gives six columns: with ``a_k`` the child frame's axes in world coordinates and
    ``c`` its origin, ``[a_k; 0]`` (k = x, y, z) then ``[a_k x (target - c); a_k]``; a ball joint
    the three angular ones, a planar joint the linear x, y and the angular z one.
    """
    zero = (0.0, 0.0, 0.0)
    Jv = [zero] * robot.nv
    Jw = [zero] * robot.nv
    path = robot.ancestors(frame)
    if joints is not None:
        path = tuple(j for j in path if j in joints)
    mult = _multipliers(robot, path)
    for j in path:
        kind = robot.kinds[j]
        if kind == "fixed":
            continue
        if kind in ("free", "ball", "planar"):
            _multi_dof_columns(kind, sp, j, robot.v_index[j], target, Jv, Jw)
            continue
        z = sp.z[j]
        qi = robot.v_index[j]
        if kind == "revolute":
            jv, jw = fold.cross(z, fold.vsub(target, sp.o[j])), z
        else:
            jv, jw = z, zero
        m = mult[j]
        Jv[qi] = fold.vadd(Jv[qi], fold.vscale(jv, m))
        Jw[qi] = fold.vadd(Jw[qi], fold.vscale(jw, m))
    return Jv, Jw


def _multi_dof_columns(kind: str, sp, j: int, vi: int, target, Jv: list, Jw: list) -> None:
    """The columns of free, ball or planar joint ``j`` (its velocity in child axes)."""
    zero = (0.0, 0.0, 0.0)
    R, c = sp.R[j + 1], sp.p[j + 1]  # the child frame (placement robots: no A after the motion)
    axes = [tuple(R[i][k] for i in range(3)) for k in range(3)]  # columns of R
    arm = fold.vsub(target, c)
    linear = {"free": (0, 1, 2), "ball": (), "planar": (0, 1)}[kind]
    angular = {"free": (0, 1, 2), "ball": (0, 1, 2), "planar": (2,)}[kind]
    col = vi
    for k in linear:
        Jv[col], Jw[col] = axes[k], zero
        col += 1
    for k in angular:
        Jv[col], Jw[col] = fold.cross(axes[k], arm), axes[k]
        col += 1


def _multipliers(robot: Robot, joints) -> dict:
    m = robot.multiplier
    if is_traced(m):
        return {j: m[j] for j in joints}
    m = np.asarray(m, dtype=np.float64)
    return {j: float(m[j]) for j in joints}


def _is_zero_column(Jv: list, Jw: list, k: int) -> bool:
    return all(fold.is_const(x) and x == 0.0 for x in (*Jv[k], *Jw[k]))


def _concatenate(parts: list, axis: int) -> jax.Array:
    """``jnp.concatenate(parts, axis)`` in groups of at most ``fold.CONCAT_OPERANDS`` operands
    (XLA may merge nested groups back into one concatenate: a copy of the fused parts then)."""
    k = fold.CONCAT_OPERANDS
    while len(parts) > k:
        parts = [
            parts[i] if len(parts[i : i + k]) == 1 else jnp.concatenate(parts[i : i + k], axis)
            for i in range(0, len(parts), k)
        ]
    return parts[0] if len(parts) == 1 else jnp.concatenate(parts, axis)


def _assemble(Jv: list, Jw: list, dtype) -> jax.Array:
    """(6, nv) array from per-column 3-vectors of scalars.

    Columns that are constant zeros (joints off the frame's path) are placed statically: the
    matrix is the concatenation of one zeros block per run of them and one stacked block per run
    of at most ``fold.CONCAT_OPERANDS`` of the others. No scatter: XLA fuses the whole assembly
    into the output loop, where a scatter into a zeros block split the kernel into one fusion
    per entry, each recomputing the forward pass (a humanoid hand: 97 fusions, 4,376
    multiplies; statically placed: 46 and 509). Nor a wider stack: XLA fuses nothing into a
    concatenate of more operands (a G1 foot, whose free-flyer and leg columns form one run of
    12: 68 fusions, 2,567 multiplies; in runs of at most 8: 28 and 304)."""
    dof = len(Jv)
    if dof == 0:
        return jnp.zeros((6, 0), dtype)
    zero = [_is_zero_column(Jv, Jw, k) for k in range(dof)]
    pieces = []
    start = 0
    for end in range(1, dof + 1):
        wide = not zero[start] and end - start >= fold.CONCAT_OPERANDS
        if end < dof and zero[end] == zero[start] and not wide:
            continue
        if zero[start]:
            pieces.append(jnp.zeros((6, end - start), dtype))
        else:
            pieces.append(_stacked_columns(Jv, Jw, start, end, dtype))
        start = end
    return _concatenate(pieces, axis=1)


def _stacked_columns(Jv: list, Jw: list, start: int, end: int, dtype) -> jax.Array:
    """(6, end - start): the scalar columns ``start..end-1`` of ``Jv``, ``Jw`` stacked."""
    cols = range(start, end)
    rows = [[Jv[k][i] for k in cols] for i in range(3)]
    rows += [[Jw[k][i] for k in cols] for i in range(3)]
    return fold.stack_matrix(rows, dtype)


class FrameJacobian(NamedTuple):
    """The geometric Jacobian of one frame, before assembly: columns as scalar 3-vectors (short
    robots, constants folded) or as (3, dof) arrays (scanned chains), plus the frame's pose
    (``R``, origin ``p``, world coordinates) from the same forward pass.

    ``cv``, ``cw``: the columns, except those computed below a free-flyer when ``below``
    (:class:`_Below`, or None) holds them, rotated into ``world_aligned`` or ``world`` at
    assembly; ``columns()`` gives all of them as ``(Jv, Jw)`` (the rotation traced once per call).
    ``matrix()`` (6, dof), ``times(qd)`` = ``J @ qd`` (6,) without forming J, ``rotation()``
    (3, 3), ``pose()`` (4, 4) ``T_world_frame``."""

    cv: Any
    cw: Any
    R: Any
    p: Any
    dtype: Any
    below: Any = None

    def columns(self) -> tuple[Any, Any]:
        """``(Jv, Jw)``, the rotated columns from below the free-flyer formed once."""
        if self.below is None:
            return self.cv, self.cw
        Kv, Kw = _rotated(self.below)
        add = lambda J, K: [fold.vadd(a, b) for a, b in zip(J, K, strict=True)]  # noqa: E731
        return add(self.cv, Kv), add(self.cw, Kw)

    def matrix(self) -> jax.Array:
        if self.below is not None:
            return _assemble_below(self.cv, self.cw, self.below, self.dtype)
        if isinstance(self.cv, list):
            return _assemble(self.cv, self.cw, self.dtype)
        return jnp.concatenate([self.cv, self.cw], axis=0)

    def times(self, qd: jax.Array) -> jax.Array:
        """``J @ qd`` (6,) without materialising J when the columns are scalars."""
        Jv, Jw = self.columns()
        if not isinstance(Jv, list):
            return self.matrix() @ qd
        qs = [qd[k] for k in range(len(Jv))]
        v = [fold.add(*(fold.mul(c[i], s) for c, s in zip(Jv, qs, strict=True))) for i in range(3)]
        w = [fold.add(*(fold.mul(c[i], s) for c, s in zip(Jw, qs, strict=True))) for i in range(3)]
        return fold.stack_matrix(v + w, self.dtype)

    def rotation(self) -> jax.Array:
        return fold.stack_matrix(self.R, self.dtype) if isinstance(self.R, tuple) else self.R

    def pose(self) -> jax.Array:
        """``T_world_frame`` (4, 4) of the frame (its origin, not ``point``)."""
        p = fold.stack_matrix(self.p, self.dtype) if isinstance(self.p, tuple) else self.p
        return spatial.make_transform(self.rotation(), p)


def jacobian_pass(
    robot: Robot, q: jax.Array, frame: int, point: jax.Array | None, reference: str
) -> FrameJacobian:
    """The kernel behind every geometric Jacobian: one forward pass, columns of frame index
    ``frame`` at ``point`` (checked offset (3,) in the frame's axes, or None) in ``reference``.

    ``q`` must be checked (``jk.geometric_jacobian`` and ``jk.jacobians.frame_jacobian`` are the
    checked entry points); nothing is checked again here, so solvers call it inside their loops.
    """
    if scan_joints(robot, frame) is not None:
        return scan_jacobian_pass(robot, q, frame, point, reference)
    sp = scalar_pass(robot, q, frames=(frame,), materialise_trig=True)
    root = free_root(robot, frame)
    rp = None
    if root is not None:
        rp = scalar_pass(robot, q, frames=(frame,), root=root, materialise_trig=True)
    return _unrolled_jacobian(robot, sp, frame, point, reference, rp)


def world_jacobian_pass(
    robot: Robot, q: jax.Array, frame: int, point: jax.Array | None, reference: str
) -> FrameJacobian:
    """:func:`jacobian_pass` with every column from the world pass (none computed below a
    free-flyer and rotated: the kernel before that path was added), for a frame whose path is
    unrolled; the reference the fast path is tested against. Unchecked."""
    sp = scalar_pass(robot, q, frames=(frame,), materialise_trig=True)
    return _unrolled_jacobian(robot, sp, frame, point, reference)


def free_root(robot: Robot, frame: int) -> int | None:
    """The child frame of the last free joint on ``frame``'s path (the frame the columns below
    a free-flyer are computed in, see :func:`jacobian_pass`), or None."""
    free = [j for j in robot.ancestors(frame) if robot.kinds[j] == "free"]
    return free[-1] + 1 if free else None


def _unrolled_jacobian(
    robot: Robot, sp, frame: int, point, reference: str, rp=None
) -> FrameJacobian:
    """Table 4.1 as scalars, from a :func:`~jaxkin._forward.scalar_pass` ``sp`` that reached
    ``frame``, and for a frame below a free joint the pass ``rp`` relative to its child frame
    (``root=free_root(robot, frame)``).

    Below a free-flyer the columns of the free joint and of the joints under it are computed in
    the free-flyer's child frame, where the model's constants fold, then rotated into world axes
    once each (``world_aligned``, ``world``) or into the frame's axes by the relative rotation
    alone (``local``: the free-flyer's rotation cancels). In world coordinates every pose below
    the free-flyer is a full product with its rotation, and XLA's CPU compiler recomputed that
    forward pass for each output entry (a humanoid's hand: about 30x the multiplies of the same
    arm on a fixed base)."""
    pt = None if point is None else point.astype(sp.dtype)
    ptv = None if pt is None else tuple(pt[i] for i in range(3))
    R, p = sp.R[frame], sp.p[frame]
    target = p if pt is None else fold.vadd(p, fold.matvec(R, ptv))
    root = None if rp is None else free_root(robot, frame)
    if root is None:
        Jv, Jw = _columns(robot, sp, target, frame)
        Jv, Jw = _world_to(reference, Jv, Jw, R, target)
        return FrameJacobian(cv=Jv, cw=Jw, R=R, p=p, dtype=sp.dtype)
    path = robot.ancestors(frame)
    below = {j for j in path if j >= root - 1 and root - 1 in robot.ancestors(j + 1)}
    above = {j for j in path if j not in below}
    Jv, Jw = _columns(robot, sp, target, frame, above)
    Jv, Jw = _world_to(reference, Jv, Jw, R, target)
    Rr, pr = rp.R[frame], rp.p[frame]
    target_r = pr if pt is None else fold.vadd(pr, fold.matvec(Rr, ptv))
    Kv, Kw = _columns(robot, rp, target_r, frame, below)
    if reference == "local":
        # the relative rotation has a deep closure: XLA keeps each entry in a buffer anyway
        Kv, Kw = _rotate(fold.transpose(Rr), Kv, Kw)
    else:
        K = _Below(sp.R[root], Kv, Kw, target if reference == "world" else None)
        if not any(_shared_column(Jv, Jw, K, k) for k in range(len(Jv))):
            return FrameJacobian(cv=Jv, cw=Jw, R=R, p=p, dtype=sp.dtype, below=K)
        Kv, Kw = _rotated(K)
    Jv = [fold.vadd(a, b) for a, b in zip(Jv, Kv, strict=True)]
    Jw = [fold.vadd(a, b) for a, b in zip(Jw, Kw, strict=True)]
    return FrameJacobian(cv=Jv, cw=Jw, R=R, p=p, dtype=sp.dtype)


class _Below(NamedTuple):
    """Columns computed below a free-flyer (``Kv``, ``Kw``: scalar 3-vectors in its child's
    axes), in world axes ``M @ column`` (``M``: that child's rotation), then for ``reference=
    "world"`` the linear part moved to the world origin (``target``: the point's world
    position; else None)."""

    M: Any
    Kv: list
    Kw: list
    target: Any


def _rotated(K: _Below) -> tuple[list, list]:
    """``K``'s columns in world axes, as scalars (zero columns stay constant zeros)."""
    Kv, Kw = _rotate(K.M, K.Kv, K.Kw)
    if K.target is not None:
        Kv = [fold.vadd(v, fold.cross(K.target, w)) for v, w in zip(Kv, Kw, strict=True)]
    return Kv, Kw


def _shared_column(Jv: list, Jw: list, K: _Below, k: int) -> bool:
    """Whether column ``k`` has terms from above and from below the free-flyer (a velocity
    entry shared by joints on both sides: a mimic joint)."""
    return not _is_zero_column(Jv, Jw, k) and not _is_zero_column(K.Kv, K.Kw, k)


def _assemble_below(Jv: list, Jw: list, K: _Below, dtype) -> jax.Array:
    """(6, nv) from the scalar columns ``Jv``, ``Jw`` and ``K``'s (no column has both).

    ``K``'s nonzero columns are stacked per entry (six (m,) arrays) and each run of them that
    is contiguous in J is rotated as rows: an entry of ``K.M`` multiplies a whole row (one
    broadcast), so it is read by a few operations and XLA fuses the rotation into the output.
    Rotated column by column as scalars, every entry of ``K.M`` was read by each of the (up to
    2 m) rotated vectors, and XLA's CPU compiler, which duplicates an operation into at most
    15 index paths (``FusionNodeIndexingEvaluation``), kept each in a buffer of its own: one
    small fusion each, and a compile of each (a Talos hand, world-aligned: 36 fusions, 505
    multiplies; now 14 and 396; the stacked columns are buffers instead). The same operations
    in the same order: the scalar columns' values (op by op bit for bit, up to the sign of
    zeros; compiled within a few ulps: FMA contraction)."""
    nv = len(Jv)
    below = [k for k in range(nv) if not _is_zero_column(K.Kv, K.Kw, k)]
    if not below:
        return _assemble(Jv, Jw, dtype)
    stack = lambda xs: fold.stack_vector(xs, dtype)  # noqa: E731
    kv = tuple(stack([K.Kv[k][i] for k in below]) for i in range(3))
    kw = tuple(stack([K.Kw[k][i] for k in below]) for i in range(3))

    def rows(a: int, b: int) -> jax.Array:  # columns a..b-1 of kv, kw in world axes: (6, b - a)
        rv = fold.matvec(K.M, tuple(x[a:b] for x in kv))
        rw = fold.matvec(K.M, tuple(x[a:b] for x in kw))
        if K.target is not None:
            rv = fold.vadd(rv, fold.cross(K.target, rw))
        ones = jnp.ones((b - a,), dtype)
        return jnp.stack([x * ones if fold.is_const(x) else x.astype(dtype) for x in (*rv, *rw)])

    at = {k: i for i, k in enumerate(below)}  # column k of J is entry at[k] of kv, kw

    def kind(k: int) -> str:
        return "below" if k in at else ("zero" if _is_zero_column(Jv, Jw, k) else "above")

    pieces = []
    start = 0
    for end in range(1, nv + 1):
        same = end < nv and kind(end) == kind(start)
        if kind(start) == "below":
            same = same and at[end] == at[end - 1] + 1
        elif kind(start) == "above":
            same = same and end - start < fold.CONCAT_OPERANDS
        if same:
            continue
        if kind(start) == "zero":
            pieces.append(jnp.zeros((6, end - start), dtype))
        elif kind(start) == "below":
            pieces.append(rows(at[start], at[end - 1] + 1))
        else:
            pieces.append(_stacked_columns(Jv, Jw, start, end, dtype))
        start = end
    return _concatenate(pieces, axis=1)


def _is_zero(c) -> bool:
    return all(fold.is_const(x) and x == 0.0 for x in c)


def _rotate(M, Jv: list, Jw: list) -> tuple[list, list]:
    """``M @ column`` for every column (zero columns stay constant zeros)."""
    rot = lambda c: c if _is_zero(c) else fold.matvec(M, c)  # noqa: E731
    return [rot(c) for c in Jv], [rot(c) for c in Jw]


def _world_to(reference: str, Jv: list, Jw: list, R, target) -> tuple[list, list]:
    """World-aligned columns in ``reference`` (``R``: the frame's rotation, ``target``: the
    point's world position)."""
    if reference == "local":
        return _rotate(fold.transpose(R), Jv, Jw)
    if reference == "world":
        # velocity of the point at the world origin: v_target - omega x target
        Jv = [fold.vadd(v, fold.cross(target, w)) for v, w in zip(Jv, Jw, strict=True)]
    return Jv, Jw


class FrameJacobians(NamedTuple):
    """The geometric Jacobians of several frames from one forward pass: ``each`` holds one
    :class:`FrameJacobian` per frame, in the order asked.

    ``matrix()`` (k, 6, nv), ``times(qd)`` (k, 6) (``J_i @ qd`` without forming J),
    ``rotation()`` (k, 3, 3), ``pose()`` (k, 4, 4) ``T_world_frame`` (origins, not points)."""

    each: tuple

    @property
    def dtype(self) -> Any:
        return self.each[0].dtype

    def matrix(self) -> jax.Array:
        return _concatenate([g.matrix()[None] for g in self.each], axis=0)

    def times(self, qd: jax.Array) -> jax.Array:
        return jnp.stack([g.times(qd) for g in self.each])

    def rotation(self) -> jax.Array:
        return jnp.stack([g.rotation() for g in self.each])

    def pose(self) -> jax.Array:
        return jnp.stack([g.pose() for g in self.each])


def jacobians_pass(
    robot: Robot,
    q: jax.Array,
    frames: tuple[int, ...],
    points: jax.Array | None = None,
    reference: str = "world_aligned",
) -> FrameJacobians:
    """Several frames' Jacobians and poses from one forward pass: the kernel of
    ``jk.geometric_jacobian(robot, q, frame=[...])``.

    ``frames``: frame indices (a tuple, in any order, duplicates allowed); ``points``: None or
    checked offsets (k, 3), row i in frame i's axes; ``reference`` as for :func:`jacobian_pass`.
    One :func:`~jaxkin._forward.scalar_pass` over the union of the frames' paths
    (:func:`~jaxkin._forward.shared_scalar_pass`): each joint on them is computed once, however
    many frames it moves; a frame whose own path is scanned (a long serial path:
    :func:`~jaxkin._forward.scan_joints`) gets its own scan. Entry i equals
    ``jacobian_pass(robot, q, frames[i], points[i], reference)`` bit for bit. ``q`` must be
    checked; nothing is checked here.
    """
    sp = shared_scalar_pass(robot, q, frames, materialise_trig=True)
    unrolled = [f for f in dict.fromkeys(frames) if scan_joints(robot, f) is None]
    roots = {f: free_root(robot, f) for f in unrolled}
    relative = {  # one pass below each free-flyer, over the union of its frames' paths
        r: scalar_pass(
            robot,
            q,
            frames=tuple(f for f in unrolled if roots[f] == r),
            root=r,
            materialise_trig=True,
        )
        for r in dict.fromkeys(roots.values())
        if r is not None
    }
    each = []
    for i, f in enumerate(frames):
        pt = None if points is None else points[i]
        if scan_joints(robot, f) is not None:
            each.append(scan_jacobian_pass(robot, q, f, pt, reference))
        else:
            rp = relative.get(roots[f])
            each.append(_unrolled_jacobian(robot, sp, f, pt, reference, rp))
    return FrameJacobians(each=tuple(each))


def geometric_pass(
    robot: Robot,
    q: jax.Array,
    frame: int | tuple[int, ...],
    point: jax.Array | None,
    reference: str,
) -> FrameJacobian | FrameJacobians:
    """:func:`jacobian_pass` for one frame index (``point`` None or (3,)), :func:`jacobians_pass`
    for a tuple of them (``point`` None or (k, 3)): the kernel of the entry points that take one
    frame or several."""
    if isinstance(frame, tuple):
        return jacobians_pass(robot, q, frame, point, reference)
    return jacobian_pass(robot, q, frame, point, reference)


def scan_jacobian_pass(
    robot: Robot, q: jax.Array, frame: int, point: jax.Array | None, reference: str
) -> FrameJacobian:
    """:func:`jacobian_pass` through the ``lax.scan`` forward pass along ``frame``'s path
    (:func:`~jaxkin._forward.scan_steps`; the path of 1-dof and fixed joints only): the kernel
    of long paths (:func:`~jaxkin._forward.scan_joints`), and for any such path the twin the
    unrolled kernel is tested against. Table 4.1 vectorised over the path's joints: each entry
    of the columns one (m,) array ((m, N) under ``vmap``), elementwise, the columns placed at
    their velocity indices statically. Unchecked."""
    path = robot.ancestors(frame)
    is_tool = robot.has_tool and frame == robot.n_joints + 1
    sp = scan_steps(robot, q, path, tool=is_tool)
    dtype = sp.dtype
    R, p = sp.R, sp.p
    target = p
    if point is not None:
        pt = point.astype(dtype)
        target = fold.vadd(p, fold.matvec(R, tuple(pt[i] for i in range(3))))
    path = np.asarray(path, dtype=np.int64)
    kinds = np.array(robot.kinds, dtype=object)[path]
    rev, pri = kinds == "revolute", kinds == "prismatic"
    lever = fold.cross(sp.z, fold.vsub(target, sp.o))
    cols_v = tuple(_by_kind(rev, pri, lever[i], sp.z[i]) for i in range(3))
    cols_w = tuple(_by_kind(rev, None, sp.z[i], None) for i in range(3))
    m = robot.multiplier
    if is_traced(m) or np.any(np.asarray(m, dtype=np.float64)[path] != 1.0):
        mult = (m[path] if is_traced(m) else jnp.asarray(np.asarray(m)[path])).astype(dtype)
        cols_v = tuple(c * mult for c in cols_v)
        cols_w = tuple(c * mult for c in cols_w)
    moving = np.nonzero(kinds != "fixed")[0]
    vidx = np.array(robot.v_index, dtype=np.int64)[path][moving]  # 1-dof joints only here
    Jv = _place_columns(cols_v, moving, vidx, robot.nv, dtype)
    Jw = _place_columns(cols_w, moving, vidx, robot.nv, dtype)
    if reference == "local":
        Rt = fold.transpose(R)
        Jv, Jw = fold.matvec(Rt, Jv), fold.matvec(Rt, Jw)
    elif reference == "world":
        Jv = fold.vadd(Jv, fold.cross(target, Jw))
    st = lambda x: fold.stack_matrix(x, dtype)  # noqa: E731
    return FrameJacobian(cv=st(Jv), cw=st(Jw), R=st(R), p=st(p), dtype=dtype)


def _by_kind(rev: np.ndarray, pri: np.ndarray | None, if_rev, if_pri):
    """Per path joint: ``if_rev`` for revolute joints, ``if_pri`` for prismatic ones (None:
    zero), zero for fixed ones; selected statically (no arithmetic on the flags)."""
    if rev.all():
        return if_rev
    if if_pri is None or not pri.any():
        return jnp.where(jnp.asarray(rev), if_rev, 0.0)
    return jnp.where(jnp.asarray(rev), if_rev, jnp.where(jnp.asarray(pri), if_pri, 0.0))


PLACED_RUNS = 8
"""At most this many runs of columns (consecutive path joints at consecutive velocity indices,
or zero columns) are placed as slices and zeros blocks; more (a long path with fixed joints
between its moving ones) are one gather per row, so the program does not grow with the path."""


def _place_columns(cols: tuple, moving: np.ndarray, vidx: np.ndarray, nv: int, dtype) -> tuple:
    """Rows (3 entries, each (nv,)) of the columns ``cols`` (per path joint, (m,) each) placed at
    velocity indices ``vidx`` (of the path joints ``moving``): runs of consecutive columns are
    slices and the others static zeros blocks, so the assembly fuses into the kernel (beyond
    :data:`PLACED_RUNS` runs: one gather of a zero-padded row); a velocity index shared by two
    joints (a mimic joint) adds its columns (a scatter-add)."""
    if len(np.unique(vidx)) != len(vidx):
        return tuple(
            jnp.zeros((nv,), dtype).at[vidx].add(jnp.asarray(c, dtype)[moving]) for c in cols
        )
    src = np.full(nv, -1, dtype=np.int64)
    src[vidx] = moving
    runs: list = []  # (first source or -1, length)
    for k in range(nv):
        s = int(src[k])
        if runs:
            s0, n = runs[-1]
            if (s0 < 0 and s < 0) or (s0 >= 0 and s == s0 + n):
                runs[-1] = (s0, n + 1)
                continue
        runs.append((s, 1))
    if len(runs) > PLACED_RUNS:
        return tuple(_gathered(c, src, dtype) for c in cols)
    return tuple(_concatenated(c, runs, dtype) for c in cols)


def _gathered(c, src: np.ndarray, dtype) -> jax.Array:
    """``c[src]`` with a zero where ``src`` is -1: one gather of the zero-padded row."""
    padded = jnp.concatenate([c, jnp.zeros((1,), dtype)])
    return padded[np.where(src < 0, c.shape[0], src)]


def _concatenated(c, runs: list, dtype) -> jax.Array:
    """The row of ``runs`` (first source or -1 for zeros, length): slices and zeros blocks."""
    parts = [jnp.zeros((n,), dtype) if s < 0 else c[s : s + n] for s, n in runs]
    if not parts:
        return jnp.zeros((0,), dtype)
    return parts[0] if len(parts) == 1 else jnp.concatenate(parts)


def _op_by_op_widened(x: jax.Array) -> jax.Array:
    """``x`` padded to a block (:func:`jaxkin._jit.padded_to_block`) when run op by op
    (``jax.disable_jit()``), else ``x`` itself."""
    return padded_to_block(x) if op_by_op() else x


def _pose_fn(robot: Robot, frame: int, point: jax.Array | None):
    """Returns ``f(q) -> (p_point, R_frame)`` used by the autodiff Jacobians (``q`` may carry
    entries beyond ``robot.nq``: the forward pass reads its entries by index, never the rest)."""

    def f(q):
        R, p = frame_pose(robot, q, frame)
        if point is not None:
            p = p + R @ point.astype(p.dtype)
        return p, R

    return f


def _poses_fn(robot: Robot, frames: tuple[int, ...], points: jax.Array | None):
    """Returns ``f(q) -> (p_points (k, 3), R_frames (k, 3, 3))`` from one shared pass."""

    def f(q):
        R, p = frame_poses(robot, q, frames)
        if points is not None:
            p = p + jnp.einsum("kij,kj->ki", R, points.astype(p.dtype))
        return p, R

    return f


def _jacobian_from_derivs(p, R, dp, dR, reference):
    # dp: (3, dof), dR: (3, 3, dof). omega column k = vee(dR_k R^T).
    Jw = jax.vmap(lambda dRk: spatial.vee(dRk @ R.T), in_axes=2, out_axes=1)(dR)
    Jv = dp
    if reference == "world_aligned":
        return jnp.concatenate([Jv, Jw], axis=0)
    if reference == "local":
        return jnp.concatenate([R.T @ Jv, R.T @ Jw], axis=0)
    return jnp.concatenate([Jv + spatial.skew(p) @ Jw, Jw], axis=0)


def autodiff_jacobian(
    robot: Robot,
    q: jax.Array,
    frame: int | tuple[int, ...],
    point: jax.Array | None,
    reference: str | tuple[str, ...],
    mode: str,
) -> jax.Array | tuple[jax.Array, ...]:
    """The geometric Jacobian by ``jax.jacfwd`` (``mode="fwd"``) or ``jax.jacrev`` (``"rev"``)
    of forward kinematics: (6, nv) for one frame index (``point`` None or (3,)), (k, 6, nv) for a
    tuple of them (``point`` None or (k, 3); one shared forward pass, differentiated once). For
    a robot with ``nq != nv`` along ``integrate(robot, q, v)`` at ``v = 0``. ``reference`` one
    reference, or a tuple of them: then a tuple of Jacobians, one per reference, from one
    differentiation (each equal to the Jacobian of that reference alone). Op by op
    (``jax.disable_jit()``) a robot with ``nq == nv`` is differentiated on a widened ``q``
    (:func:`_op_by_op_widened`). Unchecked."""
    several = isinstance(frame, tuple)
    pose = _poses_fn(robot, frame, point) if several else _pose_fn(robot, frame, point)
    jac = jax.jacfwd if mode == "fwd" else jax.jacrev
    q = q.astype(result_dtype(robot, q))
    nv = robot.nv
    if robot.nq == nv:
        q = _op_by_op_widened(q)
        dp, dR = jac(pose)(q)
    else:  # differentiate along the configuration manifold: v -> pose(integrate(q, v)) at 0
        v0 = jnp.zeros(nv, q.dtype)
        dp, dR = jac(lambda v: pose(integrate_kernel(robot, q, v)))(v0)
    p, R = pose(q.astype(dp.dtype))

    def in_reference(ref: str) -> jax.Array:
        if several:
            J = jax.vmap(lambda *a: _jacobian_from_derivs(*a, ref))(p, R, dp, dR)
        else:
            J = _jacobian_from_derivs(p, R, dp, dR, ref)
        return J if J.shape[-1] == nv else J[..., :nv]

    if isinstance(reference, tuple):
        return tuple(in_reference(ref) for ref in reference)
    return in_reference(reference)


def analytical_jacobian_pass(
    robot: Robot,
    q: jax.Array,
    frame: int,
    point: jax.Array | None,
    representation: str,
    method: str = "chain",
) -> tuple[jax.Array, jax.Array]:
    """The kernel of ``jk.analytical_jacobian`` on checked arguments: ``(J_a (6, nv), margin)``,
    unmasked (see :func:`jacobian_pass` for the arguments). Op by op (``jax.disable_jit()``) on
    widened columns (:func:`_op_by_op_widened`)."""
    pt = point
    dtype = result_dtype(robot, q)
    to_phi = lambda R: from_matrix(R, representation)  # noqa: E731

    if method == "chain":
        g = jacobian_pass(robot, q, frame, pt, "world_aligned")
        J = _op_by_op_widened(g.matrix())  # every column on its own below
        R = g.rotation()
        phi = to_phi(R)
        dphi_dR = jax.jacfwd(to_phi)(R)  # (3, 3, 3): d phi_i / d R_ab
        # dR/dq_k = skew(w_k) R, elementwise (no small batched dots):
        w = J[3:]  # (3, dof)
        S = jnp.stack(
            [
                jnp.stack([jnp.zeros_like(w[0]), -w[2], w[1]]),
                jnp.stack([w[2], jnp.zeros_like(w[0]), -w[0]]),
                jnp.stack([-w[1], w[0], jnp.zeros_like(w[0])]),
            ]
        )  # (3, 3, dof): S[a, c, k] = skew(w_k)[a, c]
        dR = jnp.sum(S[:, :, None, :] * R[None, :, :, None], axis=1)  # (3, 3, dof)
        dphi = jnp.sum(dphi_dR[:, :, :, None] * dR[None], axis=(1, 2))  # (3, dof)
        Ja = jnp.concatenate([J[:3], dphi], axis=0)
    else:
        pose = _pose_fn(robot, frame, pt)

        def x_of_q(qq):
            p, R = pose(qq)
            phi = to_phi(R)
            return jnp.concatenate([p, phi]), phi

        if robot.nq == robot.nv:
            Ja, phi = jax.jacfwd(x_of_q, has_aux=True)(_op_by_op_widened(q.astype(dtype)))
        else:
            qq = q.astype(dtype)
            Ja, phi = jax.jacfwd(lambda v: x_of_q(integrate_kernel(robot, qq, v)), has_aux=True)(
                jnp.zeros(robot.nv, dtype)
            )
    if Ja.shape[-1] != robot.nv:
        Ja = Ja[:, : robot.nv]
    return Ja, representation_margin(phi, representation)
