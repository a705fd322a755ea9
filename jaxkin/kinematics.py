"""Forward kinematics: poses of every frame, and the one forward pass the Jacobians reuse.

All poses are in the world frame (the frame ``robot.base`` is expressed in; the robot's base frame
when ``base`` is None): ``T_world_frame``, shape (4, 4). Kernels take one configuration ``q`` of
shape ``(nq,)``; batch with ``jax.vmap``.

Free and ball joints' quaternions (and planar joints' (cos, sin) pairs) are normalised inside the
kernel, as MuJoCo's ``mj_kinematics`` does: any nonzero quaternion is the rotation of its unit
multiple. A zero or non-finite one raises eagerly (:func:`jaxkin._checks.check_q`) and gives NaN
under ``jit``/``vmap``.
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
from .model import JOINT_SIZES, Robot
from .placements import joint_placements

__all__ = [
    "ForwardPass",
    "ScalarPass",
    "fk",
    "fk_all",
    "forward_pass",
    "frame_pose",
    "path_joints",
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


def snap_tolerance(dtype) -> float:
    """How far from 0 or +-1 a concrete constant of a robot stored in ``dtype`` is taken as exact.

    float64: 1e-15 (``cos(pi/2)`` evaluates to 6e-17). float32: the angles themselves are rounded
    to float32 (``float32(pi/2)`` is 4.4e-8 from pi/2, so its cosine is -4.4e-8), up to half an
    ulp of an angle below 2 pi: 2.4e-7; ``4 * eps32`` (4.8e-7) covers it. Snapping moves a float32
    result by about that much times the reach, far inside float32 tolerances, and gives the
    float32 program the structure of the float64 one (the +-90 degree placements fold away).
    """
    return max(SNAP, 4.0 * float(np.finfo(np.dtype(dtype)).eps))


def _snap(x, tol: float = SNAP) -> float:
    """A concrete constant as a Python float; within ``tol`` of 0 or +-1 it is taken as exact
    (see :func:`snap_tolerance`), so +-90 degree placements fold away."""
    x = float(x)
    for exact in (0.0, 1.0, -1.0):
        if abs(x - exact) <= tol:
            return exact
    return x


def _scalars(x, to_scalar):
    if getattr(x, "ndim", 0) == 0:
        return to_scalar(x)
    return tuple(_scalars(x[i], to_scalar) for i in range(x.shape[0]))


def _constants(robot: Robot, dtype, joints: list | None = None) -> _Constants:
    """Everything the forward pass needs from the model, as scalars.

    With concrete leaves (a robot closed over by ``jit``, or eager use) the constants are Python
    floats computed in float64 and folded into the kernel; with traced leaves (``jit`` over the
    robot, ``grad`` with respect to its parameters, ``vmap`` over a stack of robots) they are JAX
    scalars and new values never retrace. Only the ``joints`` listed (default: all) are
    converted; the per-joint lists hold None for the others.
    """
    if not is_traced(robot):
        xp, conv = np, lambda a: np.asarray(a, dtype=np.float64)
        tol = snap_tolerance(robot.dtype)
        to_scalar = lambda a: _snap(a, tol)  # noqa: E731
    else:
        xp, conv = jnp, lambda a: jnp.asarray(a).astype(dtype)
        to_scalar = lambda a: a  # noqa: E731
    place = joint_placements(robot, dtype, xp=xp)
    n = robot.n_joints
    idx = range(n) if joints is None else joints

    def per_joint(a) -> list:
        out: list = [None] * n
        if joints is not None and xp is jnp:
            # one gather of the path's rows: its transpose (grad over the robot) is one
            # scatter, not one full-size pad per joint
            a = a[np.asarray(joints, dtype=np.int32)]
            for k, j in enumerate(joints):
                out[j] = _scalars(a[k], to_scalar)
            return out
        for j in idx:
            out[j] = _scalars(a[j], to_scalar)
        return out

    def pairs(pl):
        if pl is None:
            return None
        return list(zip(per_joint(pl[0]), per_joint(pl[1]), strict=True))

    if robot.parameterisation != "placement":
        axis = [(0.0, 0.0, 1.0)] * n  # DH joints move about z by construction
    else:
        axis = per_joint(conv(robot.axis))
    base = conv(robot.base)
    tool = conv(robot.tool)
    return _Constants(
        B=pairs(place.B),
        A=pairs(place.A),
        axis=axis,
        offset=per_joint(conv(robot.offset)),
        mult=per_joint(conv(robot.multiplier)),
        base=(_scalars(base[:3, :3], to_scalar), _scalars(base[:3, 3], to_scalar)),
        tool=(_scalars(tool[:3, :3], to_scalar), _scalars(tool[:3, 3], to_scalar))
        if robot.has_tool
        else None,
    )


def _joint_trig(robot: Robot, K: _Constants, qv: dict, joints) -> dict:
    """cos and sin of each revolute joint's value among ``joints``, computed once and together.

    The optimisation barrier asks XLA not to re-derive them inside each fusion of the kernel
    (its CPU pipeline may still drop it; see PERFORMANCE.md).
    """
    values = {}
    for j in joints:
        if robot.kinds[j] == "revolute":
            values[j] = fold.add(fold.mul(K.mult[j], qv[robot.q_index[j]]), K.offset[j])
    if not values:
        return {}
    keys = list(values)
    v = jnp.stack([jnp.asarray(values[j]) for j in keys])
    c, s = jax.lax.optimization_barrier((jnp.cos(v), jnp.sin(v)))
    return {j: (c[i], s[i]) for i, j in enumerate(keys)}


_MULTI = ("free", "ball", "planar")


def quaternion_rotation(w, x, y, z) -> tuple:
    """The rotation (nested tuples) of the quaternion ``(w, x, y, z)`` divided by its norm:
    ``I + 2 / |q|^2 (w [v]x + [v]x^2)``, so a non-unit quaternion gives the rotation of its unit
    multiple and the zero quaternion gives NaN."""
    s = 2.0 / (w * w + x * x + y * y + z * z)
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    return (
        (1.0 - (yy + zz), xy - wz, xz + wy),
        (xy + wz, 1.0 - (xx + zz), yz - wx),
        (xz - wy, yz + wx, 1.0 - (xx + yy)),
    )


def joint_motion(kind: str, coords: list) -> tuple:
    """``(R, t)`` of a free, ball or planar joint's motion (child frame in the joint frame) from
    its coordinates (see :mod:`jaxkin.configuration`); ``t`` is None for a ball joint."""
    if kind == "free":
        return quaternion_rotation(*coords[3:]), tuple(coords[:3])
    if kind == "ball":
        return quaternion_rotation(*coords), None
    x, y, c, s = coords
    inv = jax.lax.rsqrt(c * c + s * s)
    c, s = c * inv, s * inv
    return ((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0)), (x, y, 0.0)


class ScalarPass(NamedTuple):
    """The forward pass as nested tuples of scalars (constants folded); see :class:`ForwardPass`.

    When the pass was asked for some frames only, the entries of frames and joints off their
    paths are None."""

    R: list  # per frame: Mat
    p: list  # per frame: Vec
    z: list  # per joint: Vec
    o: list  # per joint: Vec
    dtype: Any


def path_joints(robot: Robot, frames) -> list:
    """Joints on the paths from the base to ``frames`` (frame indices), in increasing order."""
    joints: set = set()
    for f in frames:
        joints.update(robot.ancestors(f))
    return sorted(joints)


def scalar_pass(robot: Robot, q: jax.Array, frames=None) -> ScalarPass:
    """One pass from the base to every frame (or to ``frames`` only: frame indices), elementwise
    and with constants folded.

    Each joint's sin and cos are computed once; placements are composed entry by entry, so XLA
    fuses the kernel into a single loop over a batch. With ``frames`` only the joints on their
    paths are traced (one frame of a large tree costs its depth, not the tree's size). ``q`` must
    be validated (``check_q``).
    """
    dtype = result_dtype(robot, q)
    q = q.astype(dtype)
    n = robot.n_joints
    joints = list(range(n)) if frames is None else path_joints(robot, frames)
    K = _constants(robot, dtype, None if frames is None else joints)
    used = sorted(
        {
            robot.q_index[j] + k
            for j in joints
            if robot.kinds[j] != "fixed"
            for k in range(JOINT_SIZES[robot.kinds[j]][0])
        }
    )
    qv = {i: q[i] for i in used}
    trig = _joint_trig(robot, K, qv, joints)
    Rs: list = [None] * robot.n_frames
    ps: list = [None] * robot.n_frames
    zs: list = [None] * n
    os: list = [None] * n
    Rs[0], ps[0] = K.base
    for j in joints:
        kind, parent, qi = robot.kinds[j], robot.parents[j], robot.q_index[j]
        R, p = Rs[parent], ps[parent]
        if K.B is not None:
            Rb, pb = K.B[j]
            p = fold.vadd(p, fold.matvec(R, pb))
            R = fold.matmul(R, Rb)
        z = fold.matvec(R, K.axis[j])
        zs[j] = z
        os[j] = p
        if kind in _MULTI:
            M, t = joint_motion(kind, [qv[qi + k] for k in range(JOINT_SIZES[kind][0])])
            if t is not None:
                p = fold.vadd(p, fold.matvec(R, t))
            R = fold.matmul(R, M)
        elif kind != "fixed":
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
        Rs[j + 1] = R
        ps[j + 1] = p
    if K.tool is not None and (frames is None or n + 1 in frames):
        R, p = Rs[n], ps[n]
        ps[n + 1] = fold.vadd(p, fold.matvec(R, K.tool[1]))
        Rs[n + 1] = fold.matmul(R, K.tool[0])
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
    """Long serial chains of revolute, prismatic and fixed joints run through ``lax.scan``
    (compile time independent of length); a robot with a free, ball or planar joint never does."""
    return (
        robot.n_joints >= SCAN_MIN_JOINTS
        and robot.parents == tuple(range(robot.n_joints))
        and not robot.multi_dof_joints
    )


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
    sp = scalar_pass(robot, q, frames=(frame,))
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
    sp = scalar_pass(robot, q, frames=(f,))
    return _pose(sp.R[f], sp.p[f], sp.dtype)


def _pose(R, p, dtype) -> jax.Array:
    rows = [(*R[i], p[i]) for i in range(3)] + [(0.0, 0.0, 0.0, 1.0)]
    return fold.stack_matrix(rows, dtype)
