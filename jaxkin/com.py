"""Mass and centre of mass: :func:`center_of_mass` and :func:`com_jacobian`.

A robot loaded from a description with inertial data (URDF ``<inertial>``, MuJoCo's compiled
body masses, ``inertial=`` joint specs of :func:`jaxkin.build.from_joints`) holds one mass,
centre of mass and rotational inertia per frame (``robot.frame_mass``, ``frame_com``,
``frame_inertia``; ``robot.has_inertia``); ``robot.mass`` is the total. The centre of mass is

    c(q) = sum_i m_i c_i(q) / sum_i m_i,   c_i = p_i + R_i com_i,

over every frame ``i``, those fixed to the base included (they do not move: a constant in ``c``,
nothing in its Jacobian), in world coordinates (the frame ``robot.base`` is expressed in), as
MuJoCo's ``subtree_com`` of the world body. Pinocchio's ``centerOfMass`` of a fixed-base model
leaves out the links fixed to its universe (``computeTotalMass`` does not count them either);
for a free-flyer model (``floating_base=True``) the two agree.

:func:`com_jacobian` is ``dc/dv`` (3, nv): ``dc = Jc v dt`` for a velocity ``v``, its columns in
jaxkin's velocity convention (``robot.velocity_names``; a free joint's linear velocity in its
child's axes, as Pinocchio's ``jacobianCenterOfMass``). One forward pass gives both: each
joint's column is that of the centre of mass of the subtree it moves, weighted by the subtree's
share of the mass (``z x (S - M o)`` for a revolute joint, ``S`` the mass-weighted sum of the
subtree's centres, ``M`` its mass, ``o`` a point on the axis).

Kernels for other solvers (unchecked, traced into the caller's computation):
:func:`com_and_jacobian` ``(robot, q) -> (c, Jc)`` and :func:`com_kernel` ``(robot, q) -> c``;
call :func:`check_inertia` once, eagerly, in the checked entry point that uses them.
"""

from __future__ import annotations

import functools
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import _fold as fold
from ._checks import check_inertia, check_q, is_traced, no_inertia_error
from ._forward import forward_pass, scalar_pass, scan_joints
from ._jit import eager
from .model import Robot

__all__ = ["center_of_mass", "com_jacobian"]  # kernels for solvers: com_and_jacobian, com_kernel


def center_of_mass(robot: Robot, q: Any) -> jax.Array:
    """The robot's centre of mass in world coordinates, shape (3,) (see the module doc).

    Raises :class:`~jaxkin.ModelError` for a robot without inertial data (a DH robot, a URDF
    without ``<inertial>``) and, called eagerly, for a total mass of 0 (under ``jit`` over the
    robot the result is then NaN). ``jit``, ``vmap`` (over ``q`` or a stack of robots) and
    ``grad`` (over ``q`` and the robot's leaves, masses included) work.

    >>> import jaxkin as jk
    >>> robot = jk.Robot.from_joints(
    ...     [
    ...         dict(name="j1", type="revolute", child="a", axis=[0, 0, 1],
    ...              inertial=dict(mass=1.0, xyz=[1, 0, 0])),
    ...         dict(name="j2", type="fixed", child="b", xyz=[2, 0, 0],
    ...              inertial=dict(mass=3.0)),
    ...     ]
    ... )
    >>> float(robot.mass), jk.center_of_mass(robot, [0.0]).tolist()  # (1 * 1 + 3 * 2) / 4
    (4.0, [1.75, 0.0, 0.0])
    """
    fn = "jk.center_of_mass"
    q = check_q(robot, q, fn=fn, host=True)
    check_inertia(robot, fn)
    return _center_of_mass(robot, q)


def com_jacobian(robot: Robot, q: Any) -> jax.Array:
    """The Jacobian of :func:`center_of_mass`, shape (3, nv): ``dc = Jc v`` (see the module doc
    for the columns; Pinocchio's ``jacobianCenterOfMass``). Errors and transformations as
    :func:`center_of_mass`.

    >>> import jaxkin as jk
    >>> robot = jk.Robot.from_joints(
    ...     [dict(name="j1", type="revolute", child="a", axis=[0, 0, 1],
    ...           inertial=dict(mass=2.0, xyz=[1, 0, 0]))]
    ... )
    >>> jk.com_jacobian(robot, [0.0]).tolist()  # turning about z moves the mass along y
    [[0.0], [1.0], [0.0]]
    """
    fn = "jk.com_jacobian"
    q = check_q(robot, q, fn=fn, host=True)
    check_inertia(robot, fn)
    return _com_jacobian(robot, q)


