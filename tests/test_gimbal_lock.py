"""Euler-angle extraction at and near gimbal lock.

``matrix_to_rpy`` at pitch exactly +-pi/2 and ``matrix_to_zyz`` at theta exactly 0 or pi used to
return angles that did not rebuild the matrix (errors up to 1.7). The round trip
``rpy_to_matrix(matrix_to_rpy(R)) == R`` (and the zyz one) must hold everywhere, exact lock
included (built exactly: ``Rz Ry(+-pi/2) Rx`` with an exact ``Ry``, and by hand), eagerly and under
``jit``, in float64 and float32, with finite gradients; at the lock the convention is yaw = 0
(rpy) and phi = 0 (zyz), as Pinocchio's ``matrixToRpy`` and spatialmath's ``tr2eul``. Away from
the lock the results are bit for bit those of the plain ``atan2`` formulas used before.
"""

from __future__ import annotations

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _oracle_modules import lazy_module
from _xla import FAST_COMPILE
from hypothesis import example, given
from hypothesis import strategies as st

import jaxkin.testing as jkt
from jaxkin import spatial

with warnings.catch_warnings():  # the oracles are test dependencies (the test extra)
    warnings.simplefilter("ignore", DeprecationWarning)
    import pinocchio as pin

smb = lazy_module("spatialmath.base")  # imported by the test that uses it

TOL = {np.float64: 1e-12, np.float32: 1e-5}
DTYPES = [np.float64, np.float32]
MODES = ["eager", "jit"]

angle = st.floats(-math.pi, math.pi, allow_nan=False, allow_subnormal=False)
sign = st.sampled_from([1, -1])

# Exact Ry(+pi/2), Ry(-pi/2) (rpy lock) and Ry(0), Ry(pi) (zyz lock): entries 0 and +-1 only.
RY_HALF_PI = {1: np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])}
RY_HALF_PI[-1] = RY_HALF_PI[1].T
RY_ZYZ_LOCK = {0: np.eye(3), 1: np.diag([-1.0, 1.0, -1.0])}


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0], [0, 0, 1]])


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0, 1, 0], [-s, 0, c]])


def _rpy_locked_product(yaw, s, roll):
    """Rz(yaw) Ry(s pi/2) Rx(roll) with exactly R[2, 0] = -s and R[0, 0] = R[1, 0] = 0."""
    R = _rz(yaw) @ RY_HALF_PI[s] @ _rx(roll)
    assert R[2, 0] == -s and R[0, 0] == 0.0 and R[1, 0] == 0.0
    return R


def _rpy_locked_by_hand(d, s):
    """R[2, 0] = -s written by hand: pitch s pi/2, d = roll - s yaw."""
    c, sn = math.cos(d), math.sin(d)
    return np.array([[0.0, s * sn, s * c], [0.0, c, -sn], [-s, 0.0, 0.0]])


def _zyz_locked_product(phi, k, psi):
    """Rz(phi) Ry(k pi) Rz(psi), k in {0, 1}: R[0, 2] = R[1, 2] = R[2, 0] = R[2, 1] = 0 exactly."""
    R = _rz(phi) @ RY_ZYZ_LOCK[k] @ _rz(psi)
    assert R[0, 2] == R[1, 2] == R[2, 0] == R[2, 1] == 0.0 and abs(R[2, 2]) == 1.0
    return R


def _zyz_locked_by_hand(d, k):
    """R[2, 2] = +-1 written by hand: theta k pi, d = phi + psi (k = 0) or phi - psi (k = 1)."""
    c, sn = math.cos(d), math.sin(d)
    z = -1.0 if k else 1.0
    return np.array([[z * c, -sn, 0.0], [z * sn, c, 0.0], [0.0, 0.0, z]])


def _negative_zeros(R, where):
    """R with the given (zero) entries replaced by -0.0 (atan2(-0.0, -0.0) is -pi, not 0)."""
    R = R.copy()
    for ij in where:
        assert R[ij] == 0.0
        R[ij] = -0.0
    return R


_exp_log = jax.jit(lambda R: spatial.exp_so3(spatial.log_so3(R)), compiler_options=FAST_COMPILE)


def _noisy(R):
    """The same rotation with unstructured rounding errors (as a forward-kinematics result has)."""
    return np.asarray(_exp_log(jnp.asarray(R)))


# Offsets from the lock: exact, within rounding, and up to the "near" switch and beyond.
offset = st.sampled_from([0.0, 1e-300, 1e-17, 1e-15, 1e-12, 1e-9, 1e-6, 1e-3, 9e-3, 1.1e-2, 0.2])

