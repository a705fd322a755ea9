"""Jacobians: the hand-built geometric Jacobian (Table 4.1) and the autodiff ones.

Rows are always ``[v; omega]`` (linear first); columns follow the velocity ``v``
(``robot.velocity_names``: the entries of ``q``, ``robot.joint_names``, unless the robot has free,
ball or planar joints, whose columns are those of their velocity coordinates: see
:mod:`jaxkin.configuration`). Every Jacobian has ``robot.nv`` columns.
``reference`` says which point's velocity the linear rows give and in which basis:

==================  =====================================  ======================================
reference           point                                  basis
==================  =====================================  ======================================
``world_aligned``   the frame origin (or ``point``)        world axes (Pinocchio
                                                           LOCAL_WORLD_ALIGNED, RTB ``jacob0``)
``local``           the frame origin (or ``point``)        the frame's own axes (Pinocchio LOCAL,
                                                           RTB ``jacobe``)
``world``           the point coinciding with the world    world axes (Pinocchio WORLD; spatial
                    origin                                 velocity)
==================  =====================================  ======================================

Identities: ``J_local = blkdiag(R^T, R^T) J_world_aligned`` and ``J_world = Ad(T) J_local``,
whose linear rows are ``J_v + skew(p) J_w``.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _fold as fold
from . import spatial
from ._checks import (
    REFERENCES,
    check_point,
    check_q,
    check_reference,
    is_traced,
    result_dtype,
)
from ._jit import eager
from .configuration import integrate_kernel
from .errors import JaxkinError, ShapeError
from .kinematics import frame_pose, scalar_pass, scan_joints, scan_pass
from .model import Robot
from .representations import (
    check_representation,
    from_matrix,
    guard_singular,
    representation_margin,
)

__all__ = [
    "REFERENCES",
    "FrameJacobian",
    "analytical_jacobian",
    "analytical_jacobian_pass",
    "change_reference",
    "frame_jacobian",
    "geometric_jacobian",
    "jacobian_fwd",
    "jacobian_pass",
    "jacobian_rev",
]


def _columns(robot: Robot, sp, target, frame: int) -> tuple[list, list]:
    """Table 4.1 as scalars: per entry of ``v`` the linear and angular column at world point
    ``target``.

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


ZERO_COLUMNS = 16


def _assemble(Jv: list, Jw: list, dtype) -> jax.Array:
    """(6, nv) array from per-column 3-vectors of scalars.

    With at least ``ZERO_COLUMNS`` all-zero constant columns (joints off the frame's path in a
    large tree) the other columns are scattered into a zeros block instead of stacking one
    literal per entry (a concatenation of many pieces compiles slowly)."""
    dof = len(Jv)

    def block(cols):
        rows = [[Jv[k][i] for k in cols] for i in range(3)]
        rows += [[Jw[k][i] for k in cols] for i in range(3)]
        return fold.stack_matrix(rows, dtype)

    nonzero = [
        k for k in range(dof) if not all(fold.is_const(x) and x == 0.0 for x in (*Jv[k], *Jw[k]))
    ]
    if dof - len(nonzero) < ZERO_COLUMNS:
        return block(range(dof))
    J = jnp.zeros((6, dof), dtype)
    if not nonzero:
        return J
    return J.at[:, np.asarray(nonzero)].set(block(nonzero))


def geometric_jacobian(
    robot: Robot,
    q: Any,
    frame: int | str | None = None,
    point: Any = None,
    reference: str = "world_aligned",
) -> jax.Array:
    """Geometric Jacobian ``J(q)`` with ``[v; omega] = J(q) @ qd``; shape (6, nv).

    Built column by column from one forward pass (the chapter's Table 4.1): a revolute joint i
    contributes ``[z_i x (p - o_i); z_i]``, a prismatic one ``[z_i; 0]``, a joint not on the path
    to ``frame`` a zero column. A free, ball or planar joint contributes one column per entry of
    its velocity (child-frame axes, :mod:`jaxkin.configuration`), so ``qd`` is a velocity of
    shape (nv,), not a time derivative of ``q``. Elementwise, with the model's constants folded
    when the robot is concrete (see :func:`jaxkin.kinematics.scalar_pass`).

    Args:
      robot: the robot.
      q: joint values, shape (nq,).
      frame: frame name or index (default: the tip, tool included).
      point: optional offset (3,) of the point of interest from the frame origin, in the frame's
        own axes; the linear rows then give that point's velocity.
      reference: ``"world_aligned"`` (default), ``"local"`` or ``"world"``; see the module doc.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))
    >>> J.shape
    (6, 2)
    >>> J[0].round(6).tolist(), J[5].round(6).tolist()  # v_x and omega_z rows
    ([-1.0, -1.0], [1.0, 1.0])
    """
    q, f, pt = _check_frame_call(robot, q, frame, point, reference, "jk.geometric_jacobian")
    return eager(_matrix, robot, (f, reference), q, pt)