# ----------------------------------------------------------------------------- kernels
def com_kernel(robot: Robot, q: jax.Array) -> jax.Array:
    """The centre of mass (3,) of a checked ``q``; nothing is checked but ``robot.has_inertia``
    (static). NaN for a total mass of 0."""
    if not robot.has_inertia:
        raise no_inertia_error(robot, "com_kernel")
    if scan_joints(robot) is None:  # the centre of com_and_jacobian's pass, bit for bit
        return _unrolled_com_and_jacobian(robot, q, jacobian=False)[0]
    fp = forward_pass(robot, q)
    m, c = _frame_centres(robot, fp)
    return jnp.sum(m[:, None] * c, axis=0) / jnp.sum(m)


def com_and_jacobian(robot: Robot, q: jax.Array) -> tuple[jax.Array, jax.Array]:
    """``(c, Jc)``: the centre of mass (3,) and its Jacobian (3, nv) of a checked ``q``, from
    one forward pass (below a floating base, one relative to it: see
    :func:`_unrolled_com_and_jacobian`); nothing is checked but ``robot.has_inertia`` (static),
    so solvers call it inside their loops (after :func:`check_inertia`). NaN for a total mass
    of 0."""
    if not robot.has_inertia:
        raise no_inertia_error(robot, "com_and_jacobian")
    if scan_joints(robot) is None:
        return _unrolled_com_and_jacobian(robot, q)
    fp = forward_pass(robot, q)
    dtype = fp.p.dtype
    m, c = _frame_centres(robot, fp)
    M = _subtree_sums(robot, m[:, None])[:, 0]  # per frame: the mass of its subtree
    S = _subtree_sums(robot, m[:, None] * c)  # and the mass-weighted sum of its centres
    total = M[0]
    Jc = jnp.zeros((robot.nv, 3), dtype=dtype)
    single = [j for j, k in enumerate(robot.kinds) if k in ("revolute", "prismatic")]
    if single:
        idx = np.asarray(single, dtype=np.int64)
        kinds = np.array(robot.kinds, dtype=object)[idx]
        rev = jnp.asarray(kinds == "revolute", dtype=dtype)[:, None]
        pri = 1.0 - rev
        mult = jnp.asarray(robot.multiplier)[idx].astype(dtype)[:, None]
        z, o, Mj, Sj = fp.z[idx], fp.o[idx], M[idx + 1][:, None], S[idx + 1]
        cols = mult * (rev * jnp.cross(z, Sj - Mj * o) + pri * Mj * z)
        Jc = Jc.at[np.asarray(robot.v_index, dtype=np.int64)[idx]].add(cols)
    for j in robot.multi_dof_joints:
        Jc = _multi_dof_columns(robot, fp, j, M[j + 1], S[j + 1], Jc)
    return S[0] / total, Jc.T / total