rpy_exact_lock = st.one_of(
    st.builds(_rpy_locked_product, angle, sign, angle),
    st.builds(_rpy_locked_by_hand, angle, sign),
)
zyz_exact_lock = st.one_of(
    st.builds(_zyz_locked_product, angle, st.sampled_from([0, 1]), angle),
    st.builds(_zyz_locked_by_hand, angle, st.sampled_from([0, 1])),
)
rpy_near_lock = st.builds(
    lambda y, s, e, r, noisy: (_noisy if noisy else np.asarray)(
        _rz(y) @ _ry(s * (math.pi / 2 - e)) @ _rx(r)
    ),
    angle,
    sign,
    offset,
    angle,
    st.booleans(),
)
zyz_near_lock = st.builds(
    lambda f, k, e, p, noisy: (_noisy if noisy else np.asarray)(
        _rz(f) @ _ry(k * math.pi + (-e if k else e)) @ _rz(p)
    ),
    angle,
    st.sampled_from([0, 1]),
    offset,
    angle,
    st.booleans(),
)

CONV = {
    "rpy": (spatial.matrix_to_rpy, spatial.rpy_to_matrix),
    "zyz": (spatial.matrix_to_zyz, spatial.zyz_to_matrix),
}
_JIT_ROUND_TRIP = {
    k: jax.jit(lambda R, f=f, g=g: g(f(R)), compiler_options=FAST_COMPILE)
    for k, (f, g) in CONV.items()
}
_JIT_FROM = {k: jax.jit(f, compiler_options=FAST_COMPILE) for k, (f, _) in CONV.items()}


def _round_trip(kind, R, dtype, mode):
    """Asserts that the angles of R rebuild R; returns the angles (numpy)."""
    R = jnp.asarray(R, dtype=dtype)
    f, g = CONV[kind]
    if mode == "jit":
        ang, back = _JIT_FROM[kind](R), _JIT_ROUND_TRIP[kind](R)
    else:
        ang = f(R)
        back = g(ang)
    assert ang.dtype == dtype and back.dtype == dtype
    ang = np.asarray(ang)
    assert np.all(np.isfinite(ang))
    np.testing.assert_allclose(np.asarray(back), np.asarray(R), rtol=0, atol=TOL[dtype])
    return ang


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


# --- round trip -------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("dtype", DTYPES)
@given(rpy_exact_lock)
@example(_rpy_locked_product(0.7, 1, 0.3))
@example(_rpy_locked_product(0.7, -1, 0.3))
@example(_rpy_locked_by_hand(math.pi, 1))
@example(_negative_zeros(_rpy_locked_by_hand(0.4, -1), [(0, 0), (1, 0)]))
def test_rpy_round_trip_exact_lock(dtype, mode, R):
    ang = _round_trip("rpy", R, dtype, mode)
    s = -R[2, 0]
    assert ang[1] == np.asarray(s * np.pi / 2, dtype=dtype)  # pitch exactly +-pi/2
    assert ang[2] == 0.0  # convention: yaw = 0 ...
    d = math.atan2(-R[1, 2], R[1, 1])  # ... so roll carries roll - s yaw
    assert abs(_wrap(ang[0] - d)) <= 10 * TOL[dtype]


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("dtype", DTYPES)
@given(zyz_exact_lock)
@example(_zyz_locked_product(0.3, 1, 0.5))
@example(_zyz_locked_product(0.3, 0, 0.5))
@example(_zyz_locked_by_hand(-math.pi, 0))
@example(_negative_zeros(_zyz_locked_by_hand(0.4, 1), [(0, 2), (1, 2)]))
def test_zyz_round_trip_exact_lock(dtype, mode, R):
    ang = _round_trip("zyz", R, dtype, mode)
    assert ang[1] == (0.0 if R[2, 2] > 0 else np.asarray(np.pi, dtype=dtype))
    assert ang[0] == 0.0  # convention: phi = 0 ...
    d = math.atan2(R[1, 0], R[1, 1])  # ... so psi carries phi + psi (theta 0) or psi - phi (pi)
    assert abs(_wrap(ang[2] - d)) <= 10 * TOL[dtype]


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("dtype", DTYPES)
@given(st.one_of(rpy_near_lock, jkt.rotations()))
def test_rpy_round_trip_near_lock_and_generic(dtype, mode, R):
    ang = _round_trip("rpy", R, dtype, mode)
    assert abs(ang[1]) <= np.float32(np.pi / 2) and np.all(np.abs(ang) <= np.float32(np.pi))


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("dtype", DTYPES)
@given(st.one_of(zyz_near_lock, jkt.rotations()))
def test_zyz_round_trip_near_lock_and_generic(dtype, mode, R):
    ang = _round_trip("zyz", R, dtype, mode)
    assert 0.0 <= ang[1] <= np.float32(np.pi) and np.all(np.abs(ang) <= np.float32(np.pi))