def _matrix(robot: Robot, f: int, reference: str, q: jax.Array, pt) -> jax.Array:
    return jacobian_pass(robot, q, f, pt, reference).matrix()


def _matrix_and_pose(robot: Robot, f: int, reference: str, q: jax.Array, pt):
    g = jacobian_pass(robot, q, f, pt, reference)
    return g.matrix(), g.pose()


def frame_jacobian(
    robot: Robot,
    q: Any,
    frame: int | str | None = None,
    point: Any = None,
    reference: str = "world_aligned",
) -> tuple[jax.Array, jax.Array]:
    """``(J, T)``: the geometric Jacobian (6, nv) of :func:`geometric_jacobian` and the frame's
    pose ``T_world_frame`` (4, 4) (its origin, not ``point``), from one forward pass.

    For solvers and controllers that need both at every step (IK, resolved-rate control,
    calibration); as pytorch_kinematics' ``jacobian(..., ret_eef_pose=True)``.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("puma560")
    >>> J, T = jk.jacobians.frame_jacobian(robot, jnp.zeros(6))
    >>> J.shape, T.shape
    ((6, 6), (4, 4))
    """
    q, f, pt = _check_frame_call(robot, q, frame, point, reference, "jk.jacobians.frame_jacobian")
    return eager(_matrix_and_pose, robot, (f, reference), q, pt)


def _check_frame_call(robot, q, frame, point, reference, fn):
    """The checks shared by every Jacobian entry point: ``(q, frame index, point)``."""
    check_reference(reference)
    q = check_q(robot, q, fn=fn, host=True)
    return q, robot.frame_index(frame), check_point(point, result_dtype(robot, q), fn)


class FrameJacobian(NamedTuple):
    """The geometric Jacobian of one frame, before assembly: columns as scalar 3-vectors (short
    robots, constants folded) or as (3, dof) arrays (scanned chains), plus the frame's pose
    (``R``, origin ``p``, world coordinates) from the same forward pass.

    ``matrix()`` (6, dof), ``times(qd)`` = ``J @ qd`` (6,) without forming J, ``rotation()``
    (3, 3), ``pose()`` (4, 4) ``T_world_frame``."""

    Jv: Any
    Jw: Any
    R: Any
    p: Any
    dtype: Any

    def matrix(self) -> jax.Array:
        if isinstance(self.Jv, list):
            return _assemble(self.Jv, self.Jw, self.dtype)
        return jnp.concatenate([self.Jv, self.Jw], axis=0)

    def times(self, qd: jax.Array) -> jax.Array:
        """``J @ qd`` (6,) without materialising J when the columns are scalars."""
        if not isinstance(self.Jv, list):
            return self.matrix() @ qd
        qs = [qd[k] for k in range(len(self.Jv))]
        v = [
            fold.add(*(fold.mul(c[i], s) for c, s in zip(self.Jv, qs, strict=True)))
            for i in range(3)
        ]
        w = [
            fold.add(*(fold.mul(c[i], s) for c, s in zip(self.Jw, qs, strict=True)))
            for i in range(3)
        ]
        return fold.stack_matrix(v + w, self.dtype)

    def rotation(self) -> jax.Array:
        return fold.stack_matrix(self.R, self.dtype) if isinstance(self.R, tuple) else self.R

    def pose(self) -> jax.Array:
        """``T_world_frame`` (4, 4) of the frame (its origin, not ``point``)."""
        p = fold.stack_matrix(self.p, self.dtype) if isinstance(self.p, tuple) else self.p
        return spatial.make_transform(self.rotation(), p)