def _unrolled_com_and_jacobian(
    robot: Robot, q: jax.Array, jacobian: bool = True
) -> tuple[jax.Array, jax.Array | None]:
    """:func:`com_and_jacobian` as scalars with the model's constants folded (every path
    unrolled): one pass over the tree accumulates each frame's subtree mass ``M`` and
    mass-weighted centre ``S`` from the leaves up, and each joint's column is read from its
    child's ``M``, ``S``. With ``jacobian=False``, ``(c, None)``: the centre alone, the same
    operations up to it (:func:`com_kernel`'s centre is this pass's, bit for bit).

    Below a free joint (the outermost on a path: a floating base) the poses, sums and columns
    are computed relative to its child frame (:func:`~jaxkin._forward.scalar_pass` with
    ``root``), where the constants fold, and rotated into world axes once, by one (3, 3) product
    per floating base. In world coordinates every pose below a free-flyer is a full product
    with its rotation, and the program was about twice as long and slow to compile."""
    n_frames = robot.n_frames
    roots = _free_roots(robot)
    group = [_group(robot, f, roots) for f in range(n_frames)]  # None: world coordinates
    outside = tuple(f for f in range(n_frames) if group[f] is None)
    passes = {None: scalar_pass(robot, q, frames=outside + roots, materialise_trig=True)}
    for r in roots:
        below = tuple(f for f in range(n_frames) if group[f] == r)
        passes[r] = scalar_pass(robot, q, frames=below, root=r, materialise_trig=True)
    sp = passes[None]
    dtype = sp.dtype
    m, com, mult = _mass_constants(robot, dtype)
    M: list = [None] * n_frames
    S: list = [None] * n_frames
    for f in range(n_frames):
        g = passes[group[f]]
        c = fold.vadd(g.p[f], fold.matvec(g.R[f], com[f]))
        M[f], S[f] = m[f], fold.vscale(c, m[f])
    for f in range(n_frames - 1, 0, -1):  # children come after their parents
        parent = _parent_frame(robot, f)
        Sf = S[f]
        if group[f] is not None and group[parent] != group[f]:  # a root: to world coordinates
            Sf = fold.vadd(fold.vscale(sp.p[f], M[f]), fold.matvec(sp.R[f], Sf))
        M[parent] = fold.add(M[parent], M[f])
        S[parent] = fold.vadd(S[parent], Sf)
    total = fold.materialize(M[0], dtype)
    c = fold.stack_vector(S[0], dtype) / total
    if not jacobian:
        return c, None
    cols = {r: [(0.0, 0.0, 0.0)] * robot.nv for r in (None, *roots)}
    for j, kind in enumerate(robot.kinds):
        if kind == "fixed":
            continue
        r = group[j + 1]
        _add_columns(robot, passes[r], j, M[j + 1], S[j + 1], mult[j], cols[r])
    parts = [_stacked(cols[None], dtype)]
    for r in roots:  # columns below a floating base: rotated into world axes
        parts.append(fold.stack_matrix(sp.R[r], dtype) @ _stacked(cols[r], dtype))
    return c, functools.reduce(jnp.add, parts) / total


def _free_roots(robot: Robot) -> tuple[int, ...]:
    """The child frames of the free joints with no free joint above them (floating bases)."""
    free = [j for j, kind in enumerate(robot.kinds) if kind == "free"]
    return tuple(j + 1 for j in free if not set(robot.ancestors(j + 1)[:-1]) & set(free))


def _group(robot: Robot, frame: int, roots: tuple[int, ...]) -> int | None:
    """The floating base (root frame) ``frame`` hangs from, itself included, or None."""
    path = robot.ancestors(frame)
    return next((r for r in roots if r - 1 in path), None)


def _parent_frame(robot: Robot, frame: int) -> int:
    if robot.has_tool and frame == robot.n_joints + 1:
        return robot.n_joints
    return robot.parents[frame - 1]


def _mass_constants(robot: Robot, dtype) -> tuple[list, list, list]:
    """Per frame the mass and the centre in the frame's axes, per joint the multiplier, as
    scalars: Python floats (folded) for a concrete robot, JAX scalars for a traced one."""
    if is_traced(robot):
        m = jnp.asarray(robot.frame_mass).astype(dtype)
        com = jnp.asarray(robot.frame_com).astype(dtype)
        mult = jnp.asarray(robot.multiplier).astype(dtype)
        n_frames = robot.n_frames
        return (
            [m[f] for f in range(n_frames)],
            [tuple(com[f, i] for i in range(3)) for f in range(n_frames)],
            [mult[j] for j in range(robot.n_joints)],
        )
    m = np.asarray(robot.frame_mass, dtype=np.float64)
    com = np.asarray(robot.frame_com, dtype=np.float64)
    mult = np.asarray(robot.multiplier, dtype=np.float64)
    return (
        [float(x) for x in m],
        [tuple(float(x) for x in row) for row in com],
        [float(x) for x in mult],
    )


def _add_columns(robot: Robot, sp, j: int, M, S, mult, cols: list) -> None:
    """Adds joint ``j``'s columns (times the mass ``M`` its subtree holds; ``S``: the subtree's
    mass-weighted centres, in the coordinates of ``sp``) to ``cols`` (per velocity entry)."""
    kind, vi = robot.kinds[j], robot.v_index[j]
    if kind in ("revolute", "prismatic"):
        z = sp.z[j]
        if kind == "revolute":
            col = _cross(z, fold.vsub(S, fold.vscale(sp.o[j], M)))
        else:
            col = fold.vscale(z, M)
        cols[vi] = fold.vadd(cols[vi], fold.vscale(col, mult))
        return
    R, c = sp.R[j + 1], sp.p[j + 1]
    axes = [tuple(R[i][k] for i in range(3)) for k in range(3)]  # the child's axes
    arm = fold.vsub(S, fold.vscale(c, M))
    linear = {"free": (0, 1, 2), "ball": (), "planar": (0, 1)}[kind]
    angular = {"free": (0, 1, 2), "ball": (0, 1, 2), "planar": (2,)}[kind]
    new = [fold.vscale(axes[k], M) for k in linear] + [_cross(axes[k], arm) for k in angular]
    for k, col in enumerate(new):
        cols[vi + k] = fold.vadd(cols[vi + k], col)


