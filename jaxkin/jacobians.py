"""Jacobians: the hand-built geometric Jacobian (Table 4.1) and the autodiff ones.

Rows are always ``[v; omega]`` (linear first); columns follow ``q`` (``robot.joint_names``).
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
from .errors import JaxkinError, ShapeError
from .kinematics import check_q, frame_pose, scalar_pass, scan_pass, uses_scan
from .model import Robot

__all__ = [
    "REFERENCES",
    "analytical_jacobian",
    "change_reference",
    "check_reference",
    "geometric_jacobian",
    "jacobian_fwd",
    "jacobian_rev",
]

REFERENCES = ("world_aligned", "local", "world")


def check_reference(reference: str) -> str:
    if reference not in REFERENCES:
        raise JaxkinError(
            f"reference must be one of {REFERENCES}, got {reference!r}. 'world_aligned' is the "
            "textbook's geometric Jacobian (frame origin, world axes)."
        )
    return reference


def _check_point(point: Any, dtype) -> jax.Array | None:
    if point is None:
        return None
    shape = getattr(point, "shape", None)
    if shape is None:
        try:
            point = np.asarray(point, dtype=float)
        except (TypeError, ValueError):
            raise ShapeError(
                f"point must be 3 numbers (in the frame's axes), got {point!r}."
            ) from None
        shape = point.shape
    if tuple(shape) != (3,):
        raise ShapeError(
            f"point must have shape (3,) (an offset in the frame's own axes), got {tuple(shape)}."
        )
    return jnp.asarray(point, dtype=dtype)


def _columns(robot: Robot, sp, target, frame: int) -> tuple[list, list]:
    """Table 4.1 as scalars: per q entry the linear and angular column at world point ``target``.

    A revolute joint i contributes ``[z_i x (target - o_i); z_i]``, a prismatic one ``[z_i; 0]``
    (times its multiplier, summed over joints sharing a q entry); joints off the path give zeros.
    """
    zero = (0.0, 0.0, 0.0)
    Jv = [zero] * robot.dof
    Jw = [zero] * robot.dof
    mult = _multipliers(robot)
    for j in robot.ancestors(frame):
        kind = robot.kinds[j]
        if kind == "fixed":
            continue
        z = sp.z[j]
        qi = robot.q_index[j]
        if kind == "revolute":
            jv, jw = fold.cross(z, fold.vsub(target, sp.o[j])), z
        else:
            jv, jw = z, zero
        m = mult[j]
        Jv[qi] = fold.vadd(Jv[qi], fold.vscale(jv, m))
        Jw[qi] = fold.vadd(Jw[qi], fold.vscale(jw, m))
    return Jv, Jw


def _multipliers(robot: Robot) -> list:
    m = robot.multiplier
    if isinstance(m, jax.core.Tracer):
        return [m[j] for j in range(robot.n_joints)]
    return [float(x) for x in np.asarray(m, dtype=np.float64)]


def _assemble(Jv: list, Jw: list, dtype) -> jax.Array:
    """(6, dof) array from per-column 3-vectors of scalars."""
    rows = [[Jv[k][i] for k in range(len(Jv))] for i in range(3)]
    rows += [[Jw[k][i] for k in range(len(Jw))] for i in range(3)]
    return fold.stack_matrix(rows, dtype)


def geometric_jacobian(
    robot: Robot,
    q: Any,
    frame: int | str | None = None,
    point: Any = None,
    reference: str = "world_aligned",
) -> jax.Array:
    """Geometric Jacobian ``J(q)`` with ``[v; omega] = J(q) @ qd``; shape (6, dof).

    Built column by column from one forward pass (the chapter's Table 4.1): a revolute joint i
    contributes ``[z_i x (p - o_i); z_i]``, a prismatic one ``[z_i; 0]``, a joint not on the path
    to ``frame`` a zero column. Elementwise, with the model's constants folded when the robot is
    concrete (see :func:`jaxkin.kinematics.scalar_pass`).

    Args:
      robot: the robot.
      q: joint values, shape (dof,).
      frame: frame name or index (default: the tip, tool included).
      point: optional offset (3,) of the point of interest from the frame origin, in the frame's
        own axes; the linear rows then give that point's velocity.
      reference: ``"world_aligned"`` (default), ``"local"`` or ``"world"``; see the module doc.
    """
    check_reference(reference)
    q = check_q(robot, q, fn="jk.geometric_jacobian")
    g = _geometric(robot, q, robot.frame_index(frame), point, reference)
    return g.matrix()


class _Geometric(NamedTuple):
    """The geometric Jacobian of one frame, before assembly: columns as scalar 3-vectors (short
    robots, constants folded) or as (3, dof) arrays (scanned chains), plus the frame's pose
    (``R``, origin ``p``) from the same forward pass."""

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


def _geometric(robot: Robot, q, f: int, point, reference: str) -> _Geometric:
    if uses_scan(robot):
        return _geometric_scan(robot, q, f, point, reference)
    sp = scalar_pass(robot, q)
    pt = _check_point(point, sp.dtype)
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
    return _Geometric(Jv=Jv, Jw=Jw, R=R, p=p, dtype=sp.dtype)


def _geometric_scan(robot: Robot, q, f: int, point, reference: str) -> _Geometric:
    """Table 4.1 vectorised over the joints of a long chain (see ``kinematics.scan_pass``)."""
    fp = scan_pass(robot, q)
    dtype = fp.p.dtype
    R, p = fp.R[f], fp.p[f]
    pt = _check_point(point, dtype)
    target = p if pt is None else p + R @ pt
    kinds = np.array(robot.kinds)
    on_path = np.zeros(robot.n_joints, dtype=bool)
    on_path[list(robot.ancestors(f))] = True
    rev = jnp.asarray((kinds == "revolute") & on_path, dtype=dtype)[:, None]
    pri = jnp.asarray((kinds == "prismatic") & on_path, dtype=dtype)[:, None]
    mult = robot.multiplier.astype(dtype)[:, None]
    cols_v = mult * (rev * jnp.cross(fp.z, target[None, :] - fp.o) + pri * fp.z)  # (n, 3)
    cols_w = mult * rev * fp.z
    qidx = np.maximum(np.array(robot.q_index), 0)
    Jv = jnp.zeros((robot.dof, 3), dtype=dtype).at[qidx].add(cols_v).T
    Jw = jnp.zeros((robot.dof, 3), dtype=dtype).at[qidx].add(cols_w).T
    if reference == "local":
        Jv, Jw = R.T @ Jv, R.T @ Jw
    elif reference == "world":
        Jv = Jv + spatial.skew(target) @ Jw
    return _Geometric(Jv=Jv, Jw=Jw, R=R, p=p, dtype=dtype)


def change_reference(
    J: jax.Array, T: jax.Array, from_reference: str, to_reference: str
) -> jax.Array:
    """Re-express a (6, dof) Jacobian of the frame with pose ``T`` (4, 4) in another reference.

    ``local = blkdiag(R^T, R^T) world_aligned``; ``world = Ad(T) local``.
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
    check_reference(reference)
    q = check_q(robot, q, fn=fn)
    f = robot.frame_index(frame)
    pt = _check_point(point, jnp.result_type(robot.base.dtype, q.dtype))
    pose = _pose_twist_fn(robot, f, pt, reference)
    jac = jax.jacfwd if mode == "fwd" else jax.jacrev
    dp, dR = jac(pose)(q.astype(jnp.result_type(robot.base.dtype, q.dtype)))
    p, R = pose(q.astype(dp.dtype))
    return _jacobian_from_derivs(p, R, dp, dR, reference)


def jacobian_fwd(robot, q, frame=None, point=None, reference="world_aligned") -> jax.Array:
    """The geometric Jacobian from ``jax.jacfwd`` of forward kinematics; shape (6, dof).

    Linear rows are d(point)/dq; angular rows are ``vee(dR/dq_k R^T)``. Independent of the
    hand-built Table 4.1 assembly, so the two check each other.
    """
    return _autodiff_jacobian(robot, q, frame, point, reference, "fwd", "jk.jacobian_fwd")


def jacobian_rev(robot, q, frame=None, point=None, reference="world_aligned") -> jax.Array:
    """As :func:`jacobian_fwd` but with ``jax.jacrev`` (reverse mode); shape (6, dof)."""
    return _autodiff_jacobian(robot, q, frame, point, reference, "rev", "jk.jacobian_rev")


def _is_traced(*trees) -> bool:
    leaves = jax.tree_util.tree_leaves(trees)
    return any(isinstance(x, jax.core.Tracer) for x in leaves)


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
    """Analytical Jacobian ``d[p; phi]/dq``; shape (6, dof).

    ``p`` is the frame origin (or ``point``, an offset in the frame's axes) in world coordinates,
    ``phi`` the frame's orientation in world coordinates in ``representation`` (``"rpy"``, the
    chapter's; ``"zyz"``; ``"rotvec"``). Rows ``[dp; dphi]``, columns follow ``q``. It equals
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
    """
    from .errors import RepresentationSingularityError
    from .representations import check_representation, from_matrix, representation_margin

    check_representation(representation)
    if method not in ("chain", "jacfwd"):
        raise JaxkinError(f"method must be 'chain' or 'jacfwd', got {method!r}.")
    q = check_q(robot, q, fn="jk.analytical_jacobian")
    f = robot.frame_index(frame)
    dtype = jnp.result_type(robot.base.dtype, q.dtype)
    pt = _check_point(point, dtype)
    to_phi = lambda R: from_matrix(R, representation)  # noqa: E731

    if method == "chain":
        g = _geometric(robot, q, f, point, "world_aligned")
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

        Ja, phi = jax.jacfwd(x_of_q, has_aux=True)(q.astype(dtype))
    margin = representation_margin(phi, representation)
    if return_margin:
        return Ja, margin
    tol = float(np.sqrt(np.finfo(dtype).eps)) if singular_tol is None else float(singular_tol)
    if not _is_traced(robot, q):
        m = float(margin)
        if m < tol:
            names = {"rpy": "pitch = +-pi/2", "zyz": "theta = 0 or pi", "rotvec": "|w| = 2 pi"}
            raise RepresentationSingularityError(
                f"the {representation!r} representation is singular here ({names[representation]}; "
                f"margin {m:.3g} < {tol:.3g}, phi = {np.asarray(phi).tolist()}): the analytical "
                "Jacobian is unbounded. Use jk.geometric_jacobian, another representation, or "
                "return_margin=True to get the raw values with their margin."
            )
        return Ja
    return jnp.where(margin < tol, jnp.full_like(Ja, jnp.nan), Ja)
