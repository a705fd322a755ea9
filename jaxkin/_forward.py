"""Private: the one forward pass, unchecked (the kernels behind :mod:`jaxkin.kinematics` and
every Jacobian).

Kernels take ``(robot, q, frame, ...)``: a checked configuration ``q`` of shape ``(nq,)`` (see
``_checks.check_q``) and frame indices (``robot.frame_index``); nothing is checked again here,
so solvers call them inside their loops. All poses are in the world frame (the frame
``robot.base`` is expressed in). Free and ball joints' quaternions (and planar joints'
(cos, sin) pairs) are normalised inside the kernel, as MuJoCo's ``mj_kinematics`` does.

Two passes, one choice (:func:`scan_joints`): :func:`scalar_pass` unrolls the path with the
model's constants folded (short paths, every tree), :func:`scan_pass` runs a long serial path
through ``lax.scan``. :func:`forward_pass` gives every frame, :func:`frame_pose` and
:func:`frame_transform` one frame, :func:`frame_transforms` several frames from one pass.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _fold as fold
from . import spatial
from ._checks import is_traced, result_dtype
from .model import JOINT_SIZES, Robot
from .placements import joint_placements

__all__ = [
    "SCAN_MIN_JOINTS",
    "SCAN_MIN_UNFOLDED",
    "ForwardPass",
    "ScalarPass",
    "ScanPass",
    "all_frame_transforms",
    "forward_pass",
    "frame_pose",
    "frame_poses",
    "frame_transform",
    "frame_transforms",
    "joint_motion",
    "path_joints",
    "scalar_pass",
    "scan_joints",
    "scan_pass",
    "scan_steps",
    "shared_scalar_pass",
    "snap_tolerance",
    "unfolded_joints",
]  # and uses_scan, the public face of scan_joints (jaxkin.kinematics re-exports it)


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


def _joint_trig(robot: Robot, K: _Constants, qv: dict, joints, materialise: bool) -> dict:
    """cos and sin of each revolute joint's value among ``joints``, computed once and together.

    XLA's CPU pipeline removes ``optimization_barrier`` and fuses an elementwise producer into
    every consumer, so a batched kernel whose results XLA splits into many fusions (a Jacobian:
    one per shared intermediate) re-derived each sine and cosine in each of them (a humanoid
    hand's Jacobian: 36 sin/cos ops for 9 joints). With ``materialise`` both are read through
    an identity gather: a gather reuses its operand's elements, so XLA computes the stacked
    (2, k) array once, into one buffer, and the fusions load it (a copy: the same values; the
    arithmetic around them may contract into FMAs differently, a few ulps). Without it (the
    poses: XLA already computes them once there) the program is as before.
    """
    values = {}
    for j in joints:
        if robot.kinds[j] == "revolute":
            values[j] = fold.add(fold.mul(K.mult[j], qv[robot.q_index[j]]), K.offset[j])
    if not values:
        return {}
    keys = list(values)
    dtype = jnp.result_type(*values.values())  # as jnp.stack promotes them
    v = fold.stack_vector([values[j] for j in keys], dtype)  # one fusion, however many joints
    if not materialise:
        c, s = jax.lax.optimization_barrier((jnp.cos(v), jnp.sin(v)))
        return {j: (c[i], s[i]) for i, j in enumerate(keys)}
    cs = jax.lax.optimization_barrier(jnp.stack([jnp.cos(v), jnp.sin(v)]))
    idx = np.arange(len(keys))  # the identity gather that materialises them (see above)
    cs = cs.at[:, idx].get(indices_are_sorted=True, unique_indices=True)
    return {j: (cs[0, i], cs[1, i]) for i, j in enumerate(keys)}


_MULTI = ("free", "ball", "planar")


def joint_motion(kind: str, coords: list) -> tuple:
    """``(R, t)`` of a free, ball or planar joint's motion (child frame in the joint frame) from
    its coordinates (see :mod:`jaxkin.configuration`); ``t`` is None for a ball joint."""
    if kind == "free":
        return spatial.quaternion_rotation(*coords[3:]), tuple(coords[:3])
    if kind == "ball":
        return spatial.quaternion_rotation(*coords), None
    x, y, c, s = coords
    c, s = spatial.max_scaled(c, s)
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


def scalar_pass(
    robot: Robot,
    q: jax.Array,
    frames=None,
    root: int | None = None,
    materialise_trig: bool = False,
) -> ScalarPass:
    """One pass from the base to every frame (or to ``frames`` only: frame indices), elementwise
    and with constants folded.

    Each joint's sin and cos are computed once; placements are composed entry by entry, so XLA
    fuses the kernel into a single loop over a batch. With ``frames`` only the joints on their
    paths are traced (one frame of a large tree costs its depth, not the tree's size). With
    ``root`` (a frame index on every path of ``frames``) the poses are relative to that frame
    (identity at ``root``) and only the joints below it are computed: the model's constants
    fold below a free-flyer, whose rotation is then applied once per result instead of into
    every pose. ``materialise_trig``: XLA computes the sines and cosines once, into one
    buffer, however many fusions read them (the Jacobian kernels; see :func:`_joint_trig`).
    ``q`` must be validated (``check_q``).
    """
    dtype = result_dtype(robot, q)
    q = q.astype(dtype)
    n = robot.n_joints
    joints = list(range(n)) if frames is None else path_joints(robot, frames)
    if root is not None:
        joints = [j for j in joints if root - 1 in robot.ancestors(j + 1)[:-1]]
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
    trig = _joint_trig(robot, K, qv, joints, materialise_trig)
    Rs: list = [None] * robot.n_frames
    ps: list = [None] * robot.n_frames
    zs: list = [None] * n
    os: list = [None] * n
    Rs[0], ps[0] = K.base
    if root is not None:
        Rs[root], ps[root] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), (0.0, 0.0, 0.0)
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
"""A path of at least this many joints runs through ``lax.scan`` (compile time independent of
its length)."""

SCAN_MIN_UNFOLDED = 8
"""A path with at least this many joints whose constants do not fold (:func:`unfolded_joints`)
runs through ``lax.scan`` too. Unrolled, XLA's CPU compiler copies the shared forward pass into
every output it fuses, so the program grows with the square of the depth (one Jacobian of a
15-joint random tree: 107,000 HLO lines, 23 s to compile), and beyond about 8 such joints the
unrolled kernel is also the slower one (random DH chains of 8 joints: compile 2.1 s against
0.44 s, 0.30 against 0.48 M Jacobians/s batched). Robots whose placements are +-90 degree turns
about coordinate axes (the Panda, the UR arms) fold almost entirely and stay unrolled."""


def unfolded_joints(robot: Robot) -> np.ndarray:
    """Per joint, True when its constants do not fold away (a placement rotation that is not a
    signed permutation, or a tilted axis); every joint of a robot with traced leaves."""
    if is_traced(robot):
        return np.ones(robot.n_joints, dtype=bool)
    return _unfolded_joints(robot)


@functools.lru_cache(maxsize=64)
def _unfolded_joints(robot: Robot) -> np.ndarray:
    tol = snap_tolerance(robot.dtype)

    def exact(a) -> np.ndarray:  # per joint: every entry within tol of 0 or +-1
        a = np.abs(np.asarray(a, dtype=np.float64)).reshape(robot.n_joints, -1)
        return np.all((a <= tol) | (np.abs(a - 1.0) <= tol), axis=1)

    place = joint_placements(robot, np.float64, xp=np)
    folds = np.ones(robot.n_joints, dtype=bool)
    for pl in (place.B, place.A):
        if pl is not None:
            folds &= exact(pl[0])
    if robot.parameterisation == "placement":
        folds &= exact(robot.axis)
    return ~folds


def scan_joints(robot: Robot, frame: int | None = None) -> tuple[int, ...] | None:
    """The joints a ``lax.scan`` pass runs over, or None for the unrolled :func:`scalar_pass`.

    ``frame=None``: the whole robot, scanned when it is a serial chain; a frame index: the joints
    on that frame's path from the base (one frame of a large tree costs its depth). Scanned when
    the path has at least :data:`SCAN_MIN_JOINTS` joints or :data:`SCAN_MIN_UNFOLDED` joints whose
    constants do not fold, and only 1-dof and fixed joints.
    """
    n = robot.n_joints
    if frame is None:
        if robot.parents != tuple(range(n)):
            return None
        path = tuple(range(n))
    else:
        path = robot.ancestors(frame)
    if any(robot.kinds[j] not in ("revolute", "prismatic", "fixed") for j in path):
        return None
    if len(path) >= SCAN_MIN_JOINTS or (
        len(path) >= SCAN_MIN_UNFOLDED
        and int(np.sum(unfolded_joints(robot)[list(path)])) >= SCAN_MIN_UNFOLDED
    ):
        return path
    return None


def uses_scan(robot: Robot) -> bool:
    """Whether the whole robot's forward pass runs through ``lax.scan`` (compile time independent
    of its length) rather than unrolled with the model's constants folded: a serial chain of
    1-dof and fixed joints with at least 32 joints, or with at least 8 joints whose constants do
    not fold (a placement rotation that is not a signed permutation, or a tilted axis). One
    frame's path in a tree is judged the same way, and only the joints on it are computed.

    >>> import jaxkin as jk
    >>> jk.kinematics.uses_scan(jk.robots.load("panda"))
    False
    """
    return scan_joints(robot) is not None


class ScanPass(NamedTuple):
    """The forward pass along a serial path from :func:`scan_steps`, entries as scalars: one
    (m,) array per entry (m path joints; (m, N) under ``vmap``) or a Python float (an entry
    constant along the path, folded).

    ``R``, ``p``: the last frame's pose (the tool frame's with ``tool``); ``z``, ``o``: per path
    joint its axis and a point on it, as 3-tuples of (m,) arrays; ``Rs``, ``ps``: every path
    joint's child frame (with ``frames``; else None)."""

    R: tuple
    p: tuple
    z: tuple
    o: tuple
    Rs: tuple | None
    ps: tuple | None
    dtype: Any