def jacobian_pass(
    robot: Robot, q: jax.Array, f: int, point: jax.Array | None, reference: str
) -> FrameJacobian:
    """The kernel behind every geometric Jacobian: one forward pass, columns of frame index ``f``
    at ``point`` (checked offset (3,) in the frame's axes, or None) in ``reference``.

    ``q`` must be checked (:func:`geometric_jacobian` and :func:`frame_jacobian` are the checked
    entry points); nothing is checked again here, so solvers call it inside their loops.
    """
    path = scan_joints(robot, f)
    if path is not None:
        return _jacobian_pass_scan(robot, q, f, path, point, reference)
    sp = scalar_pass(robot, q, frames=(f,))
    pt = None if point is None else point.astype(sp.dtype)
    R, p = sp.R[f], sp.p[f]
    target = p if pt is None else fold.vadd(p, fold.matvec(R, tuple(pt[i] for i in range(3))))
    Jv, Jw = _columns(robot, sp, target, f)
    if reference == "local":
        Rt = fold.transpose(R)
        Jv = [fold.matvec(Rt, c) for c in Jv]
        Jw = [fold.matvec(Rt, c) for c in Jw]
    elif reference == "world":
        # velocity of the point at the world origin: v_target - omega x target
        Jv = [fold.vadd(v, fold.cross(target, w)) for v, w in zip(Jv, Jw, strict=True)]
    return FrameJacobian(Jv=Jv, Jw=Jw, R=R, p=p, dtype=sp.dtype)


def _jacobian_pass_scan(robot: Robot, q, f: int, path, point, reference: str) -> FrameJacobian:
    """Table 4.1 vectorised over the joints of a long path (see ``kinematics.scan_pass``)."""
    is_tool = robot.has_tool and f == robot.n_joints + 1
    fp = scan_pass(robot, q, path, tool=is_tool)
    dtype = fp.p.dtype
    R, p = fp.R[-1], fp.p[-1]
    target = p if point is None else p + R @ point.astype(dtype)
    path = np.asarray(path, dtype=np.int64)
    kinds = np.array(robot.kinds, dtype=object)[path]
    rev = jnp.asarray(kinds == "revolute", dtype=dtype)[:, None]
    pri = jnp.asarray(kinds == "prismatic", dtype=dtype)[:, None]
    m = robot.multiplier
    mult = (m[path] if is_traced(m) else jnp.asarray(np.asarray(m)[path])).astype(dtype)[:, None]
    cols_v = mult * (rev * jnp.cross(fp.z, target[None, :] - fp.o) + pri * fp.z)  # (len, 3)
    cols_w = mult * rev * fp.z
    moving = kinds != "fixed"
    vidx = np.array(robot.v_index, dtype=np.int64)[path][moving]  # 1-dof joints only here
    Jv = jnp.zeros((robot.nv, 3), dtype=dtype).at[vidx].add(cols_v[moving]).T
    Jw = jnp.zeros((robot.nv, 3), dtype=dtype).at[vidx].add(cols_w[moving]).T
    if reference == "local":
        Jv, Jw = R.T @ Jv, R.T @ Jw
    elif reference == "world":
        Jv = Jv + spatial.skew(target) @ Jw
    return FrameJacobian(Jv=Jv, Jw=Jw, R=R, p=p, dtype=dtype)