def test_vmap_over_locked_and_regular():
    Rs = np.stack(
        [
            _rpy_locked_product(0.7, 1, 0.3),
            _rpy_locked_by_hand(2.0, -1),
            _zyz_locked_product(0.3, 1, 0.5),
            _zyz_locked_product(0.3, 0, 0.5),
            _rz(0.1) @ _ry(0.2) @ _rx(0.3),
        ]
    )
    for f, g in CONV.values():
        back = jax.vmap(lambda R, f=f, g=g: g(f(R)))
        back = jax.jit(back, compiler_options=FAST_COMPILE)(jnp.asarray(Rs))
        np.testing.assert_allclose(np.asarray(back), Rs, rtol=0, atol=1e-12)


# --- away from the lock: the previous formulas, bit for bit -----------------------------------
def _plain_rpy(R):
    yaw = jnp.arctan2(R[1, 0], R[0, 0])
    pitch = jnp.arctan2(-R[2, 0], jnp.sqrt(R[0, 0] ** 2 + R[1, 0] ** 2))
    roll = jnp.arctan2(R[2, 1], R[2, 2])
    return jnp.stack([roll, pitch, yaw])


def _plain_zyz(R):
    theta = jnp.arctan2(jnp.sqrt(R[0, 2] ** 2 + R[1, 2] ** 2), R[2, 2])
    phi = jnp.arctan2(R[1, 2], R[0, 2])
    psi = jnp.arctan2(R[2, 1], -R[2, 0])
    return jnp.stack([phi, theta, psi])


@pytest.mark.parametrize("dtype", DTYPES)
@given(st.one_of(jkt.rotations(), rpy_near_lock, zyz_near_lock))
def test_unchanged_away_from_lock(dtype, R):
    R = jnp.asarray(R, dtype=dtype)
    far = 1e-2 if dtype == np.float64 else 1e-1
    if float(R[0, 0] ** 2 + R[1, 0] ** 2) >= far**2:
        np.testing.assert_array_equal(
            np.asarray(spatial.matrix_to_rpy(R)), np.asarray(_plain_rpy(R))
        )
    if float(R[0, 2] ** 2 + R[1, 2] ** 2) >= far**2:
        np.testing.assert_array_equal(
            np.asarray(spatial.matrix_to_zyz(R)), np.asarray(_plain_zyz(R))
        )


# --- gradients --------------------------------------------------------------------------------
def _cos_pitch(c, sign):
    """Rz(0.7) Ry(p) Rx(0.3) with cos(p) = c exactly, c down to below underflow."""
    s = sign * math.sqrt(1.0 - c * c)
    return _rz(0.7) @ np.array([[c, 0.0, s], [0, 1, 0], [-s, 0, c]]) @ _rx(0.3)


def _sin_theta(st_, sign):
    """Rz(0.3) Ry(theta) Rz(0.5) with sin(theta) = st_ exactly."""
    ct = sign * math.sqrt(1.0 - st_ * st_)
    return _rz(0.3) @ np.array([[ct, 0.0, st_], [0, 1, 0], [-st_, 0, ct]]) @ _rz(0.5)


SMALL = {
    np.float64: [0.0, 1e-170, 1e-154, 1e-120, 1e-17, 1e-9, 1e-3, 2e-2],
    np.float32: [0.0, 1e-25, 1e-19, 1e-12, 1e-6, 1e-2, 2e-1],
}


