"""Inverse velocity: pseudo-inverse, damped least squares (fixed, adaptive, weighted), null-space
projection and resolved-rate control.

Oracles: NumPy's ``pinv``/``lstsq`` and the closed forms of the weighted and damped solutions;
the DLS bound ``|qd| <= |v| / (2 lambda)`` as a hypothesis property over random, also
rank-deficient, Jacobians; exact singular configurations for finiteness.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk

_FINITE = dict(allow_nan=False, allow_subnormal=False)


@st.composite
def jacobians_and_twists(draw):
    """(J, v): J (m, n) with m in 1..6, n in 1..8, entries in [-2, 2], sometimes rank deficient
    (repeated or zero columns, a zero matrix); v (m,) in [-3, 3]."""
    m = draw(st.integers(1, 6))
    n = draw(st.integers(1, 8))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    J = rng.uniform(-2, 2, size=(m, n))
    kind = draw(st.sampled_from(["generic", "repeated", "zero_column", "zero", "rank1"]))
    if kind == "repeated" and n > 1:
        J[:, 1] = J[:, 0]
    elif kind == "zero_column":
        J[:, 0] = 0.0
    elif kind == "zero":
        J[:] = 0.0
    elif kind == "rank1":
        J = np.outer(rng.uniform(-2, 2, m), rng.uniform(-2, 2, n))
    v = np.array(draw(st.lists(st.floats(-3, 3, **_FINITE), min_size=m, max_size=m)))
    return J, v


# The properties draw J of up to 48 shapes: one small compiled program per shape costs less than
# compiling each primitive of the solve per shape op by op (the eager call); finite inputs only,
# so the eager refusals are not in play (they are tested in test_errors and test_nonfinite.py).
_dls = jax.jit(
    lambda J, v, lam: jk.damped_least_squares(J, v, damping=lam), compiler_options=FAST_COMPILE
)
_adaptive = jax.jit(
    lambda J: jk.adaptive_damping(J, max_damping=0.1, threshold=0.3), compiler_options=FAST_COMPILE
)


@settings(max_examples=25)
@given(jacobians_and_twists(), st.floats(1e-3, 10.0, **_FINITE))
def test_property_dls_bound(Jv, lam):
    J, v = Jv
    qd = np.asarray(_dls(J, v, lam))
    assert np.all(np.isfinite(qd))
    bound = np.linalg.norm(v) / (2 * lam)
    assert np.linalg.norm(qd) <= bound * (1 + 1e-9) + 1e-300
    # and it is the minimiser of |J qd - v|^2 + lam^2 |qd|^2 (normal equations)
    n = J.shape[1]
    expected = np.linalg.solve(J.T @ J + lam**2 * np.eye(n), J.T @ v)
    np.testing.assert_allclose(qd, expected, rtol=1e-8, atol=1e-10 * (1 + bound))


@settings(max_examples=15)
@given(jacobians_and_twists())
def test_property_adaptive_damping_bound(Jv):
    J, v = Jv
    eps, lam_max = 0.3, 0.1  # those of _adaptive
    lam = float(_adaptive(J))
    s = np.linalg.svd(J, compute_uv=False)
    smin = s[-1] if J.shape[0] <= J.shape[1] else 0.0
    assert 0.0 <= lam <= lam_max
    if smin >= eps:
        assert lam == 0.0
    else:
        assert lam == pytest.approx(lam_max * math.sqrt(1 - (smin / eps) ** 2), rel=1e-10)
    if lam > 0:
        qd = np.asarray(_dls(J, v, lam))
        assert np.linalg.norm(qd) <= np.linalg.norm(v) / (2 * lam) * (1 + 1e-9) + 1e-300


def test_pinv_matches_numpy_and_is_minimum_norm():
    robot = jk.robots.load("panda", dtype=np.float64)
    q = np.asarray(robot.configurations["qr"])
    J = np.asarray(jk.geometric_jacobian(robot, q))
    v = np.array([0.1, -0.05, 0.02, 0.0, 0.3, -0.1])
    qd = np.asarray(jk.pinv_velocity(J, v, rcond=1e-10))
    np.testing.assert_allclose(qd, np.linalg.pinv(J, rcond=1e-10) @ v, rtol=0, atol=1e-13)
    np.testing.assert_allclose(J @ qd, v, rtol=0, atol=1e-13)
    # minimum norm: orthogonal to the null space
    _, _, Vt = np.linalg.svd(J)
    assert abs(float(Vt[-1] @ qd)) < 1e-13
    # rcond cuts singular directions: at the planar arm's singularity the pseudo-inverse only
    # moves along the non-singular direction, and stays finite
    planar = jk.robots.load("two_link_planar", dtype=np.float64)
    Jp = np.asarray(jk.geometric_jacobian(planar, np.zeros(2)))[:2]
    qd = np.asarray(jk.pinv_velocity(Jp, np.array([1.0, 1.0]), rcond=1e-8))
    np.testing.assert_allclose(qd, np.linalg.pinv(Jp, rcond=1e-8) @ [1.0, 1.0], atol=1e-14)


def test_weighted_solutions_match_closed_forms():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(6, 7))
    v = rng.normal(size=6)
    w = rng.uniform(0.5, 3.0, size=7)
    Wq = np.diag(w)
    # weighted minimum norm: qd = W^-1 J^T (J W^-1 J^T)^-1 v
    expected = np.linalg.inv(Wq) @ J.T @ np.linalg.solve(J @ np.linalg.inv(Wq) @ J.T, v)
    np.testing.assert_allclose(
        np.asarray(jk.pinv_velocity(J, v, rcond=1e-12, joint_weights=w)), expected, atol=1e-12
    )
    A = rng.normal(size=(7, 7))
    Wfull = A @ A.T + 7 * np.eye(7)
    expected = np.linalg.solve(Wfull, J.T) @ np.linalg.solve(J @ np.linalg.solve(Wfull, J.T), v)
    np.testing.assert_allclose(
        np.asarray(jk.pinv_velocity(J, v, rcond=1e-12, joint_weights=Wfull)), expected, atol=1e-12
    )
    # weighted DLS: argmin |J qd - v|^2_Wx + lam^2 qd^T Wq qd
    wx = rng.uniform(0.5, 2.0, size=6)
    lam = 0.05
    Wx = np.diag(wx)
    expected = np.linalg.solve(J.T @ Wx @ J + lam**2 * Wfull, J.T @ Wx @ v)
    got = jk.damped_least_squares(J, v, damping=lam, joint_weights=Wfull, task_weights=wx)
    np.testing.assert_allclose(np.asarray(got), expected, atol=1e-12)


def test_dls_smooth_and_finite_at_exact_singularity():
    planar = jk.robots.load("two_link_planar", dtype=np.float64)
    v = jnp.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0])

    def speed(q, lam):
        J = jk.geometric_jacobian(planar, q)
        return jnp.sum(jk.damped_least_squares(J, v, damping=lam) ** 2)

    q0 = jnp.zeros(2)  # stretched
    # compiled: one small program each (op by op, every primitive of the backward pass compiles)
    g_q, g_lam = jax.jit(jax.grad(speed, argnums=(0, 1)), compiler_options=FAST_COMPILE)(q0, 0.1)
    assert np.all(np.isfinite(np.asarray(g_q))) and np.isfinite(float(g_lam))
    qd = jk.damped_least_squares(jk.geometric_jacobian(planar, q0), v, damping=0.1)
    assert float(jnp.linalg.norm(qd)) <= 1.0 / 0.2
    # adaptive damping is differentiable too (the sqrt is double-where guarded)
    g = jax.jit(
        jax.grad(
            lambda q: jk.adaptive_damping(
                jk.geometric_jacobian(planar, q)[:2], max_damping=0.1, threshold=0.5
            )
        ),
        compiler_options=FAST_COMPILE,
    )(q0)
    assert np.all(np.isfinite(np.asarray(g)))


def test_null_space_projection():
    robot = jk.robots.load("panda", dtype=np.float64)
    # (not "qr": there the self-motion is stationary for the manipulability, by symmetry)
    q = jnp.array([0.3, -0.5, 0.4, -2.0, 0.3, 1.5, 0.2])
    v = jnp.array([0.05, 0.0, -0.02, 0.0, 0.1, 0.0])

    # one compiled program (op by op, the gradient's backward pass and every primitive of the
    # solves compiled on their own; the eager refusals are tested in test_errors)
    @functools.partial(jax.jit, compiler_options=FAST_COMPILE)
    def kernel(q, v):
        J = jk.geometric_jacobian(robot, q)
        g = jk.manipulability_gradient(robot, q)
        # the secondary motion alone (v = 0)
        qd0 = jk.null_space_velocity(J, jnp.zeros(6), g, rcond=1e-10)
        return {
            "J": J,
            "g": g,
            "N": jk.null_space_projector(J, rcond=1e-10),
            "qd": jk.null_space_velocity(J, v, g, rcond=1e-10),
            "qd0": qd0,
            "m0": jk.manipulability(J),
            "m1": jk.manipulability(jk.geometric_jacobian(robot, q + 1.0 * qd0)),
            "qd_d": jk.null_space_velocity(J, v, g, damping=1e-4),  # damped
        }

    out = jax.tree_util.tree_map(np.asarray, kernel(q, v))
    J, g, N, qd, qd0 = out["J"], out["g"], out["N"], out["qd"], out["qd0"]
    np.testing.assert_allclose(J @ N, 0.0, atol=1e-13)
    np.testing.assert_allclose(N @ N, N, atol=1e-13)
    np.testing.assert_allclose(J @ qd, np.asarray(v), atol=1e-13)
    # the secondary motion alone (v = 0) leaves the tip still and raises the manipulability
    np.testing.assert_allclose(J @ qd0, 0.0, atol=1e-13)
    assert float(out["m1"]) > float(out["m0"])
    assert float(g @ qd0) > 0
    # damped variant: task error of order lambda^2
    assert float(np.max(np.abs(J @ out["qd_d"] - np.asarray(v)))) < 1e-6
    with pytest.raises(jk.JaxkinError, match="exactly one of rcond"):
        jk.null_space_velocity(J, v, g)


def test_resolved_rate_follows_a_circle_and_reports_errors():
    robot = jk.robots.load("panda", dtype=np.float64)
    q0 = np.asarray(robot.configurations["qr"])
    T0 = np.asarray(jk.fk(robot, q0))
    n, dt = 200, 0.01
    t = np.arange(n) * dt
    Ts = np.repeat(T0[None], n, 0)
    Ts[:, 0, 3] += 0.05 * np.sin(np.pi * t)  # a 5 cm circle in 2 s
    Ts[:, 1, 3] += 0.05 * (1 - np.cos(np.pi * t))
    res = jk.resolved_rate_control(robot, q0, Ts, dt, gain=20.0)
    assert res.q.shape == (n + 1, 7) and res.qd.shape == (n, 7)
    assert res.position_error.shape == (n,) and res.orientation_error.shape == (n,)
    np.testing.assert_array_equal(np.asarray(res.q[0]), q0)
    assert float(res.max_position_error) < 1e-4
    assert float(res.max_orientation_error) < 1e-4
    # the reported errors are the real ones
    T_end = np.asarray(jk.fk(robot, res.q[-1]))
    assert np.linalg.norm(T_end[:3, 3] - Ts[-1, :3, 3]) == pytest.approx(
        float(res.position_error[-1]), abs=1e-15
    )
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    assert np.all((np.asarray(res.q) >= lo) & (np.asarray(res.q) <= hi))
    # without feedback the same loop drifts (explicit Euler): the gain is doing the work
    open_loop = jk.resolved_rate_control(robot, q0, Ts, dt, gain=0.0)
    assert float(open_loop.max_position_error) > 10 * float(res.max_position_error)
    # pseudo-inverse variant
    pinv = jk.resolved_rate_control(robot, q0, Ts, dt, gain=20.0, damping=None, rcond=1e-8)
    assert float(pinv.max_position_error) < 1e-4


def test_errors():
    J = np.zeros((6, 7))
    with pytest.raises(jk.ShapeError, match=r"v must have shape \(6,\)"):
        jk.damped_least_squares(J, np.zeros(3), damping=0.1)
    with pytest.raises(jk.ShapeError, match=r"jax\.vmap"):
        jk.pinv_velocity(np.zeros((2, 6, 7)), np.zeros(6), rcond=1e-6)
    with pytest.raises(jk.JaxkinError, match="damping must be >= 0"):
        jk.damped_least_squares(J, np.zeros(6), damping=-1.0)
    with pytest.raises(jk.ShapeError, match="joint_weights must be a vector"):
        jk.damped_least_squares(J, np.zeros(6), damping=0.1, joint_weights=np.ones(3))
    with pytest.raises(TypeError):
        jk.pinv_velocity(J, np.zeros(6))  # rcond is required
    robot = jk.robots.load("ur5", dtype=np.float64)
    with pytest.raises(jk.ShapeError, match="T_path"):
        jk.resolved_rate_control(robot, np.zeros(6), np.zeros((4, 4)), 0.01)
    with pytest.raises(jk.JaxkinError, match="dt must be"):
        jk.resolved_rate_control(robot, np.zeros(6), np.zeros((3, 4, 4)) + np.eye(4), 0.0)
