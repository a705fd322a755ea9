"""Derivatives of inverse-kinematics solutions by the implicit function theorem.

:func:`jaxkin.solve_ik` is differentiable: ``jax.jvp``, ``jax.jacfwd`` and ``jax.grad`` of
``sol.q`` with respect to ``T_target`` and to the robot's parameters (its float leaves, e.g. a
tool offset; the robot must then be traced, as inside ``jax.grad(loss)(robot)``) apply the rule
below at the returned solution; the solver's iterations are never differentiated. The start
``q0`` and the seeds have derivative zero.

The solver drives the residual ``e(q, T, theta) = [p_T - p(q); log(R_T R(q)^T)]`` (world axes;
:func:`jaxkin.pose_errors.pose_residual`) to zero, and ``de/dq = -J`` at ``e = 0`` (``J``: the
geometric Jacobian of the frame, world-aligned, rows ``[v; omega]``). Differentiating
``e(q*(T, theta), T, theta) = 0`` gives ``J dq = b`` with ``b = (de/dT) dT + (de/dtheta) dtheta``,
and the derivative returned is

    dq = J_f^T (J_f J_f^T + mu^2 I)^-1 b = sum_i s_i / (s_i^2 + mu^2) v_i u_i^T b     (dof,)

where ``J_f`` is ``J`` with the columns of the *held* joints zeroed (joints the solver left
exactly at a limit: their ``dq`` is 0), ``s_i, u_i, v_i`` its singular values and vectors, and
``mu = eps^(3/4) s_max`` (``eps`` of the dtype). For a regular solution this is the pseudo-inverse
``dq = J_f^+ b`` up to a relative ``(mu / s_min)^2``, below rounding while ``s_min / s_max >
sqrt(eps)``:

* non-redundant arm (6 free joints): the unique derivative ``J^-1 b``;
* redundant arm (more free joints than 6, e.g. the Panda): the solutions form a manifold and
  ``dq`` is its minimum-norm tangent, i.e. the derivative of the solution *nearest to* ``q*``
  on the perturbed target's manifold (what re-solving warm-started at ``q*`` returns);
* fewer than 6 free joints (a limit active on a 6-dof arm): the least-squares ``dq``.

Singular or unconverged solutions give finite damped values, never NaN. Check the flags of the
:class:`jaxkin.IKSolution`: ``converged`` (without it there is no implicit function and the
derivative is only that of a best effort) and ``singular`` (``s_min^2 <= eps |J_f|_F^2`` among
the free columns: the true derivative is unbounded there and the damped one is a choice).

Whole-body solves (several frames, weights, a centre-of-mass target, free and ball joints: see
:mod:`jaxkin.ik`) use the same rule on the stacked, weighted residual and Jacobian (rows of weight
0 are zero rows; columns: the velocity ``v``, nv of them): ``dv = J_f^+ b`` as above, then
``dq = d/ds integrate(q, s dv)`` at ``s = 0`` (nq,): a quaternion's tangent is
``0.5 quat * (0, omega)``, so ``q + t dq`` stays unit to first order. The posture term is not
part of the residual the solution zeroes and does not enter the derivative. ``full_rank`` then
counts only the rows whose weight is not 0 (``rows=``).

Calibration through IK: fit a tool offset ``p`` so that the IK solutions of known poses ``Ts``
(N, 4, 4) match the joint angles measured there, ``q_measured`` (N, dof); each solve starts at
the measured angles (they pick the branch)::

    import optax
    def loss(robot, Ts, q_measured):
        sol = jk.solve_ik(robot, Ts, q_measured, num_seeds=1, tol=1e-13, throw=False)
        return jnp.sum((sol.q - q_measured) ** 2)
    grad = jax.jit(jax.grad(loss))   # the robot is an argument: traced, its leaves get gradients
    # L-BFGS directions, steps capped at 2 mm (no line search: one compiled gradient serves all)
    opt = optax.chain(optax.scale_by_lbfgs(), optax.clip_by_global_norm(2e-3), optax.scale(-1.0))
    p = robot.tool[:3, 3]
    state = opt.init(p)
    for _ in range(60):
        robot = robot.replace(tool=robot.tool.at[:3, 3].set(p))
        g = grad(robot, Ts, q_measured)              # a Robot of gradients; g.tool[:3, 3] for p
        updates, state = opt.update(g.tool[:3, 3], state, p)
        p = optax.apply_updates(p, updates)

``tests/test_ik_implicit.py`` runs this loop on a UR5 with 8 measured configurations and
recovers a tool offset 3 cm away from the nominal one to 1e-6 m.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from ._jacobian_pass import jacobian_pass
from ._linalg import unrolled_cholesky
from .pose_errors import pose_residual

__all__ = ["damped_pinv_apply", "full_rank", "solution_tangent"]


def _pivots_positive(A: jax.Array) -> jax.Array:
    """True when the symmetric (m, m) ``A`` is positive definite (every Cholesky pivot > 0),
    unrolled into scalar operations (cheap under ``vmap``)."""
    floor = jnp.finfo(A.dtype).tiny
    return unrolled_cholesky(lambda i, k: A[i, k], A.shape[0], floor)[1]


def full_rank(J: jax.Array, held: jax.Array, rows: jax.Array | None = None) -> jax.Array:
    """True when ``J`` (m, dof) restricted to the free columns (``~held``) has full rank to
    working precision: ``s_min^2 > eps |J_f|_F^2`` over its ``min(m, n_free)`` singular values.

    For ``m <= 6`` decided exactly by a Cholesky factorisation of the Gram matrix shifted by that
    threshold (positive definite iff every eigenvalue exceeds it), not an SVD; larger (stacked,
    whole-body) Jacobians by their singular values. ``rows`` (m,) bool: the rows that count
    (a row with weight zero is not a target: it is left out of ``m``); default all.

    >>> import jax, jax.numpy as jnp
    >>> check = jax.jit(full_rank)  # one program (op by op, its unrolled Cholesky is ~50 ops)
    >>> J = jnp.eye(6, 7)
    >>> bool(check(J, jnp.zeros(7, bool))), bool(check(J, jnp.arange(7) == 0))
    (True, False)
    """
    dtype = J.dtype
    Jf = jnp.where(held[None, :], 0.0, J)
    if rows is not None:
        Jf = jnp.where(rows[:, None], Jf, 0.0)
    fro2 = jnp.sum(Jf * Jf)
    tau = jnp.finfo(dtype).eps * fro2
    n = J.shape[1]
    if rows is not None or J.shape[0] > 6:
        s = jnp.linalg.svd(Jf, compute_uv=False)  # descending; zero rows give zeros
        m = J.shape[0] if rows is None else jnp.sum(rows)
        r = jnp.minimum(m, jnp.sum(~held))
        ok = (r >= 1) & (s[jnp.maximum(r - 1, 0)] ** 2 > tau) if n >= 1 else False
        return ok & (fro2 > 0) & jnp.all(jnp.isfinite(J))
    if n < 1:
        return jnp.zeros((), bool)
    m = J.shape[0]
    wide = jnp.sum(~held) >= m  # the m x m Gram J_f J_f^T decides
    G = Jf @ Jf.T - tau * jnp.eye(m, dtype=dtype)
    # Otherwise the Gram of the free columns; held ones get a diagonal that cannot fail.
    H = Jf.T @ Jf + jnp.diag(jnp.where(held, 2 * fro2 + 1, -tau)).astype(dtype)
    ok = _pivots_positive(jnp.where(wide, _padded(G, n), _padded(H, m)))
    return ok & (fro2 > 0) & jnp.all(jnp.isfinite(J))


def _padded(A: jax.Array, size: int) -> jax.Array:
    """``A`` (k, k) as the leading block of a (max(k, size),) square matrix with 1 on the rest
    of the diagonal: its Cholesky pivots are those of ``A`` (the same operations, bit for bit),
    then 1s. One factorisation then decides for either Gram matrix (:func:`full_rank`)."""
    k = A.shape[0]
    if size <= k:
        return A
    return jnp.eye(size, dtype=A.dtype).at[:k, :k].set(A)


def damped_pinv_apply(J: jax.Array, held: jax.Array, b: jax.Array) -> jax.Array:
    """``J_f^T (J_f J_f^T + mu^2 I)^-1 b`` (dof,) through the SVD of ``J_f`` (see the module
    doc); held joints get exactly 0. ``J`` must be finite."""
    dtype = J.dtype
    Jf = jnp.where(held[None, :], 0.0, J)
    U, s, Vt = jnp.linalg.svd(Jf, full_matrices=False)
    mu = jnp.finfo(dtype).eps ** 0.75 * jnp.max(s)
    denom = s * s + mu * mu
    w = jnp.where(denom > 0, s / jnp.where(denom > 0, denom, 1.0), 0.0)
    dq = Vt.T @ (w * (U.T @ b))
    return jnp.where(held, 0.0, dq)


def solution_tangent(
    robot: Any,
    q: jax.Array,
    T_target: jax.Array,
    f: int,
    held: jax.Array,
    T_dot: jax.Array,
    robot_dot: Any = None,
) -> jax.Array:
    """The derivative ``dq`` (dof,) of an IK solution ``q`` of ``T_target`` (4, 4) for the
    tangents ``T_dot`` (4, 4) and ``robot_dot`` (a robot of tangents, or None for none), by the
    rule of the module doc; ``held`` (dof,) bool marks the joints held at a limit."""

    def e_of_T(T):
        return pose_residual(pose, T)

    g = jacobian_pass(robot, q, f, None, "world_aligned")
    pose = g.pose()
    J = g.matrix()
    _, b = jax.jvp(e_of_T, (T_target,), (T_dot,))
    if robot_dot is not None:

        def e_of_robot(rb):
            return pose_residual(jacobian_pass(rb, q, f, None, "world_aligned").pose(), T_target)

        _, b_robot = jax.jvp(e_of_robot, (robot,), (robot_dot,))
        b = b + b_robot
    finite = jnp.all(jnp.isfinite(J))
    dq = damped_pinv_apply(jnp.where(finite, J, 0.0), held, jnp.where(finite, b, 0.0))
    return dq
