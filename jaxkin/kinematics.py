"""Forward kinematics: poses of every frame, and the one forward pass the Jacobians reuse.

All poses are in the world frame (the frame ``robot.base`` is expressed in; the robot's base frame
when ``base`` is None): ``T_world_frame``, shape (4, 4). Kernels take one configuration ``q`` of
shape ``(dof,)``; batch with ``jax.vmap``.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _fold as fold
from . import spatial
from ._checks import check_q, is_traced, result_dtype
from ._jit import eager
from .model import Robot
from .placements import joint_placements

__all__ = [
    "ForwardPass",
    "ScalarPass",
    "fk",
    "fk_all",
    "forward_pass",
    "frame_pose",
    "scalar_pass",
    "scan_pass",
    "uses_scan",
]


class _Constants(NamedTuple):
    """Per-joint constants as scalars: Python floats (folded) or JAX scalars (traced)."""

    B: list | None  # per joint (Mat, Vec)
    A: list | None
    axis: list  # per joint Vec
    offset: list
    mult: list
    base: tuple  # (Mat, Vec)
    tool: tuple | None


SNAP = 1e-15


def _snap(x) -> float:
    """A concrete constant as a Python float; within 1e-15 of 0 or +-1 it is taken as exact
    (cos(pi/2) evaluates to 6e-17 in float64), so +-90 degree placements fold away."""
    x = float(x)
    for exact in (0.0, 1.0, -1.0):
        if abs(x - exact) <= SNAP:
            return exact
    return x


def _scalars(x, to_scalar):
    if getattr(x, "ndim", 0) == 0:
        return to_scalar(x)
    return tuple(_scalars(x[i], to_scalar) for i in range(x.shape[0]))


def _constants(robot: Robot, dtype) -> _Constants:
    """Everything the forward pass needs from the model, as scalars.

    With concrete leaves (a robot closed over by ``jit``, or eager use) the constants are Python
    floats computed in float64 and folded into the kernel; with traced leaves (``jit`` over the
    robot, ``grad`` with respect to its parameters, ``vmap`` over a stack of robots) they are JAX
    scalars and new values never retrace.
    """
    if not is_traced(robot):
        xp, conv = np, lambda a: np.asarray(a, dtype=np.float64)
        to_scalar = _snap
    else:
        xp, conv = jnp, lambda a: jnp.asarray(a).astype(dtype)
        to_scalar = lambda a: a  # noqa: E731
    place = joint_placements(robot, dtype, xp=xp)
    n = robot.n_joints

    def pairs(pl):
        if pl is None:
            return None
        R, p = _scalars(pl[0], to_scalar), _scalars(pl[1], to_scalar)
        return [(R[j], p[j]) for j in range(n)]

    axis = _scalars(conv(robot.axis), to_scalar)
    if robot.parameterisation != "placement":
        axis = [(0.0, 0.0, 1.0)] * n  # DH joints move about z by construction
    base = conv(robot.base)
    tool = conv(robot.tool)
    return _Constants(
        B=pairs(place.B),
        A=pairs(place.A),
        axis=list(axis),
        offset=list(_scalars(conv(robot.offset), to_scalar)),
        mult=list(_scalars(conv(robot.multiplier), to_scalar)),
        base=(_scalars(base[:3, :3], to_scalar), _scalars(base[:3, 3], to_scalar)),
        tool=(_scalars(tool[:3, :3], to_scalar), _scalars(tool[:3, 3], to_scalar))
        if robot.has_tool
        else None,
    )


def _joint_trig(robot: Robot, K: _Constants, qv: list) -> dict:
    """cos and sin of every revolute joint's value, computed once and materialised together.

    The optimisation barrier stops XLA from re-deriving them inside each fusion of the kernel
    (it otherwise duplicates the transcendental ops into every consumer).
    """
    values = {}
    for j, (kind, qi) in enumerate(zip(robot.kinds, robot.q_index, strict=True)):
        if kind == "revolute":
            values[j] = fold.add(fold.mul(K.mult[j], qv[qi]), K.offset[j])
    if not values:
        return {}
    keys = list(values)
    v = jnp.stack([jnp.asarray(values[j]) for j in keys])
    c, s = jax.lax.optimization_barrier((jnp.cos(v), jnp.sin(v)))
    return {j: (c[i], s[i]) for i, j in enumerate(keys)}


class ScalarPass(NamedTuple):
    """The forward pass as nested tuples of scalars (constants folded); see :class:`ForwardPass`."""

    R: list  # per frame: Mat
    p: list  # per frame: Vec
    z: list  # per joint: Vec
    o: list  # per joint: Vec
    dtype: Any


def scalar_pass(robot: Robot, q: jax.Array) -> ScalarPass:
    """One pass from the base to every frame, elementwise and with constants folded.

    Each joint's sin and cos are computed once; placements are composed entry by entry, so XLA
    fuses the kernel into a single loop over a batch. ``q`` must be validated (``check_q``).
    """
    dtype = result_dtype(robot, q)
    q = q.astype(dtype)
    K = _constants(robot, dtype)
    qv = [q[i] for i in range(robot.dof)]
    trig = _joint_trig(robot, K, qv)
    Rs, ps = [K.base[0]], [K.base[1]]
    zs, os = [], []
    for j, (kind, parent, qi) in enumerate(
        zip(robot.kinds, robot.parents, robot.q_index, strict=True)
    ):
        R, p = Rs[parent], ps[parent]
        if K.B is not None:
            Rb, pb = K.B[j]
            p = fold.vadd(p, fold.matvec(R, pb))
            R = fold.matmul(R, Rb)
        z = fold.matvec(R, K.axis[j])
        zs.append(z)
        os.append(p)
        if kind != "fixed":
            value = fold.add(fold.mul(K.mult[j], qv[qi]), K.offset[j])
            if kind == "revolute":
                M = fold.rotation_about(K.axis[j], *trig[j])
                R = fold.matmul(R, M)
            else:
                p = fold.vadd(p, fold.vscale(z, value))
        if K.A is not None:
            Ra, pa = K.A[j]
            p = fold.vadd(p, fold.matvec(R, pa))
            R = fold.matmul(R, Ra)
        Rs.append(R)
        ps.append(p)
    if K.tool is not None:
        R, p = Rs[-1], ps[-1]
        ps.append(fold.vadd(p, fold.matvec(R, K.tool[1])))
        Rs.append(fold.matmul(R, K.tool[0]))
    return ScalarPass(R=Rs, p=ps, z=zs, o=os, dtype=dtype)


class ForwardPass(NamedTuple):
    """Everything one pass down the tree yields, all in world coordinates.

    ``R`` (n_frames, 3, 3) and ``p`` (n_frames, 3): frame orientations and origins;
    ``z`` (n_joints, 3): each joint's unit axis; ``o`` (n_joints, 3): a point on each joint's axis
    (the origin of the frame in which the joint moves: o_{i-1} of Table 4.1 in standard DH).
    """

    R: jax.Array
    p: jax.Array
    z: jax.Array
    o: jax.Array


SCAN_MIN_JOINTS = 32


def uses_scan(robot: Robot) -> bool:
    """Long serial chains run through ``lax.scan`` (compile time independent of length)."""
    return robot.n_joints >= SCAN_MIN_JOINTS and robot.parents == tuple(range(robot.n_joints))


def scan_pass(robot: Robot, q: jax.Array) -> ForwardPass:
    """The forward pass of a serial chain as one ``lax.scan`` step per joint.

    Every joint is the same step: ``B``, then a rotation by ``is_revolute * value`` about the
    axis and a translation by ``is_prismatic * value`` along it, then ``A`` (fixed joints have
    both flags 0). Compile time does not grow with the number of joints.
    """
    dtype = result_dtype(robot, q)
    q = q.astype(dtype)
    n = robot.n_joints
    place = joint_placements(robot, dtype)
    eye = jnp.broadcast_to(jnp.eye(3, dtype=dtype), (n, 3, 3))
    zero3 = jnp.zeros((n, 3), dtype=dtype)
    B_R, B_p = place.B if place.B is not None else (eye, zero3)
    A_R, A_p = place.A if place.A is not None else (eye, zero3)
    axis = robot.axis.astype(dtype)
    if robot.parameterisation != "placement":
        axis = jnp.broadcast_to(jnp.array([0.0, 0.0, 1.0], dtype=dtype), (n, 3))
    kinds = np.array(robot.kinds)
    is_rev = jnp.asarray(kinds == "revolute", dtype=dtype)
    is_pri = jnp.asarray(kinds == "prismatic", dtype=dtype)
    qidx = np.maximum(np.array(robot.q_index), 0)
    value = robot.multiplier.astype(dtype) * q[qidx] + robot.offset.astype(dtype)
    base = robot.base.astype(dtype)

    def step(carry, x):
        R, p = carry
        BR, Bp, ax, val, rev, pri, AR, Ap = x
        p = p + R @ Bp
        R = R @ BR
        z = R @ ax
        o = p
        angle = rev * val
        R = R @ spatial.rotation_about_axis(ax, angle)
        p = p + z * (pri * val)
        p = p + R @ Ap
        R = R @ AR
        return (R, p), (R, p, z, o)

    xs = (B_R, B_p, axis, value, is_rev, is_pri, A_R, A_p)
    _, (Rs, ps, zs, os) = jax.lax.scan(step, (base[:3, :3], base[:3, 3]), xs)
    Rs = jnp.concatenate([base[None, :3, :3], Rs])
    ps = jnp.concatenate([base[None, :3, 3], ps])
    if robot.has_tool:
        tool = robot.tool.astype(dtype)
        Rs = jnp.concatenate([Rs, (Rs[-1] @ tool[:3, :3])[None]])
        ps = jnp.concatenate([ps, (ps[-1] + Rs[-2] @ tool[:3, 3])[None]])
    return ForwardPass(R=Rs, p=ps, z=zs, o=os)


def forward_pass(robot: Robot, q: jax.Array) -> ForwardPass:
    """One pass from the base to every frame, as stacked arrays; q must be validated."""
    if uses_scan(robot):
        return scan_pass(robot, q)
    sp = scalar_pass(robot, q)
    st = lambda x: fold.stack_matrix(x, sp.dtype)  # noqa: E731
    return ForwardPass(R=st(sp.R), p=st(sp.p), z=st(sp.z), o=st(sp.o))


def frame_pose(robot: Robot, q: jax.Array, frame: int) -> tuple[jax.Array, jax.Array]:
    """``(R, p)`` of one frame (by index) in world coordinates; q must be validated."""
    if uses_scan(robot):
        fp = scan_pass(robot, q)
        return fp.R[frame], fp.p[frame]
    sp = scalar_pass(robot, q)
    return fold.stack_matrix(sp.R[frame], sp.dtype), fold.stack_matrix(sp.p[frame], sp.dtype)


def fk_all(robot: Robot, q: Any) -> jax.Array:
    """Poses ``T_world_frame`` of every frame, shape (n_frames, 4, 4), in ``robot.frame_names``
    order (base first, tool last when present).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q = jnp.array([0.0, jnp.pi / 2])
    >>> Ts = jk.fk_all(robot, q)
    >>> Ts.shape, robot.frame_names
    ((3, 4, 4), ('base', 'link1', 'link2'))
    >>> bool(jnp.allclose(Ts[-1], jk.fk(robot, q)))  # the last frame is the tip
    True
    """
    return eager(_fk_all, robot, (), check_q(robot, q, fn="jk.fk_all"))


def _fk_all(robot: Robot, q: jax.Array) -> jax.Array:
    if uses_scan(robot):
        fp = scan_pass(robot, q)
        return jax.vmap(spatial.make_transform)(fp.R, fp.p)
    sp = scalar_pass(robot, q)
    return jnp.stack([_pose(R, p, sp.dtype) for R, p in zip(sp.R, sp.p, strict=True)])


def fk(robot: Robot, q: Any, frame: int | str | None = None) -> jax.Array:
    """Pose ``T_world_frame`` of one frame (default: the tip, tool included), shape (4, 4).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")  # two unit links in the xy plane
    >>> T = jk.fk(robot, jnp.array([0.0, jnp.pi / 2]))
    >>> T.shape
    (4, 4)
    >>> T[:2, 3].round(6).tolist()  # the tip: link 1 along x, then link 2 along y
    [1.0, 1.0]
    """
    q = check_q(robot, q, fn="jk.fk")
    return eager(frame_transform, robot, (robot.frame_index(frame),), q)


def frame_transform(robot: Robot, f: int, q: jax.Array) -> jax.Array:
    """``T_world_frame`` (4, 4) of frame index ``f``; the kernel of :func:`fk` (q checked)."""
    if uses_scan(robot):
        R, p = frame_pose(robot, q, f)
        return spatial.make_transform(R, p)
    sp = scalar_pass(robot, q)
    return _pose(sp.R[f], sp.p[f], sp.dtype)


def _pose(R, p, dtype) -> jax.Array:
    rows = [(*R[i], p[i]) for i in range(3)] + [(0.0, 0.0, 0.0, 1.0)]
    return fold.stack_matrix(rows, dtype)
