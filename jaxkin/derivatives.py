"""Derivatives of the Jacobian: J-dot, J-dot qd and the kinematic Hessian, exact by autodiff.

Every function here differentiates the hand-built geometric Jacobian jaxkin already builds
(:func:`jaxkin.geometric_jacobian`) with ``jax.jvp`` / ``jax.jacfwd``: no finite differences, no
second hand-written formula to keep in sync. The analytical J-dot (:func:`analytical_jacobian_dot`)
adds the representation's rate terms to that one ``jax.jvp``: with ``J_a = blkdiag(I, B^-1) J``
(``B = B(phi)`` the rate matrix of :mod:`jaxkin.representations`), its orientation rows are
``B^-1 (Jdot_w - Bdot B^-1 J_w)``, ``Bdot`` the ``jax.jvp`` of the closed-form ``B`` along
``phi_dot``: the derivative of :func:`jaxkin.analytical_jacobian`, without differentiating the
representation map (atan2, log) twice.

Definitions (``J(q)`` the (6, dof) Jacobian of ``frame`` at ``point`` in ``reference``):

* ``jacobian_dot(robot, q, qd)``: ``Jdot = d/dt J(q(t)) = sum_k dJ/dq_k qd_k``, shape (6, dof),
  the time derivative of the matrix ``J`` in the same reference (one forward-mode pass:
  ``jax.jvp(J, (q,), (qd,))``);
* ``jacobian_dot_qd(robot, q, qd)``: ``Jdot @ qd``, shape (6,), the velocity-product term of the
  acceleration ``d/dt (J qd) = J qdd + Jdot qd``. For ``reference="world_aligned"`` it is the
  classical (not spatial) acceleration of the point, linear rows first, at ``qdd = 0``;
* ``kinematic_hessian(robot, q)``: ``H[k, :, j] = d J[:, j] / d q_k``, shape (dof, 6, dof)
  (``H[k]`` is the Jacobian's partial derivative with respect to ``q_k``); ``Jdot = sum_k H[k]
  qd_k``. For revolute joints in ``world_aligned`` (Haviland & Corke 2022, part II):
  ``H[k, :3, j] = z_a x Jv_b`` with ``a = min(k, j)``, ``b = max(k, j)`` (symmetric in k, j) and
  ``H[k, 3:, j] = z_k x z_j`` for ``k < j``, zero for ``k >= j``.

Reference frames (see :mod:`jaxkin.jacobians`): the matrix is differentiated *as expressed* in
the given reference, so ``jacobian_dot(..., reference="local")`` is ``d/dt J_local``, which equals
Pinocchio's ``getFrameJacobianTimeVariation(..., LOCAL)``; ``"world"`` equals Pinocchio's
``WORLD`` and ``"world_aligned"`` its ``LOCAL_WORLD_ALIGNED`` (tests/test_derivatives.py checks
all three, and Pinocchio's ``getJointKinematicHessian``).

Robots with free, ball or planar joints (``robot.nq != robot.nv``, :mod:`jaxkin.configuration`):
``qd`` is a velocity of shape (nv,) and derivatives are taken along the configuration manifold,
``d/dt J(integrate(robot, q, t qd))`` at ``t = 0``; ``H`` is (nv, 6, nv), ``H[k]`` the derivative
along ``integrate(robot, q, v)`` with respect to ``v_k`` at ``v = 0``.

Each kernel takes one configuration; batch with ``jax.vmap``.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from ._checks import check_point, check_q, check_reference, check_v, result_dtype
from ._jacobian_pass import jacobian_pass
from ._jit import eager
from .configuration import integrate_kernel
from .model import Robot
from .representations import (
    check_representation,
    from_matrix,
    guard_singular,
    rate_matrix,
    representation_margin,
)

__all__ = [
    "analytical_jacobian_dot",
    "analytical_jacobian_dot_qd",
    "jacobian_dot",
    "jacobian_dot_qd",
    "kinematic_hessian",
]


def _check_call(robot: Robot, q: Any, qd: Any, frame, point, reference: str, fn: str, hint=None):
    """Entry checks shared by the derivatives: ``(q, qd, frame index, point)``, one dtype."""
    check_reference(reference)
    hint = hint or f"jax.vmap(lambda q, qd: {fn}(robot, q, qd))(qs, qds)"
    q = check_q(robot, q, fn=fn, batch_hint=hint, host=True)
    if qd is None:  # the Hessian: no velocity
        qd = q
    else:
        qd = check_v(robot, qd, what="qd", fn=fn, batch_hint=hint, host=True)
    dtype = result_dtype(robot, q, qd)
    pt = check_point(point, dtype, fn)
    return q.astype(dtype), qd.astype(dtype), robot.frame_index(frame), pt


def jacobian_dot(
    robot: Robot,
    q: Any,
    qd: Any,
    frame: int | str | None = None,
    point: Any = None,
    reference: str = "world_aligned",
) -> jax.Array:
    """Time derivative ``Jdot = d/dt J(q(t))`` of the geometric Jacobian; shape (6, dof).

    ``J`` is :func:`jaxkin.geometric_jacobian` of ``frame`` (default: the tip) at ``point`` (an
    offset in the frame's axes) in ``reference``; rows ``[v; omega]``, columns follow ``q``.
    Exact: one ``jax.jvp`` of the hand-built Jacobian in direction ``qd``.

    Args:
      robot: the robot.
      q: joint values, shape (dof,).
      qd: joint velocities, shape (dof,).
      frame, point, reference: as in :func:`jaxkin.geometric_jacobian`.

    Pinocchio: ``computeJointJacobiansTimeVariation(model, data, q, qd)``,
    ``updateFramePlacements`` and ``getFrameJacobianTimeVariation(model, data, frame_id, rf)``
    with ``rf`` LOCAL_WORLD_ALIGNED / LOCAL / WORLD for ``"world_aligned"`` / ``"local"`` /
    ``"world"``.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q, qd = jnp.array([0.0, jnp.pi / 2]), jnp.array([1.0, 0.0])
    >>> Jd = jk.jacobian_dot(robot, q, qd)
    >>> Jd.shape
    (6, 2)
    >>> bool(jnp.allclose(Jd @ qd, jk.jacobian_dot_qd(robot, q, qd)))
    True
    """
    q, qd, f, pt = _check_call(robot, q, qd, frame, point, reference, "jk.jacobian_dot")
    return _jacobian_dot(robot, q, f, qd, pt, reference)


def _tangent(robot, q, fun):
    """``(g, x0)``: ``fun`` and ``q`` itself (nq == nv), or ``v -> fun(integrate(q, v))`` and
    ``v = 0`` (free, ball or planar joints), so that derivatives of ``g`` at ``x0`` are taken
    along the configuration manifold."""
    if robot.nq == robot.nv:
        return fun, q
    return (lambda v: fun(integrate_kernel(robot, q, v))), jnp.zeros(robot.nv, q.dtype)


def _jacobian_dot_kernel(robot, q, frame, qd, point, reference):
    def J(qq):
        return jacobian_pass(robot, qq, frame, point, reference).matrix()

    g, x0 = _tangent(robot, q, J)
    return jax.jvp(g, (x0,), (qd,))[1]


def jacobian_dot_qd(
    robot: Robot,
    q: Any,
    qd: Any,
    frame: int | str | None = None,
    point: Any = None,
    reference: str = "world_aligned",
) -> jax.Array:
    """``Jdot @ qd``, shape (6,): the velocity-product (bias) term of ``d/dt (J qd)``.

    With ``reference="world_aligned"`` this is ``[a; alpha]`` of the point (classical linear
    acceleration of the frame origin or ``point`` in world axes, and angular acceleration) when
    ``qdd = 0``; add ``J @ qdd`` for the full acceleration. Shapes: ``q``, ``qd`` (dof,).
    Computed as one ``jax.jvp`` of the twist ``q -> J(q) @ qd`` (no (6, dof) matrix formed).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q, qd = jnp.array([0.0, jnp.pi / 2]), jnp.array([1.0, 0.0])
    >>> jk.jacobian_dot_qd(robot, q, qd)[:2].round(6).tolist()  # tip at (1, 1): centripetal
    [-1.0, -1.0]
    """
    q, qd, f, pt = _check_call(robot, q, qd, frame, point, reference, "jk.jacobian_dot_qd")
    return _jacobian_dot_qd(robot, q, f, qd, pt, reference)


def _jacobian_dot_qd_kernel(robot, q, frame, qd, point, reference):
    def V(qq):
        return jacobian_pass(robot, qq, frame, point, reference).times(qd)

    g, x0 = _tangent(robot, q, V)
    return jax.jvp(g, (x0,), (qd,))[1]


def kinematic_hessian(
    robot: Robot,
    q: Any,
    frame: int | str | None = None,
    point: Any = None,
    reference: str = "world_aligned",
) -> jax.Array:
    """The kinematic Hessian ``H[k, :, j] = d J[:, j] / d q_k``; shape (dof, 6, dof).

    ``H[k]`` (6, dof) is the partial derivative of the geometric Jacobian (``frame``, ``point``,
    ``reference`` as in :func:`jaxkin.geometric_jacobian`; rows ``[v; omega]``) with respect to
    joint ``k``; ``Jdot = einsum("k,kij->ij", qd, H)``. Exact: ``jax.jacfwd`` of the hand-built
    Jacobian.

    Index order against other libraries: Pinocchio's ``getJointKinematicHessian`` (joint frames
    only) returns the buffer of a column-major (6, nv, nv) Eigen tensor as a C-ordered numpy array,
    so read it as ``P.reshape(nv, nv, 6)[k, j, :] == H[k, :, j]`` (tests/README.md: "H[k, j, i]");
    the Robotics Toolbox's ``hessian0(q)`` is (n, 6, n) and equals ``H`` for
    ``reference="world_aligned"`` at the tip.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q, qd = jnp.array([0.0, jnp.pi / 2]), jnp.array([1.0, 0.0])
    >>> H = jk.kinematic_hessian(robot, q)
    >>> H.shape
    (2, 6, 2)
    >>> bool(jnp.allclose(jnp.einsum("k,kij->ij", qd, H), jk.jacobian_dot(robot, q, qd)))
    True
    """
    fn = "jk.kinematic_hessian"
    hint = f"jax.vmap(lambda q: {fn}(robot, q))(qs)"
    q, _, f, pt = _check_call(robot, q, None, frame, point, reference, fn, hint)
    return _hessian(robot, q, f, pt, reference)


def _hessian_kernel(robot, q, frame, point, reference):
    def J(qq):
        return jacobian_pass(robot, qq, frame, point, reference).matrix()

    g, x0 = _tangent(robot, q, J)
    dJ = jax.jacfwd(g)(x0)  # (6, dof_j, dof_k)
    return jnp.transpose(dJ, (2, 0, 1))


# ----------------------------------------------------------------------------- analytical
def _singular_guard(Jad, margin, representation, singular_tol, return_margin, robot, q, qd):
    if return_margin:
        return Jad, margin
    return guard_singular(
        Jad,
        margin,
        representation,
        singular_tol,
        "the analytical Jacobian and its derivative",
        "jk.jacobian_dot (geometric)",
        robot,
        q,
        qd,
    )


def analytical_jacobian_dot(
    robot: Robot,
    q: Any,
    qd: Any,
    representation: str = "rpy",
    frame: int | str | None = None,
    point: Any = None,
    *,
    singular_tol: float | None = None,
    return_margin: bool = False,
):
    """Time derivative of the analytical Jacobian ``d/dt J_a(q(t))``; shape (6, dof).

    ``J_a = d[p; phi]/dq`` as in :func:`jaxkin.analytical_jacobian` (``p`` the frame origin or
    ``point`` in world coordinates, ``phi`` the orientation in ``representation``: ``"rpy"``,
    ``"zyz"`` or ``"rotvec"``); rows ``[dp; dphi]``. ``d/dt [p; phi] = J_a qd`` and
    ``d2/dt2 [p; phi] = J_a qdd + Jdot_a qd``. Exact: one ``jax.jvp`` of the hand-built
    Jacobian along ``qd``, and for the orientation rows ``B^-1 (Jdot_w - Bdot B^-1 J_w)`` (``B``
    the rate matrix at ``phi``, see :func:`jaxkin.rate_matrix`).

    Representation singularities are handled as in :func:`jaxkin.analytical_jacobian`: eagerly,
    a margin below ``singular_tol`` raises :class:`~jaxkin.RepresentationSingularityError`; under
    ``jit``/``vmap`` the result is all NaN there; ``return_margin=True`` returns
    ``(Jdot_a, margin)`` unmasked.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("puma560")
    >>> q, qd = jnp.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6]), jnp.ones(6)
    >>> jk.analytical_jacobian_dot(robot, q, qd, "zyz").shape
    (6, 6)
    """
    check_representation(representation)
    fn = "jk.analytical_jacobian_dot"
    q, qd, f, pt = _check_call(robot, q, qd, frame, point, "world_aligned", fn)
    Jad, margin = _analytical_dot(robot, q, f, qd, pt, representation)
    return _singular_guard(Jad, margin, representation, singular_tol, return_margin, robot, q, qd)


def analytical_jacobian_dot_qd(
    robot: Robot,
    q: Any,
    qd: Any,
    representation: str = "rpy",
    frame: int | str | None = None,
    point: Any = None,
    *,
    singular_tol: float | None = None,
    return_margin: bool = False,
):
    """``Jdot_a @ qd``, shape (6,): ``d2/dt2 [p; phi]`` at ``qdd = 0`` (``phi`` in
    ``representation``). Singularities as in :func:`analytical_jacobian_dot`."""
    check_representation(representation)
    fn = "jk.analytical_jacobian_dot_qd"
    q, qd, f, pt = _check_call(robot, q, qd, frame, point, "world_aligned", fn)
    acc, margin = _analytical_dot_qd(robot, q, f, qd, pt, representation)
    return _singular_guard(acc, margin, representation, singular_tol, return_margin, robot, q, qd)


def _inverse3(B: jax.Array) -> jax.Array:
    """The inverse of a (3, 3) matrix by its adjugate (rows ``b2 x b3``, ``b3 x b1``, ``b1 x b2``
    of its columns ``b_i``, over the determinant): elementwise operations only, cheap to compile
    and to differentiate again; inf/NaN where ``B`` is singular (the margin says where)."""
    b1, b2, b3 = B[:, 0], B[:, 1], B[:, 2]
    adj = jnp.stack([jnp.cross(b2, b3), jnp.cross(b3, b1), jnp.cross(b1, b2)])
    return adj / jnp.sum(b1 * adj[0])


def _times(M: jax.Array, X: jax.Array) -> jax.Array:
    """``M @ X`` for a (3, 3) ``M`` and a (3,) or (3, n) ``X``, elementwise (no small dot)."""
    if X.ndim == 1:
        return jnp.sum(M * X[None, :], axis=1)
    return jnp.sum(M[:, :, None] * X[None, :, :], axis=1)


def _rate_terms(R: jax.Array, w: jax.Array, wd: jax.Array, qd: jax.Array, representation: str):
    """The orientation rows of the analytical J-dot (or J-dot qd), with their margin.

    With ``phi`` the representation of ``R``, ``B = B(phi)`` its rate matrix
    (``omega = B phi_dot``) and ``w``, ``wd`` the angular rows of the geometric Jacobian and of
    its time derivative (or of ``J qd`` and ``Jdot qd``): the analytical rows are
    ``w_a = B^-1 w`` (what ``jk.analytical_jacobian`` computes by the chain rule through the
    representation map), and differentiating ``B w_a = w`` along ``q(t)`` gives
    ``d/dt w_a = B^-1 (wd - Bdot w_a)``, ``Bdot = dB/dphi . phi_dot``, ``phi_dot = w_a qd``
    (``= w_a`` itself for ``J qd``). The same derivative as differentiating the chain rule's
    ``jacfwd`` of the representation map, without its second derivatives."""
    phi = from_matrix(R, representation)
    Binv = _inverse3(rate_matrix(phi, representation))
    wa = _times(Binv, w)
    phid = wa if wa.ndim == 1 else wa @ qd
    Bd = jax.jvp(lambda p: rate_matrix(p, representation), (phi,), (phid,))[1]
    return _times(Binv, wd - _times(Bd, wa)), representation_margin(phi, representation)


def _analytical_dot_kernel(robot, q, frame, qd, point, representation):
    def J(qq):
        g = jacobian_pass(robot, qq, frame, point, "world_aligned")
        return g.matrix(), g.rotation()

    g, x0 = _tangent(robot, q, J)
    (Jg, R), (Jd, _) = jax.jvp(g, (x0,), (qd,))
    rows, margin = _rate_terms(R, Jg[3:], Jd[3:], qd, representation)
    return jnp.concatenate([Jd[:3], rows], axis=0), margin


def _analytical_dot_qd_kernel(robot, q, frame, qd, point, representation):
    def V(qq):
        g = jacobian_pass(robot, qq, frame, point, "world_aligned")
        return g.times(qd), g.rotation()

    g, x0 = _tangent(robot, q, V)
    (v, R), (a, _) = jax.jvp(g, (x0,), (qd,))
    rows, margin = _rate_terms(R, v[3:], a[3:], qd, representation)
    return jnp.concatenate([a[:3], rows]), margin


_jacobian_dot = eager(_jacobian_dot_kernel, ("frame", "reference"))
_jacobian_dot_qd = eager(_jacobian_dot_qd_kernel, ("frame", "reference"))
_hessian = eager(_hessian_kernel, ("frame", "reference"))
_analytical_dot = eager(_analytical_dot_kernel, ("frame", "representation"))
_analytical_dot_qd = eager(_analytical_dot_qd_kernel, ("frame", "representation"))
