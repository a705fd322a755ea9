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

from . import spatial
from .errors import ShapeError
from .model import Robot

__all__ = ["ForwardPass", "check_q", "fk", "fk_all", "forward_pass", "joint_placements"]


def check_q(robot: Robot, q: Any, what: str = "q", fn: str = "this function") -> jax.Array:
    """Validate a joint vector (before tracing) and return it as a float array of shape (dof,)."""
    if not isinstance(robot, Robot):
        raise ShapeError(
            f"{fn} expects a jaxkin Robot as first argument, got {type(robot).__name__}."
        )
    if isinstance(q, (list, tuple)):
        try:
            q = np.asarray(q, dtype=float)
        except (TypeError, ValueError):
            raise ShapeError(f"{what} must be a sequence of numbers, got {q!r}.") from None
    if not (hasattr(q, "shape") and hasattr(q, "dtype")):
        try:
            q = np.asarray(q)
        except (TypeError, ValueError):
            raise ShapeError(f"{what} must be an array of numbers, got {q!r}.") from None
    shape = q.shape
    dtype = np.dtype(q.dtype)
    if dtype.kind == "c":
        raise ShapeError(f"{what} must be real, got complex dtype {dtype}.")
    if dtype.kind not in "fiub":
        raise ShapeError(f"{what} must be an array of numbers, got dtype {dtype} ({q!r:.60}).")
    if tuple(shape) != (robot.dof,):
        hint = ""
        if len(shape) >= 2 and shape[-1] == robot.dof:
            hint = (
                f" For a batch of configurations use jax.vmap, e.g. "
                f"jax.vmap(lambda q: {fn}(robot, q))(qs)."
            )
        elif len(shape) == 1:
            hint = f" Give one value per joint {list(robot.joint_names)}."
        raise ShapeError(
            f"{fn}: {what} must have shape ({robot.dof},) for robot {robot.name!r} "
            f"({robot.dof} joints), got shape {tuple(shape)}.{hint}"
        )
    q = jnp.asarray(q)
    if not jnp.issubdtype(q.dtype, jnp.floating):
        q = q.astype(robot.dtype)
    return q


def _result_dtype(robot: Robot, q: jax.Array):
    return jnp.result_type(robot.base.dtype, q.dtype)


class JointPlacements(NamedTuple):
    """Constant parts of every joint's transform, computed once per call from the leaves.

    ``B`` (before the motion) and ``A`` (after it) are ``(R, p)`` pairs of shape (n, 3, 3) and
    (n, 3), or None when the parameterisation makes them the identity.
    """

    B: tuple[jax.Array, jax.Array] | None
    A: tuple[jax.Array, jax.Array] | None


def _dh_standard(params, dtype):
    a, alpha, d, theta = (params[k].astype(dtype) for k in ("a", "alpha", "d", "theta"))
    ct, st, ca, sa = jnp.cos(theta), jnp.sin(theta), jnp.cos(alpha), jnp.sin(alpha)
    z = jnp.zeros_like(a)
    # Rz(theta) Tz(d) Tx(a) Rx(alpha)
    R = jnp.stack(
        [
            jnp.stack([ct, -st * ca, st * sa], -1),
            jnp.stack([st, ct * ca, -ct * sa], -1),
            jnp.stack([z, sa, ca], -1),
        ],
        -2,
    )
    p = jnp.stack([a * ct, a * st, d], -1)
    return R, p


def _dh_modified(params, dtype):
    a, alpha, d, theta = (params[k].astype(dtype) for k in ("a", "alpha", "d", "theta"))
    ct, st, ca, sa = jnp.cos(theta), jnp.sin(theta), jnp.cos(alpha), jnp.sin(alpha)
    z = jnp.zeros_like(a)
    # Rx(alpha) Tx(a) Rz(theta) Tz(d)
    R = jnp.stack(
        [
            jnp.stack([ct, -st, z], -1),
            jnp.stack([ca * st, ca * ct, -sa], -1),
            jnp.stack([sa * st, sa * ct, ca], -1),
        ],
        -2,
    )
    p = jnp.stack([a, -sa * d, ca * d], -1)
    return R, p