def _along_path(a, dtype, concrete: bool):
    """A per-joint constant (m,) as one scan input, or a Python float when the robot is concrete
    and the value is the same for every joint of the path (it then folds, as in
    :func:`scalar_pass`; no snapping: the scan uses the model's values as they are)."""
    if concrete:
        a = np.asarray(a, dtype=np.float64)
        if a.size and np.all(a == a[0]):
            return float(a[0])
    return jnp.asarray(a, dtype=dtype)


def scan_steps(
    robot: Robot, q: jax.Array, joints=None, tool: bool = False, frames: bool = False
) -> ScanPass:
    """The forward pass along a serial path as one ``lax.scan`` step per joint, elementwise.

    ``joints``: the path (joint indices from the base, each joint's parent frame the previous
    joint's child; default every joint of a serial chain); 1-dof and fixed joints. Every joint
    is the same step: ``B``, then a rotation about the axis by the joint's value (revolute) and a
    translation along it (prismatic), then ``A``. The carry is the pose as 12 scalars and every
    operation is a scalar one (per-joint constants as (m,) scan inputs, or folded when constant
    along the path; sines and cosines computed once for the whole path before the loop), so
    under ``vmap`` each carry is one (N,) array: a structure-of-arrays loop that XLA fuses per
    step, where 3x3 products batched first were small ``dot`` ops (the 32-joint chain's batched
    Jacobian 3-4x slower). Compile time does not grow with the number of joints.
    """
    dtype = result_dtype(robot, q)
    q = q.astype(dtype)
    n = robot.n_joints
    path = np.arange(n) if joints is None else np.asarray(joints, dtype=np.int64).reshape(-1)
    concrete = not is_traced(robot)
    xp = np if concrete else jnp
    conv = (lambda a: np.asarray(a, np.float64)) if concrete else (lambda a: a.astype(dtype))
    place = joint_placements(robot, dtype, xp=xp)
    col = lambda a: _along_path(a, dtype, concrete)  # noqa: E731
    eye = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    zero = (0.0, 0.0, 0.0)

    def pose(pl):
        if pl is None:
            return eye, zero
        M, v = pl
        return (
            tuple(tuple(col(M[path, i, j]) for j in range(3)) for i in range(3)),
            tuple(col(v[path, i]) for i in range(3)),
        )

    if robot.parameterisation != "placement":
        axis = (0.0, 0.0, 1.0)  # DH joints move about z by construction
    else:
        a = conv(robot.axis)
        axis = tuple(col(a[path, i]) for i in range(3))
    kinds = np.array(robot.kinds, dtype=object)[path]
    rev, pri = kinds == "revolute", kinds == "prismatic"
    qidx = np.maximum(np.array(robot.q_index, dtype=np.int64)[path], 0)
    value = jnp.asarray(conv(robot.multiplier)[path], dtype) * q[qidx] + jnp.asarray(
        conv(robot.offset)[path], dtype
    )
    angle = value if rev.all() else value * jnp.asarray(rev, dtype)
    trig = jax.lax.optimization_barrier(jnp.stack([jnp.cos(angle), jnp.sin(angle)]))
    consts = {
        "B": pose(place.B),
        "A": pose(place.A),
        "axis": axis,
        "c": trig[0],
        "s": trig[1],
        "d": value * jnp.asarray(pri, dtype) if pri.any() else 0.0,
    }
    leaves, tree = jax.tree_util.tree_flatten(consts)
    scanned = [i for i, leaf in enumerate(leaves) if not fold.is_const(leaf)]
    m = len(path)

    def unpack(x) -> dict:
        out = list(leaves)
        for i, v in zip(scanned, x, strict=True):
            out[i] = v
        return jax.tree_util.tree_unflatten(tree, out)

    def arrays(t):
        return jax.tree_util.tree_map(lambda v: fold.materialize(v, dtype), t)

    def step(carry, x):
        R, p = carry
        k = unpack(x)
        (BR, Bp), (AR, Ap), ax = k["B"], k["A"], k["axis"]
        p = fold.vadd(p, fold.matvec(R, Bp))
        R = fold.matmul(R, BR)
        z = fold.matvec(R, ax)
        o = p
        R = fold.matmul(R, fold.rotation_about(ax, k["c"], k["s"]))
        p = fold.vadd(p, fold.vscale(z, k["d"]))
        p = fold.vadd(p, fold.matvec(R, Ap))
        R = fold.matmul(R, AR)
        R, p = arrays(R), arrays(p)
        return (R, p), arrays((z, o, R, p) if frames else (z, o))

    base = jnp.asarray(robot.base, dtype)
    R0 = tuple(tuple(base[i, j] for j in range(3)) for i in range(3))
    p0 = tuple(base[i, 3] for i in range(3))
    xs = [jnp.broadcast_to(leaves[i], (m,)).astype(dtype) for i in scanned]
    if m:
        (R, p), ys = jax.lax.scan(step, (R0, p0), xs)
    else:  # the base frame (op by op, a zero-length scan has no output type)
        none = (jnp.zeros((0,), dtype),) * 3
        R, p, ys = R0, p0, (none, none, (none,) * 3, none)
    if tool:
        T = conv(robot.tool)
        entry = (lambda i, j: float(T[i, j])) if concrete else (lambda i, j: T[i, j])
        p = fold.vadd(p, fold.matvec(R, tuple(entry(i, 3) for i in range(3))))
        R = fold.matmul(R, tuple(tuple(entry(i, j) for j in range(3)) for i in range(3)))
    z, o = ys[0], ys[1]
    Rs, ps = (ys[2], ys[3]) if frames else (None, None)
    return ScanPass(R=R, p=p, z=z, o=o, Rs=Rs, ps=ps, dtype=dtype)