def _lock_points(dtype):
    pts = [_rpy_locked_product(0.7, 1, 0.3), _rpy_locked_by_hand(-1.0, -1)]
    pts += [_zyz_locked_product(0.3, 1, 0.5), _zyz_locked_product(0.3, 0, 0.5)]
    for c in SMALL[dtype]:
        for s in (1.0, -1.0):
            pts += [_cos_pitch(c, s), _sin_theta(c, s)]
    return pts


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("kind", ["rpy", "zyz"])
def test_gradients_finite_at_and_near_lock(kind, dtype):
    f, g = CONV[kind]
    pts = jnp.asarray(np.stack(_lock_points(dtype)), dtype=dtype)
    if dtype == np.float64:  # eagerly (slow to dispatch) at an exact lock of this convention ...
        J = jax.jacfwd(f)(pts[0 if kind == "rpy" else 2])
        assert J.shape == (3, 3, 3) and np.all(np.isfinite(np.asarray(J)))
    # ... and jitted at every point, exact lock and cos(pitch) / sin(theta) down to underflow
    J = jax.jit(jax.vmap(jax.jacfwd(f)), compiler_options=FAST_COMPILE)(pts)
    assert J.shape == (len(pts), 3, 3, 3) and J.dtype == dtype
    assert np.all(np.isfinite(np.asarray(J)))
    w = jnp.asarray([0.3, -0.5, 0.8], dtype=dtype)

    def along_path(t, R0):  # rotation leaving R0 in a generic direction
        return jnp.sum(f(R0 @ spatial.exp_so3(t * w)))

    ts = jnp.asarray([0.0, 1e-12, 1e-6], dtype=dtype)
    d = jax.vmap(jax.vmap(jax.grad(along_path), (0, None)), (None, 0))
    d = jax.jit(d, compiler_options=FAST_COMPILE)(ts, pts)
    assert d.shape == (len(pts), 3) and np.all(np.isfinite(np.asarray(d)))
    # and the round trip through the gradient-safe branches still rebuilds R
    back = jax.jit(jax.vmap(lambda R: g(f(R))), compiler_options=FAST_COMPILE)(pts)
    np.testing.assert_allclose(np.asarray(back), np.asarray(pts), rtol=0, atol=TOL[dtype])


def test_round_trip_derivative_is_identity_near_lock():
    """d/dt of rpy_to_matrix(matrix_to_rpy(R(t))) equals dR/dt where the angles are smooth
    (the de-rotated branch near the lock differentiates consistently)."""
    w = jnp.asarray([0.3, -0.5, 0.8])
    R0s = jnp.asarray(
        np.stack([_cos_pitch(1e-6, 1.0), _cos_pitch(1e-3, -1.0), _sin_theta(1e-6, -1.0)])
    )
    for f, g in CONV.values():

        def tangents(R0, f=f, g=g):
            path = lambda t: R0 @ spatial.exp_so3(t * w)  # noqa: E731
            d_rt = jax.jvp(lambda t: g(f(path(t))), (0.0,), (1.0,))[1]
            return d_rt, jax.jvp(path, (0.0,), (1.0,))[1]

        d_rt, d_R = jax.jit(jax.vmap(tangents), compiler_options=FAST_COMPILE)(R0s)
        np.testing.assert_allclose(np.asarray(d_rt), np.asarray(d_R), rtol=0, atol=1e-8)


# --- oracles: Pinocchio (rpy) and spatialmath (zyz) rebuild the same matrix -------------------
@given(st.one_of(rpy_exact_lock, rpy_near_lock, jkt.rotations()))
@example(_rpy_locked_product(0.7, 1, 0.3))
@example(_rpy_locked_product(0.7, -1, 0.3))
def test_rpy_against_pinocchio(R):
    ours = np.asarray(spatial.matrix_to_rpy(jnp.asarray(R)))
    theirs = pin.rpy.matrixToRpy(R)
    rebuilt_ours = np.asarray(spatial.rpy_to_matrix(jnp.asarray(ours)))
    rebuilt_theirs = pin.rpy.rpyToMatrix(theirs)
    np.testing.assert_allclose(rebuilt_ours, R, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rebuilt_theirs, R, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rebuilt_ours, rebuilt_theirs, rtol=0, atol=1e-12)
    if R[0, 0] == 0.0 and R[1, 0] == 0.0:  # exact lock: same convention (yaw = 0), same angles
        np.testing.assert_allclose(_wrap(ours - theirs), 0.0, atol=1e-12)


@given(st.one_of(zyz_exact_lock, zyz_near_lock, jkt.rotations()))
@example(_zyz_locked_product(0.3, 1, 0.5))
@example(_zyz_locked_product(0.3, 0, 0.5))
def test_zyz_against_spatialmath(R):
    ours = np.asarray(spatial.matrix_to_zyz(jnp.asarray(R)))
    theirs = smb.tr2eul(R)
    rebuilt_ours = np.asarray(spatial.zyz_to_matrix(jnp.asarray(ours)))
    rebuilt_theirs = smb.eul2r(theirs)
    np.testing.assert_allclose(rebuilt_ours, R, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rebuilt_theirs, R, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rebuilt_ours, rebuilt_theirs, rtol=0, atol=1e-12)
    if R[0, 2] == 0.0 and R[1, 2] == 0.0:  # exact lock: same convention (phi = 0), same angles
        np.testing.assert_allclose(_wrap(ours - theirs), 0.0, atol=1e-12)
