"""SO(3) at its singular points, as jaxlie tests it: derivatives taken exactly at angle 0 (and pi),
where the closed forms divide 0 by 0, are finite and equal to the limits of their Taylor series;
``safe_norm`` has gradient 0 at 0; the Taylor and closed-form branches meet at the one threshold
(``get_epsilon``); and the host-side numpy twins equal the jnp kernels on random inputs.

Each check is one jitted ``vmap`` over a batch (a few compiles of 3x3 kernels, milliseconds to run).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE

from jaxkin import spatial

E = np.eye(3)
GENERATORS = np.stack([np.asarray(spatial.skew(jnp.asarray(e))) for e in E])  # skew(e_k)
# d vee(R) / dR as a (3, 3, 3) array: vee = (R21 - R12, R02 - R20, R10 - R01) / 2.
VEE_JACOBIAN = np.zeros((3, 3, 3))
for _k, (_i, _j) in enumerate([(2, 1), (0, 2), (1, 0)]):
    VEE_JACOBIAN[_k, _i, _j], VEE_JACOBIAN[_k, _j, _i] = 0.5, -0.5


@functools.cache  # one jit per kernel: a kernel used twice (same shapes) compiles once
def _jit(fn):
    return jax.jit(fn, compiler_options=FAST_COMPILE)  # one compile, not one per operation


@functools.cache
def _jv(fn):
    return jax.jit(jax.vmap(fn), compiler_options=FAST_COMPILE)


def _random_rotations(n: int, seed: int) -> np.ndarray:
    w = np.random.default_rng(seed).normal(size=(n, 3))
    return np.asarray(_jv(spatial.exp_so3)(jnp.asarray(w)))


def _finite(*xs) -> bool:
    return all(bool(np.all(np.isfinite(np.asarray(x)))) for x in xs)


# --- angle 0: derivatives equal the Taylor limits --------------------------------------------
def test_exp_at_zero_first_and_second_derivatives_are_the_series_limits():
    zero = jnp.zeros(3)
    d1 = np.asarray(_jit(jax.jacfwd(spatial.exp_so3))(zero))  # (3, 3, k)
    np.testing.assert_array_equal(np.moveaxis(d1, -1, 0), GENERATORS)  # dR/dw_k = skew(e_k)
    d2 = np.asarray(_jit(jax.jacfwd(jax.jacfwd(spatial.exp_so3)))(zero))  # (3, 3, i, j)
    want = np.einsum("iab,jbc->acij", GENERATORS, GENERATORS)
    np.testing.assert_allclose(d2, 0.5 * (want + want.transpose(0, 1, 3, 2)), rtol=0, atol=1e-15)


def test_log_at_identity_has_the_derivative_of_vee():
    d = np.asarray(_jit(jax.jacfwd(spatial.log_so3))(jnp.eye(3)))
    np.testing.assert_allclose(d, VEE_JACOBIAN, rtol=0, atol=1e-15)
    g = _jit(jax.grad(lambda R: jnp.sum(spatial.log_so3(R) ** 2)))(jnp.eye(3))
    np.testing.assert_array_equal(np.asarray(g), 0.0)
    round_trip = _jit(jax.jacfwd(lambda w: spatial.log_so3(spatial.exp_so3(w))))(jnp.zeros(3))
    np.testing.assert_allclose(np.asarray(round_trip), E, rtol=0, atol=1e-15)


def test_left_jacobian_and_its_inverse_at_zero():
    zero = jnp.zeros(3)
    np.testing.assert_array_equal(np.asarray(spatial.left_jacobian_so3(zero)), E)
    np.testing.assert_array_equal(np.asarray(spatial.left_jacobian_so3_inverse(zero)), E)
    d = np.moveaxis(np.asarray(_jit(jax.jacfwd(spatial.left_jacobian_so3))(zero)), -1, 0)
    np.testing.assert_allclose(d, 0.5 * GENERATORS, rtol=0, atol=1e-15)  # J_l = I + K/2 + ...
    d_inv = _jit(jax.jacfwd(spatial.left_jacobian_so3_inverse))(zero)
    d_inv = np.moveaxis(np.asarray(d_inv), -1, 0)
    np.testing.assert_allclose(d_inv, -0.5 * GENERATORS, rtol=0, atol=1e-15)
    d_r = np.moveaxis(np.asarray(_jit(jax.jacfwd(spatial.right_jacobian_so3))(zero)), -1, 0)
    np.testing.assert_allclose(d_r, -0.5 * GENERATORS, rtol=0, atol=1e-15)  # J_r(w) = J_l(-w)
    hess = _jit(jax.jacfwd(jax.jacfwd(spatial.left_jacobian_so3)))(zero)
    assert _finite(hess)


def test_quaternion_exp_and_log_at_zero():
    d_exp = np.asarray(jax.jacfwd(spatial.quaternion_exp)(jnp.zeros(3)))
    np.testing.assert_allclose(d_exp, np.vstack([np.zeros(3), 0.5 * E]), rtol=0, atol=1e-15)
    d_log = np.asarray(_jit(jax.jacfwd(spatial.quaternion_log))(jnp.array([1.0, 0.0, 0.0, 0.0])))
    np.testing.assert_allclose(d_log, np.hstack([np.zeros((3, 1)), 2.0 * E]), rtol=0, atol=1e-15)


# --- angle pi: finite values and gradients ---------------------------------------------------
PI_AXES = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [1.0, 1.0, 0], [1.0, -2.0, 3.0]])
PI_AXES = PI_AXES / np.linalg.norm(PI_AXES, axis=1, keepdims=True)


def test_log_at_pi_is_pi_times_the_axis_with_finite_derivatives():
    exact = np.stack([2.0 * np.outer(a, a) - E for a in PI_AXES])  # rotations by exactly pi
    rounded = np.asarray(_jv(spatial.exp_so3)(jnp.asarray(np.pi * PI_AXES)))
    for Rs in (exact, rounded):
        w = np.asarray(_jv(spatial.log_so3)(jnp.asarray(Rs)))
        np.testing.assert_allclose(np.abs(np.sum(w * PI_AXES, axis=1)), np.pi, rtol=1e-14)
        d = _jv(jax.jacfwd(spatial.log_so3))(jnp.asarray(Rs))
        g = _jv(jax.grad(lambda R: jnp.sum(spatial.log_so3(R))))(jnp.asarray(Rs))
        assert _finite(d, g)
    along = _jv(jax.jacfwd(lambda t, a: spatial.log_so3(spatial.exp_so3(t * a))))
    assert _finite(along(jnp.full(len(PI_AXES), jnp.pi), jnp.asarray(PI_AXES)))


def test_exp_at_pi_has_the_finite_difference_derivative():
    w = jnp.asarray(np.pi * PI_AXES)
    d = np.asarray(_jv(jax.jacfwd(spatial.exp_so3))(w))
    h = 1e-6
    fd = np.stack(
        [
            (
                np.asarray(_jv(spatial.exp_so3)(w + h * E[k][None]))
                - np.asarray(_jv(spatial.exp_so3)(w - h * E[k][None]))
            )
            / (2 * h)
            for k in range(3)
        ],
        axis=-1,
    )
    np.testing.assert_allclose(d, fd, rtol=0, atol=1e-8)


# --- safe_norm -------------------------------------------------------------------------------
def test_safe_norm_at_zero_has_value_and_gradient_zero():
    for dtype in (jnp.float64, jnp.float32):
        zero = jnp.zeros(3, dtype)
        assert float(spatial.safe_norm(zero)) == 0.0
        g = np.asarray(jax.grad(spatial.safe_norm)(zero))
        np.testing.assert_array_equal(g, 0.0)
        assert g.dtype == dtype
        assert _finite(_jit(jax.hessian(spatial.safe_norm))(zero))
    assert float(jax.grad(spatial.safe_sqrt)(0.0)) == 0.0
    v = jnp.array([3.0, 0.0, -4.0])
    assert float(spatial.safe_norm(v)) == 5.0
    np.testing.assert_allclose(np.asarray(jax.grad(spatial.safe_norm)(v)), [0.6, 0.0, -0.8])
    rows = jnp.array([[3.0, 4.0], [0.0, 0.0]])
    np.testing.assert_array_equal(np.asarray(spatial.safe_norm(rows, axis=1)), [5.0, 0.0])


# --- one threshold: the branches meet at get_epsilon -----------------------------------------
AXIS = np.array([0.48, -0.6, 0.64])  # unit
MEET = {
    "exp_so3": spatial.exp_so3,
    "left_jacobian_so3": spatial.left_jacobian_so3,
    "quaternion_exp": spatial.quaternion_exp,
    "log_so3": lambda w: spatial.log_so3(spatial.exp_so3(w)) / jnp.linalg.norm(w),
    "quaternion_log": lambda w: (
        spatial.quaternion_log(spatial.quaternion_exp(w)) / jnp.linalg.norm(w)
    ),
}


def _both_sides(fn, dtype) -> tuple[np.ndarray, np.ndarray, float]:
    """``fn`` just below and just above the threshold, and the dtype's machine epsilon."""
    eps, ulp = spatial.get_epsilon(dtype), float(jnp.finfo(dtype).eps)
    gap = 16 * ulp  # a few ulps: rounding cannot move either point across
    ws = jnp.asarray(np.stack([eps * (1 - gap) * AXIS, eps * (1 + gap) * AXIS]), dtype)
    small, _ = spatial.small_angle(jnp.sum(ws * ws, axis=1))
    assert bool(small[0]) and not bool(small[1])  # one on each side
    lo, hi = np.asarray(_jv(fn)(ws)).astype(np.float64)
    return lo, hi, ulp


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
@pytest.mark.parametrize("name", sorted(MEET))
def test_taylor_and_closed_form_branches_meet_at_get_epsilon(name, dtype):
    assert spatial.get_epsilon(dtype) == (1e-3 if dtype == jnp.float64 else 3e-2)
    lo, hi, ulp = _both_sides(MEET[name], dtype)
    np.testing.assert_allclose(lo, hi, rtol=0, atol=32 * ulp)