def scan_pass(robot: Robot, q: jax.Array, joints=None, tool: bool = False) -> ForwardPass:
    """The forward pass along a serial path (:func:`scan_steps`) as stacked arrays.

    ``joints``: the path (default every joint of a serial chain). The result has the base, then
    one frame per path joint (then the tool frame, for the whole chain or with ``tool=True``) in
    ``R`` and ``p``, and one entry per path joint in ``z`` and ``o``.
    """
    with_tool = robot.has_tool and (joints is None or tool)
    sp = scan_steps(robot, q, joints, tool=with_tool, frames=True)
    dtype = sp.dtype
    base = robot.base.astype(dtype)
    Rs = jnp.moveaxis(fold.stack_matrix(sp.Rs, dtype), -1, 0)  # (m, 3, 3)
    ps = jnp.moveaxis(fold.stack_matrix(sp.ps, dtype), -1, 0)
    Rs = jnp.concatenate([base[None, :3, :3], Rs])
    ps = jnp.concatenate([base[None, :3, 3], ps])
    if with_tool:
        Rs = jnp.concatenate([Rs, fold.stack_matrix(sp.R, dtype)[None]])
        ps = jnp.concatenate([ps, fold.stack_matrix(sp.p, dtype)[None]])
    z = jnp.stack(sp.z, axis=-1)
    o = jnp.stack(sp.o, axis=-1)
    return ForwardPass(R=Rs, p=ps, z=z, o=o)