def joint_placements(robot: Robot, dtype=None) -> JointPlacements:
    """The constant placements ``B_j`` and ``A_j`` of every joint (see :mod:`jaxkin.model`)."""
    dtype = dtype or robot.dtype
    kind = robot.parameterisation
    if kind == "dh_standard":
        return JointPlacements(B=None, A=_dh_standard(robot.params, dtype))
    if kind == "dh_modified":
        return JointPlacements(B=_dh_modified(robot.params, dtype), A=None)
    xyz = robot.params["xyz"].astype(dtype)
    rpy = robot.params["rpy"].astype(dtype)
    R = jax.vmap(spatial.rpy_to_matrix)(rpy)
    return JointPlacements(B=(R, xyz), A=None)


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


def forward_pass(robot: Robot, q: jax.Array) -> ForwardPass:
    """One pass from the base to every frame; q must already be validated (``check_q``)."""
    dtype = _result_dtype(robot, q)
    q = q.astype(dtype)
    place = joint_placements(robot, dtype)
    axis = robot.axis.astype(dtype)
    offset = robot.offset.astype(dtype)
    mult = robot.multiplier.astype(dtype)
    base = robot.base.astype(dtype)
    dh = robot.parameterisation != "placement"

    Rs = [base[:3, :3]]
    ps = [base[:3, 3]]
    zs, os = [], []
    for j, (kind, parent, qi) in enumerate(
        zip(robot.kinds, robot.parents, robot.q_index, strict=True)
    ):
        R, p = Rs[parent], ps[parent]
        if place.B is not None:
            p = p + R @ place.B[1][j]
            R = R @ place.B[0][j]
        if dh:
            zj = R[:, 2]
        else:
            zj = R @ axis[j]
        zs.append(zj)
        os.append(p)
        if kind != "fixed":
            value = mult[j] * q[qi] + offset[j]
            if kind == "revolute":
                c, s = jnp.cos(value), jnp.sin(value)
                if dh:
                    R = jnp.stack(
                        [R[:, 0] * c + R[:, 1] * s, R[:, 1] * c - R[:, 0] * s, R[:, 2]], 1
                    )
                else:
                    K = spatial.skew(axis[j])
                    M = jnp.eye(3, dtype=dtype) + s * K + (1.0 - c) * (K @ K)
                    R = R @ M
            else:
                p = p + zj * value
        if place.A is not None:
            p = p + R @ place.A[1][j]
            R = R @ place.A[0][j]
        Rs.append(R)
        ps.append(p)
    if robot.has_tool:
        tool = robot.tool.astype(dtype)
        R, p = Rs[-1], ps[-1]
        ps.append(p + R @ tool[:3, 3])
        Rs.append(R @ tool[:3, :3])
    return ForwardPass(R=jnp.stack(Rs), p=jnp.stack(ps), z=jnp.stack(zs), o=jnp.stack(os))


def _to_T(R: jax.Array, p: jax.Array) -> jax.Array:
    top = jnp.concatenate([R, p[..., :, None]], axis=-1)
    bottom = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0], dtype=R.dtype), (*R.shape[:-2], 1, 4))
    return jnp.concatenate([top, bottom], axis=-2)


def fk_all(robot: Robot, q: Any) -> jax.Array:
    """Poses ``T_world_frame`` of every frame, shape (n_frames, 4, 4), in ``robot.frame_names``
    order (base first, tool last when present)."""
    q = check_q(robot, q, fn="jk.fk_all")
    fp = forward_pass(robot, q)
    return _to_T(fp.R, fp.p)


def fk(robot: Robot, q: Any, frame: int | str | None = None) -> jax.Array:
    """Pose ``T_world_frame`` of one frame (default: the tip, tool included), shape (4, 4)."""
    q = check_q(robot, q, fn="jk.fk")
    f = robot.frame_index(frame)
    fp = forward_pass(robot, q)
    return _to_T(fp.R[f], fp.p[f])