def change_reference(
    J: jax.Array, T: jax.Array, from_reference: str, to_reference: str
) -> jax.Array:
    """Re-express a (6, dof) Jacobian of the frame with pose ``T`` (4, 4) in another reference.

    ``local = blkdiag(R^T, R^T) world_aligned``; ``world = Ad(T) local``.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q = jnp.array([0.0, jnp.pi / 2])
    >>> J, T = jk.geometric_jacobian(robot, q), jk.fk(robot, q)
    >>> J_local = jk.change_reference(J, T, "world_aligned", "local")
    >>> bool(jnp.allclose(J_local, jk.geometric_jacobian(robot, q, reference="local")))
    True
    """
    check_reference(from_reference)
    check_reference(to_reference)
    J = jnp.asarray(J)
    T = jnp.asarray(T)
    if J.ndim != 2 or J.shape[0] != 6 or T.shape != (4, 4):
        raise ShapeError(
            f"expected J of shape (6, dof) and T of shape (4, 4), got {J.shape}, {T.shape}."
        )
    R = T[:3, :3]
    if from_reference == "world_aligned":
        local = jnp.concatenate([R.T @ J[:3], R.T @ J[3:]], axis=0)
    elif from_reference == "local":
        local = J
    else:
        local = jnp.linalg.solve(spatial.adjoint(T), J)
    if to_reference == "local":
        return local
    if to_reference == "world_aligned":
        return jnp.concatenate([R @ local[:3], R @ local[3:]], axis=0)
    return spatial.adjoint(T) @ local


def _pose_twist_fn(robot: Robot, frame: int, point: jax.Array | None, reference: str):
    """Returns ``f(q) -> (p_point, R_frame)`` used by the autodiff Jacobians."""

    def f(q):
        R, p = frame_pose(robot, q, frame)
        if point is not None:
            p = p + R @ point.astype(p.dtype)
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


def _autodiff_jacobian(robot, q, frame, point, reference, mode, fn):
    q, f, pt = _check_frame_call(robot, q, frame, point, reference, fn)
    return eager(_autodiff_kernel, robot, (f, reference, mode), q, pt)


def _autodiff_kernel(robot, f, reference, mode, q, pt):
    pose = _pose_twist_fn(robot, f, pt, reference)
    jac = jax.jacfwd if mode == "fwd" else jax.jacrev
    q = q.astype(result_dtype(robot, q))
    if robot.nq == robot.nv:
        dp, dR = jac(pose)(q)
    else:  # differentiate along the configuration manifold: v -> pose(integrate(q, v)) at 0
        v0 = jnp.zeros(robot.nv, q.dtype)
        dp, dR = jac(lambda v: pose(integrate_kernel(robot, q, v)))(v0)
    p, R = pose(q.astype(dp.dtype))
    return _jacobian_from_derivs(p, R, dp, dR, reference)


def jacobian_fwd(robot, q, frame=None, point=None, reference="world_aligned") -> jax.Array:
    """The geometric Jacobian from ``jax.jacfwd`` of forward kinematics; shape (6, nv).

    Linear rows are d(point)/dq; angular rows are ``vee(dR/dq_k R^T)``. Independent of the
    hand-built Table 4.1 assembly, so the two check each other. For a robot with free, ball or
    planar joints the derivative is taken with respect to ``v`` of
    ``fk(jaxkin.integrate(robot, q, v))`` at ``v = 0`` (:mod:`jaxkin.configuration`).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("puma560")
    >>> q = jnp.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    >>> bool(jnp.allclose(jk.jacobian_fwd(robot, q), jk.geometric_jacobian(robot, q)))
    True
    """
    return _autodiff_jacobian(robot, q, frame, point, reference, "fwd", "jk.jacobian_fwd")


def jacobian_rev(robot, q, frame=None, point=None, reference="world_aligned") -> jax.Array:
    """As :func:`jacobian_fwd` but with ``jax.jacrev`` (reverse mode); shape (6, nv).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("puma560")
    >>> q = jnp.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    >>> bool(jnp.allclose(jk.jacobian_rev(robot, q), jk.geometric_jacobian(robot, q)))
    True
    """
    return _autodiff_jacobian(robot, q, frame, point, reference, "rev", "jk.jacobian_rev")