def forward_pass(robot: Robot, q: jax.Array) -> ForwardPass:
    """One pass from the base to every frame, as stacked arrays; q must be validated."""
    if scan_joints(robot) is not None:
        return scan_pass(robot, q)
    sp = scalar_pass(robot, q)
    st = lambda x: fold.stack_matrix(x, sp.dtype)  # noqa: E731
    return ForwardPass(R=st(sp.R), p=st(sp.p), z=st(sp.z), o=st(sp.o))


def frame_pose(robot: Robot, q: jax.Array, frame: int) -> tuple[jax.Array, jax.Array]:
    """``(R, p)`` of one frame (by index) in world coordinates; q must be validated."""
    path = scan_joints(robot, frame)
    if path is not None:
        is_tool = robot.has_tool and frame == robot.n_joints + 1
        fp = scan_pass(robot, q, path, tool=is_tool)
        return fp.R[-1], fp.p[-1]
    sp = scalar_pass(robot, q, frames=(frame,))
    return fold.stack_matrix(sp.R[frame], sp.dtype), fold.stack_matrix(sp.p[frame], sp.dtype)


def frame_transform(robot: Robot, q: jax.Array, frame: int) -> jax.Array:
    """``T_world_frame`` (4, 4) of one frame (by index): the pose of :func:`frame_pose` as one
    matrix, the kernel of ``jk.fk``; q must be validated. Only the joints on the frame's path
    are computed."""
    if scan_joints(robot, frame) is not None:
        R, p = frame_pose(robot, q, frame)
        return spatial.make_transform(R, p)
    sp = scalar_pass(robot, q, frames=(frame,))
    return _pose(sp.R[frame], sp.p[frame], sp.dtype)


