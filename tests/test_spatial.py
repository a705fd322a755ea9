"""Spatial algebra: the chapter's skew-symmetric properties (Eqs. 4.4 - 4.12), rotations and their
parameterisations, exp/log NaN-free at angle 0 and pi, adjoint, angular velocity (Eq. 4.18)."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE
from hypothesis import given
from hypothesis import strategies as st

import jaxkin.testing as jkt
from jaxkin import spatial

# XLA on CPU flushes subnormals to zero, so they are excluded.
vec3 = st.tuples(*[st.floats(-10, 10, allow_nan=False, allow_subnormal=False)] * 3).map(np.array)
scalar = st.floats(-10, 10, allow_nan=False, allow_subnormal=False)


# --- Eqs. 4.4 - 4.10: the skew-symmetric operator ---------------------------------------------
@given(vec3)
def test_skew_is_skew_symmetric_with_zero_diagonal(a):  # Eqs. 4.4, 4.5, 4.6
    S = np.asarray(spatial.skew(a))
    np.testing.assert_array_equal(S + S.T, np.zeros((3, 3)))
    np.testing.assert_array_equal(np.diag(S), np.zeros(3))
    expected = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    np.testing.assert_array_equal(S, expected)
    np.testing.assert_array_equal(np.asarray(spatial.vee(S)), a)


@given(vec3, vec3, scalar, scalar)
def test_skew_is_linear(a, b, alpha, beta):  # Eq. 4.7
    lhs = np.asarray(spatial.skew(alpha * a + beta * b))
    rhs = alpha * np.asarray(spatial.skew(a)) + beta * np.asarray(spatial.skew(b))
    np.testing.assert_allclose(lhs, rhs, rtol=0, atol=1e-12 * (1 + np.abs(rhs).max()))


@given(vec3, vec3)
def test_skew_is_cross_product(a, p):  # Eq. 4.8
    np.testing.assert_allclose(
        np.asarray(spatial.skew(a)) @ p, np.cross(a, p), rtol=0, atol=1e-12 * 100
    )


@given(jkt.rotations(), vec3)
def test_skew_rotation_conjugation(R, a):  # Eq. 4.9: R S(a) R^T = S(R a)
    lhs = R @ np.asarray(spatial.skew(a)) @ R.T
    np.testing.assert_allclose(lhs, np.asarray(spatial.skew(R @ a)), rtol=0, atol=1e-12 * 10)


@given(vec3, vec3)
def test_skew_quadratic_form_vanishes(a, x):  # Eq. 4.10: x^T S x = 0
    S = np.asarray(spatial.skew(a))
    assert abs(x @ S @ x) <= 1e-11 * (1 + np.linalg.norm(a)) * (1 + x @ x)


@given(jkt.unit_vectors(), st.floats(-6, 6), st.floats(-3, 3))
def test_derivative_of_rotation_is_skew_times_rotation(k, theta, rate):  # Eqs. 4.11, 4.12
    R_of_t = lambda t: spatial.rotation_about_axis(jnp.asarray(k), theta + rate * t)  # noqa: E731
    R, Rdot = jax.jvp(R_of_t, (0.0,), (1.0,))
    S = np.asarray(Rdot @ R.T)
    np.testing.assert_allclose(S + S.T, np.zeros((3, 3)), atol=1e-12)
    np.testing.assert_allclose(S, rate * np.asarray(spatial.skew(k)), atol=1e-12)
    np.testing.assert_allclose(
        np.asarray(spatial.angular_velocity(R_of_t, 0.0)), rate * k, atol=1e-12
    )
    np.testing.assert_allclose(
        np.asarray(spatial.body_angular_velocity(R_of_t, 0.0)),
        rate * (np.asarray(R).T @ k),
        atol=1e-12,
    )


@given(
    st.lists(
        st.tuples(jkt.unit_vectors(), st.floats(-3, 3), st.floats(-2, 2)), min_size=1, max_size=6
    ),
    st.floats(-1, 1),
)
def test_rdot_rt_skew_and_angular_velocity_addition(chain, t0):  # Eq. 4.18
    """Frames chained by time-varying rotations R_{i-1,i}(t) = Rot(k_i, a_i + b_i t): the angular
    velocity of the last frame equals the sum of the relative ones rotated into frame 0."""
    ks = jnp.asarray(np.array([c[0] for c in chain]))
    a = jnp.asarray([c[1] for c in chain])
    b = jnp.asarray([c[2] for c in chain])
    R, Rdot, omega, summed = jax.device_get(_chain_velocities(ks, a, b, jnp.asarray(t0)))
    S = np.asarray(Rdot @ R.T)
    np.testing.assert_allclose(S, -S.T, atol=1e-12)
    np.testing.assert_allclose(omega, summed, rtol=0, atol=1e-12 * len(chain))


# one program per chain length (op by op, every length compiles its own operations)
@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _chain_velocities(ks, a, b, t0):
    """``(R, Rdot, omega, summed)`` of the chain ``R(t) = prod_i Rot(k_i, a_i + b_i t)`` at t0:
    the tangent by ``jax.jvp``, omega by ``spatial.angular_velocity`` and the sum of the relative
    angular velocities (each ``b_i k_i``, the axis being fixed in both frames) rotated into
    frame 0."""

    def rel(t):
        return jax.vmap(spatial.rotation_about_axis)(ks, a + b * t)

    def R_total(t):
        R = jnp.eye(3)
        for Ri in rel(t):
            R = R @ Ri
        return R

    R, Rdot = jax.jvp(R_total, (t0,), (jnp.ones_like(t0),))
    omega = spatial.angular_velocity(R_total, t0)
    summed = spatial.compose_angular_velocities(rel(t0), b[:, None] * ks)
    return R, Rdot, omega, summed


# --- rotations and parameterisations ----------------------------------------------------------
@given(st.floats(-math.pi, math.pi), st.floats(-1.5, 1.5), st.floats(-math.pi, math.pi))
def test_rpy_round_trip_and_convention(roll, pitch, yaw):
    R = np.asarray(spatial.rpy_to_matrix(jnp.array([roll, pitch, yaw])))
    expected = (
        np.asarray(spatial.rot_z(yaw))
        @ np.asarray(spatial.rot_y(pitch))
        @ np.asarray(spatial.rot_x(roll))
    )
    np.testing.assert_allclose(R, expected, atol=1e-14)
    back = np.asarray(spatial.matrix_to_rpy(jnp.asarray(R)))
    np.testing.assert_allclose(np.asarray(spatial.rpy_to_matrix(back)), R, atol=1e-12)
    if abs(pitch) < 1.5:
        np.testing.assert_allclose(back, [roll, pitch, yaw], atol=1e-10)


@given(st.floats(-math.pi, math.pi), st.floats(0.01, math.pi - 0.01), st.floats(-math.pi, math.pi))
def test_zyz_round_trip(phi, theta, psi):
    R = np.asarray(spatial.zyz_to_matrix(jnp.array([phi, theta, psi])))
    back = np.asarray(spatial.matrix_to_zyz(jnp.asarray(R)))
    np.testing.assert_allclose(back, [phi, theta, psi], atol=1e-9)


@given(jkt.rotations())
def test_rotations_are_orthonormal(R):
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
    assert abs(np.linalg.det(R) - 1) < 1e-14


def test_elementary_rotations_match_rodrigues():
    for t in (0.3, -2.0, math.pi):
        for axis, fn in enumerate((spatial.rot_x, spatial.rot_y, spatial.rot_z)):
            np.testing.assert_allclose(
                np.asarray(fn(t)),
                np.asarray(spatial.rotation_about_axis(jnp.eye(3)[axis], t)),
                atol=1e-15,
            )


@given(jkt.unit_vectors(), st.floats(0, math.pi))
def test_exp_log_round_trip(axis, angle):
    w = axis * angle
    R = spatial.exp_so3(jnp.asarray(w))
    np.testing.assert_allclose(
        np.asarray(R), np.asarray(spatial.rotation_about_axis(axis, angle)), atol=1e-14
    )
    w_back = np.asarray(spatial.log_so3(R))
    if angle < math.pi - 1e-6:
        np.testing.assert_allclose(w_back, w, atol=1e-9)
    # at pi, -w is the same rotation; either way exp(log(R)) == R
    np.testing.assert_allclose(
        np.asarray(spatial.exp_so3(jnp.asarray(w_back))), np.asarray(R), atol=1e-9
    )


# one program for every angle below (op by op, each derivative compiles its own ops)
@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _exp_log_derivatives(w):
    R = spatial.exp_so3(w)
    return dict(
        J_exp=jax.jacfwd(spatial.exp_so3)(w),
        J_exp_rev=jax.jacrev(spatial.exp_so3)(w),
        J_log=jax.jacfwd(spatial.log_so3)(R),
        J_log_rev=jax.jacrev(spatial.log_so3)(R),
        g=jax.grad(lambda ww: jnp.sum(spatial.log_so3(spatial.exp_so3(ww)) ** 2))(w),
        log=spatial.log_so3(R),
        J=jax.jacfwd(lambda ww: spatial.log_so3(spatial.exp_so3(ww)))(w),
    )


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-6, 1e-3, math.pi - 1e-6, math.pi])
def test_exp_and_log_values_and_gradients_are_finite_at_0_and_pi(angle):
    axis = np.array([0.48, -0.6, 0.64])
    w = jnp.asarray(axis * angle)
    d = jax.device_get(_exp_log_derivatives(w))
    J_exp, J_exp_rev = d["J_exp"], d["J_exp_rev"]
    assert np.all(np.isfinite(J_exp)) and np.all(np.isfinite(J_exp_rev))
    for arr in (d["J_log"], d["J_log_rev"], d["g"], d["log"]):
        assert np.all(np.isfinite(np.asarray(arr))), angle
    if angle < 1.0:
        # log(exp(w)) = w near 0, so its Jacobian is the identity
        J = d["J"]
        np.testing.assert_allclose(np.asarray(J), np.eye(3), atol=1e-9)
        # d exp / d w at 0 is skew(e_k) for each k (the generators)
        if angle == 0.0:
            for k in range(3):
                np.testing.assert_allclose(
                    np.asarray(J_exp[:, :, k]), np.asarray(spatial.skew(jnp.eye(3)[k])), atol=1e-15
                )


# --- transforms --------------------------------------------------------------------------------
@given(jkt.transforms(), jkt.transforms(), vec3)
def test_transforms_inverse_and_adjoint(T1, T2, p):
    Ti = np.asarray(spatial.transform_inverse(jnp.asarray(T1)))
    np.testing.assert_allclose(Ti @ T1, np.eye(4), atol=1e-13)
    np.testing.assert_allclose(
        np.asarray(spatial.transform_point(T1, p)), (T1 @ np.append(p, 1.0))[:3], atol=1e-13
    )
    # Ad(T1 T2) = Ad(T1) Ad(T2), Ad(T^-1) = Ad(T)^-1
    A = lambda T: np.asarray(spatial.adjoint(jnp.asarray(T)))  # noqa: E731
    np.testing.assert_allclose(A(T1 @ T2), A(T1) @ A(T2), atol=1e-12)
    np.testing.assert_allclose(A(Ti), np.linalg.inv(A(T1)), atol=1e-12)
    np.testing.assert_allclose(
        np.asarray(spatial.make_transform(T1[:3, :3], T1[:3, 3])), T1, atol=0
    )


def test_adjoint_maps_body_twist_to_spatial_twist():
    """d/dt T(t) = T(t) [V_b]^ (body) and [V_s]^ T(t) (spatial) with V_s = Ad(T) V_b."""
    T0 = np.asarray(
        spatial.make_transform(
            spatial.rpy_to_matrix(jnp.array([0.3, -0.4, 1.2])), jnp.array([0.5, -0.2, 0.9])
        )
    )
    Vb = np.array([0.1, -0.3, 0.2, 0.7, -0.5, 0.4])

    def hat(V):
        M = np.zeros((4, 4))
        M[:3, :3] = np.asarray(spatial.skew(V[3:]))
        M[:3, 3] = V[:3]
        return M

    Tdot = T0 @ hat(Vb)
    Vs = np.asarray(spatial.adjoint(jnp.asarray(T0))) @ Vb
    np.testing.assert_allclose(hat(Vs) @ T0, Tdot, atol=1e-14)