def analytical_jacobian(
    robot: Robot,
    q: Any,
    representation: str = "rpy",
    frame: int | str | None = None,
    point: Any = None,
    *,
    method: str = "chain",
    singular_tol: float | None = None,
    return_margin: bool = False,
):
    """Analytical Jacobian ``d[p; phi]/dq``; shape (6, nv).

    ``p`` is the frame origin (or ``point``, an offset in the frame's axes) in world coordinates,
    ``phi`` the frame's orientation in world coordinates in ``representation`` (``"rpy"``, the
    chapter's; ``"zyz"``; ``"rotvec"``). Rows ``[dp; dphi]``, columns follow ``q`` (for a robot
    with free, ball or planar joints: the velocity ``v``, the derivative being taken along
    ``jaxkin.integrate(robot, q, v)`` at ``v = 0``). It equals
    ``blkdiag(I, B(phi)^-1) @ geometric_jacobian(...)`` (see
    :func:`jaxkin.representations.analytical_from_geometric`).

    ``method``:

    * ``"chain"`` (default, fast): ``dp/dq`` is the hand-built linear block and
      ``dphi/dq_k = (dphi/dR) : (skew(J_w[:, k]) R)``, where ``dphi/dR`` is ``jax.jacfwd`` of the
      representation map and ``dR/dq_k = skew(J_w[:, k]) R`` is exact (one forward pass);
    * ``"jacfwd"``: ``jax.jacfwd`` of the whole map ``q -> [p; phi(R(q))]`` through forward
      kinematics (about 3 - 4x slower; independent of the hand-built Jacobian, which the tests
      use to check one against the other).

    Representation singularities (rpy pitch = +-pi/2, zyz theta = 0 or pi) make ``J_a`` unbounded.
    With ``margin = representation_margin(phi)`` and ``tol = singular_tol`` (default: the square
    root of the dtype's machine epsilon):

    * called eagerly, ``margin < tol`` raises :class:`~jaxkin.RepresentationSingularityError`;
    * under ``jit``/``vmap`` (where values cannot raise), the Jacobian of such a configuration is
      all NaN, so it can never pass for a number; pass ``return_margin=True`` to get
      ``(J_a, margin)`` instead, unmasked, and filter yourself.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> Ja = jk.analytical_jacobian(robot, jnp.array([0.0, jnp.pi / 2]), "rpy")
    >>> Ja.shape
    (6, 2)
    >>> Ja[5].round(6).tolist()  # d(yaw)/dq: a planar arm's yaw is q1 + q2
    [1.0, 1.0]
    """
    check_representation(representation)
    if method not in ("chain", "jacfwd"):
        raise JaxkinError(f"method must be 'chain' or 'jacfwd', got {method!r}.")
    q, f, pt = _check_frame_call(robot, q, frame, point, "world_aligned", "jk.analytical_jacobian")
    Ja, margin = eager(_analytical_kernel, robot, (f, representation, method), q, pt)
    if return_margin:
        return Ja, margin
    return guard_singular(
        Ja,
        margin,
        representation,
        singular_tol,
        "the analytical Jacobian",
        "jk.geometric_jacobian",
        robot,
        q,
    )


def _analytical_kernel(robot, f, representation, method, q, pt):
    return analytical_jacobian_pass(robot, q, f, pt, representation, method)


def analytical_jacobian_pass(
    robot: Robot,
    q: jax.Array,
    f: int,
    point: jax.Array | None,
    representation: str,
    method: str = "chain",
) -> tuple[jax.Array, jax.Array]:
    """The kernel of :func:`analytical_jacobian` on checked arguments: ``(J_a (6, nv), margin)``,
    unmasked (see :func:`jacobian_pass` for the arguments)."""
    pt = point
    dtype = result_dtype(robot, q)
    to_phi = lambda R: from_matrix(R, representation)  # noqa: E731

    if method == "chain":
        g = jacobian_pass(robot, q, f, pt, "world_aligned")
        J = g.matrix()
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
        pose = _pose_twist_fn(robot, f, pt, "world_aligned")

        def x_of_q(qq):
            p, R = pose(qq)
            phi = to_phi(R)
            return jnp.concatenate([p, phi]), phi

        if robot.nq == robot.nv:
            Ja, phi = jax.jacfwd(x_of_q, has_aux=True)(q.astype(dtype))
        else:
            qq = q.astype(dtype)
            Ja, phi = jax.jacfwd(lambda v: x_of_q(integrate_kernel(robot, qq, v)), has_aux=True)(
                jnp.zeros(robot.nv, dtype)
            )
    return Ja, representation_margin(phi, representation)