def _pose(R, p, dtype) -> jax.Array:
    rows = [(*R[i], p[i]) for i in range(3)] + [(0.0, 0.0, 0.0, 1.0)]
    return fold.stack_matrix(rows, dtype)


def all_frame_transforms(robot: Robot, q: jax.Array) -> jax.Array:
    """``T_world_frame`` of every frame, shape (n_frames, 4, 4), from one :func:`forward_pass`;
    the kernel of :func:`jaxkin.fk_all`."""
    if scan_joints(robot) is not None:
        fp = scan_pass(robot, q)
        return jax.vmap(spatial.make_transform)(fp.R, fp.p)
    sp = scalar_pass(robot, q)
    return jnp.stack([_pose(R, p, sp.dtype) for R, p in zip(sp.R, sp.p, strict=True)])


# ------------------------------------------------------------------ several frames, one pass
def shared_scalar_pass(
    robot: Robot, q: jax.Array, frames: tuple[int, ...], materialise_trig: bool = False
) -> ScalarPass | None:
    """One :func:`scalar_pass` over the union of the paths of those ``frames`` (indices) that
    :func:`scan_joints` leaves unrolled: each joint on them is computed once, however many of the
    frames it moves. None when every frame's path is scanned (long serial paths: one
    :func:`scan_pass` each). ``materialise_trig`` as for :func:`scalar_pass`."""
    unrolled = tuple(dict.fromkeys(f for f in frames if scan_joints(robot, f) is None))
    if not unrolled:
        return None
    return scalar_pass(robot, q, frames=unrolled, materialise_trig=materialise_trig)


def frame_poses(robot: Robot, q: jax.Array, frames: tuple[int, ...]) -> tuple[jax.Array, jax.Array]:
    """``(R (k, 3, 3), p (k, 3))`` of several frames (indices, in the order given, duplicates
    allowed) from one pass (:func:`shared_scalar_pass`); row i is :func:`frame_pose` of
    ``frames[i]``, bit for bit. q must be validated."""
    sp = shared_scalar_pass(robot, q, frames)
    poses = [
        frame_pose(robot, q, f)
        if scan_joints(robot, f) is not None
        else (fold.stack_matrix(sp.R[f], sp.dtype), fold.stack_matrix(sp.p[f], sp.dtype))
        for f in frames
    ]
    return jnp.stack([R for R, _ in poses]), jnp.stack([p for _, p in poses])


def frame_transforms(robot: Robot, q: jax.Array, frames: tuple[int, ...]) -> jax.Array:
    """``T_world_frame`` (k, 4, 4) of several frames (indices, in the order given, duplicates
    allowed) from one pass (:func:`shared_scalar_pass`); row i is :func:`frame_transform` of
    ``frames[i]``, bit for bit. The kernel of ``jk.fk(robot, q, frame=[...])``; q must be
    validated."""
    sp = shared_scalar_pass(robot, q, frames)
    return jnp.stack(
        [
            frame_transform(robot, q, f)
            if scan_joints(robot, f) is not None
            else _pose(sp.R[f], sp.p[f], sp.dtype)
            for f in frames
        ]
    )