def _cross(u: tuple, v: tuple) -> tuple:
    """``u x v`` of scalar 3-vectors, constants folded, but ``0 - x`` kept a subtraction (not
    ``-x``): a zero entry is +0.0, as the array product gives it (a column printed as ``-0.0``
    otherwise)."""

    def sub(a, b):
        return fold.sub(a, b) if fold.is_const(b) or not fold.is_const(a) else a - b

    return (
        sub(fold.mul(u[1], v[2]), fold.mul(u[2], v[1])),
        sub(fold.mul(u[2], v[0]), fold.mul(u[0], v[2])),
        sub(fold.mul(u[0], v[1]), fold.mul(u[1], v[0])),
    )


def _stacked(cols: list, dtype) -> jax.Array:
    """(3, nv) from per-column scalar 3-vectors."""
    if not cols:
        return jnp.zeros((3, 0), dtype)
    return jnp.stack([fold.stack_vector([c[i] for c in cols], dtype) for i in range(3)])


def _frame_centres(robot: Robot, fp) -> tuple[jax.Array, jax.Array]:
    """Per frame: the mass (n_frames,) and the centre of mass in world coordinates (n_frames,
    3)."""
    dtype = fp.p.dtype
    m = jnp.asarray(robot.frame_mass).astype(dtype)
    com = jnp.asarray(robot.frame_com).astype(dtype)
    return m, fp.p + jnp.einsum("fij,fj->fi", fp.R, com)


def _multi_dof_columns(robot: Robot, fp, j: int, M, S, Jc: jax.Array) -> jax.Array:
    """The columns of free, ball or planar joint ``j`` (velocity in its child's axes, as
    :mod:`jaxkin.jacobians`), times the mass ``M`` its subtree holds (``S``: the subtree's
    mass-weighted centres)."""
    kind, vi = robot.kinds[j], robot.v_index[j]
    R, c = fp.R[j + 1], fp.p[j + 1]
    axes = R.T  # rows: the child's axes in world coordinates
    angular = jnp.cross(axes, S - M * c)  # rows: a_k x (S - M c)
    if kind == "free":
        cols = jnp.concatenate([M * axes, angular])
    elif kind == "ball":
        cols = angular
    else:  # planar: vx, vy, wz
        cols = jnp.concatenate([M * axes[:2], angular[2:]])
    return Jc.at[vi : vi + cols.shape[0]].add(cols)


def _subtree_sums(robot: Robot, x: jax.Array) -> jax.Array:
    """Per frame, the sum of ``x`` (n_frames, k) over the frame's subtree (itself included):
    a reverse cumulative sum for a serial chain, else one scatter-add per depth level of the
    tree, deepest first."""
    levels = _levels(robot.parents, robot.has_tool)
    if levels is None:
        return jnp.cumsum(x[::-1], axis=0)[::-1]
    for kids, parents in levels:
        x = x.at[parents].add(x[kids])
    return x


@functools.lru_cache(maxsize=256)
def _levels(parents: tuple[int, ...], has_tool: bool):
    """The frames of each depth of the tree with their parent frames, deepest first, as index
    arrays; None for a serial chain (each frame's parent is the previous frame)."""
    n = len(parents)
    parent = [-1, *parents, *([n] if has_tool else [])]
    if all(p == f - 1 for f, p in enumerate(parent)):
        return None
    depth = [0] * len(parent)
    for f in range(1, len(parent)):  # parents come before children
        depth[f] = depth[parent[f]] + 1
    by_depth: dict[int, list[int]] = {}
    for f in range(1, len(parent)):
        by_depth.setdefault(depth[f], []).append(f)
    return tuple(
        (np.asarray(fs, dtype=np.int64), np.asarray([parent[f] for f in fs], dtype=np.int64))
        for d, fs in sorted(by_depth.items(), reverse=True)
    )


def _jacobian_kernel(robot: Robot, q: jax.Array) -> jax.Array:
    return com_and_jacobian(robot, q)[1]


_center_of_mass = eager(com_kernel)
_com_jacobian = eager(_jacobian_kernel)