@pytest.mark.xfail(
    strict=True,
    reason="known: the closed form of J_l^-1, (1 - t sin t / (2 (1 - cos t))) / t^2, cancels "
    "just above get_epsilon (about 5e4 ulp in float64, 180 ulp in float32); kept bit-identical "
    "in the renovation, to be fixed with a longer series or a larger threshold for it",
)
@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_left_jacobian_inverse_branches_meet_at_get_epsilon(dtype):
    lo, hi, ulp = _both_sides(spatial.left_jacobian_so3_inverse, dtype)
    np.testing.assert_allclose(lo, hi, rtol=0, atol=32 * ulp)


# --- the host-side numpy twins equal the jnp kernels ------------------------------------------
def test_numpy_twins_equal_the_jnp_kernels_on_random_inputs():
    rng = np.random.default_rng(7)
    n = 64
    q = rng.normal(size=(n, 4)) * np.exp(rng.uniform(-20, 20, size=(n, 1)))  # any nonzero size
    jq = np.asarray(_jv(spatial.quaternion_to_matrix)(jnp.asarray(q)))
    np.testing.assert_allclose(
        np.stack([spatial.quaternion_to_matrix_np(x) for x in q]), jq, rtol=0, atol=1e-15
    )
    axes, angles = rng.normal(size=(n, 3)), rng.uniform(-7, 7, size=n)
    units = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    ja = np.asarray(_jv(spatial.rotation_about_axis)(jnp.asarray(units), jnp.asarray(angles)))
    na = np.stack([spatial.rotation_about_axis_np(a, t) for a, t in zip(axes, angles, strict=True)])
    np.testing.assert_allclose(na, ja, rtol=0, atol=1e-15)
    p = rng.normal(size=(n, 3))
    jt = np.asarray(_jv(spatial.make_transform)(jnp.asarray(ja), jnp.asarray(p)))
    nt = np.stack([spatial.make_transform_np(R, x) for R, x in zip(na, p, strict=True)])
    np.testing.assert_allclose(nt, jt, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(spatial.make_transform_np(), np.eye(4))
    Rs = _random_rotations(n, seed=8)
    rpy = np.asarray(_jv(spatial.matrix_to_rpy)(jnp.asarray(Rs)))
    n_rpy = np.stack([spatial.matrix_to_rpy_np(R) for R in Rs])
    assert np.min(np.abs(np.cos(rpy[:, 1]))) > 1e-2  # away from gimbal lock: one answer
    np.testing.assert_allclose(n_rpy, rpy, rtol=0, atol=1e-13)


def test_numpy_and_jnp_rpy_agree_exactly_at_gimbal_lock():
    for pitch in (np.pi / 2, -np.pi / 2):
        R = np.array(spatial.rpy_to_matrix(jnp.array([0.7, pitch, 0.0])))
        R[0, 0] = R[1, 0] = 0.0  # exactly locked
        ours, host = np.asarray(spatial.matrix_to_rpy(jnp.asarray(R))), spatial.matrix_to_rpy_np(R)
        assert ours[2] == host[2] == 0.0  # yaw = 0 by convention
        np.testing.assert_allclose(host, ours, rtol=0, atol=1e-15)


def test_quaternion_kernels_agree_with_the_rotation_matrix_ones():
    w = jnp.asarray(np.random.default_rng(9).normal(size=(32, 3)))
    R = np.asarray(_jv(spatial.exp_so3)(w))
    q = _jv(spatial.quaternion_exp)(w)
    np.testing.assert_allclose(
        np.asarray(_jv(spatial.quaternion_to_matrix)(q)), R, rtol=0, atol=1e-14
    )
    np.testing.assert_allclose(
        np.asarray(_jv(spatial.quaternion_log)(q)),
        np.asarray(_jv(spatial.log_so3)(jnp.asarray(R))),
        rtol=0,
        atol=1e-13,
    )
    qq = _jv(spatial.quaternion_multiply)(q, _jv(spatial.quaternion_conjugate)(q))
    np.testing.assert_allclose(np.asarray(qq), np.tile([1.0, 0, 0, 0], (32, 1)), atol=1e-15)
    # The left Jacobian maps a change of w to the spatial angular change of exp(w).
    dw = jnp.asarray(np.random.default_rng(10).normal(size=(32, 3)))
    Rdot = _jv(lambda a, b: jax.jvp(spatial.exp_so3, (a,), (b,))[1])(w, dw)
    omega = np.asarray(_jv(lambda Rd, R: spatial.vee(Rd @ R.T))(Rdot, jnp.asarray(R)))
    Jl = _jv(spatial.left_jacobian_so3)(w)
    np.testing.assert_allclose(omega, np.asarray(jnp.einsum("nij,nj->ni", Jl, dw)), atol=1e-13)
    ident = jnp.einsum("nij,njk->nik", Jl, _jv(spatial.left_jacobian_so3_inverse)(w))
    np.testing.assert_allclose(np.asarray(ident), np.tile(E, (32, 1, 1)), rtol=0, atol=1e-12)
