"""Orientation representations: rate matrices B(phi), J_a = blkdiag(I, B^-1) J_g, singularities."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _padded import padded
from _xla import FAST_COMPILE, op_by_op
from hypothesis import given
from hypothesis import strategies as st

import jaxkin as jk
import jaxkin.testing as jkt
from jaxkin import representations as reps
from jaxkin import spatial

angles = st.tuples(*[st.floats(-3, 3, allow_nan=False, allow_subnormal=False)] * 3).map(np.array)


@functools.cache  # one program per representation for every example (op by op costs more)
def _rates(rep):
    """``phi -> (B closed form, B by autodiff, omega of R(phi + t phidot) by jax.jvp, phidot)``."""
    phidot = jnp.array([0.3, -0.7, 0.5])

    def rates(phi):
        omega = spatial.angular_velocity(lambda t: reps.to_matrix(phi + t * phidot, rep), 0.0)
        return jk.rate_matrix(phi, rep), reps.rate_matrix_autodiff(phi, rep), omega, phidot

    return jax.jit(rates, compiler_options=FAST_COMPILE)


@pytest.mark.parametrize("rep", reps.REPRESENTATIONS)
@given(phi=angles)
def test_rate_matrix_closed_form_equals_autodiff(rep, phi):
    if rep == "rotvec":
        phi = phi / max(1.0, np.linalg.norm(phi) / 3.0)  # principal branch |w| <= 3
    B, B_ad, _, _ = jax.device_get(_rates(rep)(jnp.asarray(phi)))
    np.testing.assert_allclose(B, B_ad, rtol=0, atol=1e-13)


@pytest.mark.parametrize("rep", reps.REPRESENTATIONS)
@given(phi=angles)
def test_angular_velocity_is_B_phi_dot(rep, phi):
    """omega of R(phi + t phidot) equals B(phi) phidot (spatial.angular_velocity is an independent
    route, through jax.jvp of the rotation itself)."""
    B, _, omega, phidot = jax.device_get(_rates(rep)(jnp.asarray(phi)))
    np.testing.assert_allclose(omega, B @ phidot, atol=1e-12)


def test_rate_matrix_singularities_and_margin():
    for rep, phi in (("rpy", [0.2, math.pi / 2, 0.3]), ("zyz", [0.2, 0.0, 0.3])):
        B = np.asarray(jk.rate_matrix(jnp.asarray(phi), rep))
        assert abs(np.linalg.det(B)) < 1e-15
        assert float(jk.representation_margin(jnp.asarray(phi), rep)) < 1e-15
    assert float(jk.representation_margin(jnp.array([0.0, 0.0, math.pi]), "rotvec")) == 0.5
    np.testing.assert_allclose(
        abs(np.linalg.det(np.asarray(jk.rate_matrix(jnp.array([0.1, 0.4, 0.2]), "rpy")))),
        math.cos(0.4),
        atol=1e-15,
    )


def _tip_phi(robot, Ts, rep):
    """``phi`` of the tip's rotation, read from ``Ts = jk.fk_all(robot, q)`` (numpy; the tip's
    row is ``jk.fk(robot, q)``): no second forward pass op by op."""
    return reps.from_matrix(Ts[robot.frame_index(None), :3, :3], rep)


@pytest.mark.parametrize("rep", reps.REPRESENTATIONS)
@given(robot_q=jkt.robots_and_configurations(1, 7))
def test_analytical_equals_blkdiag_Binv_geometric(rep, robot_q):
    robot, q = robot_q
    with jax.disable_jit():  # op by op: a robot used once compiles nothing of its own
        Ja, margin = jk.analytical_jacobian(robot, q, rep, return_margin=True)
        Jg = jk.geometric_jacobian(robot, q)
        Ja, margin, Jg, Ts = jax.device_get((Ja, margin, Jg, jk.fk_all(robot, q)))
        phi = jax.device_get(_tip_phi(robot, Ts, rep))
        # column by column: on padded columns its operations compile once, not once per size
        expected = padded(jk.analytical_from_geometric, Jg, phi, rep)
    margin = float(margin)
    if margin < 1e-3:
        return  # covered by the singularity tests below
    reach = max(1.0, float(np.max(np.linalg.norm(Ts[:, :3, 3] - Ts[:1, :3, 3], axis=1))))
    if rep == "rotvec" and np.linalg.norm(np.asarray(phi)) > math.pi - 1e-3:
        return  # branch cut at |w| = pi: phi jumps, its derivative is one-sided
    np.testing.assert_allclose(np.asarray(Ja), expected, rtol=0, atol=1e-12 * reach / margin**2)
    np.testing.assert_allclose(np.asarray(Ja[:3]), np.asarray(Jg[:3]), rtol=0, atol=1e-12 * reach)


def _pitching_arm():
    # one revolute joint about y: its rotation is Ry(q), so rpy pitch = q
    return jk.Robot.from_joints(
        [dict(name="j", type="revolute", child="tip", axis=(0, 1, 0), xyz=(0, 0, 0.5))],
        root="base",
    )


def test_representation_singularity_eager_raises():
    robot = _pitching_arm()
    with pytest.raises(jk.RepresentationSingularityError, match=r"pitch = \+-pi/2.*geometric"):
        jk.analytical_jacobian(robot, jnp.array([math.pi / 2]))
    planar = jk.robots.load("two_link_planar")
    with pytest.raises(jk.RepresentationSingularityError, match="theta = 0 or pi"):
        jk.analytical_jacobian(planar, jnp.array([0.3, 0.2]), "zyz")
    # away from it, fine; the user may lower the tolerance explicitly
    assert np.all(np.isfinite(np.asarray(jk.analytical_jacobian(robot, jnp.array([0.3])))))


def test_representation_singularity_under_vmap_is_flagged_never_silent():
    robot = _pitching_arm()
    qs = jnp.array([[0.3], [math.pi / 2], [math.pi / 2 - 1e-12], [-1.0]])

    def both(qs):  # masked and unmasked in one program (op by op: ~90 primitives compiled)
        Ja = jax.vmap(lambda q: jk.analytical_jacobian(robot, q))(qs)
        return Ja, jax.vmap(lambda q: jk.analytical_jacobian(robot, q, return_margin=True))(qs)

    Ja, (Ja2, margin) = jax.jit(both, compiler_options=FAST_COMPILE)(qs)
    finite = np.all(np.isfinite(np.asarray(Ja)), axis=(1, 2))
    np.testing.assert_array_equal(finite, [True, False, False, True])
    np.testing.assert_allclose(np.asarray(margin), np.abs(np.cos(np.asarray(qs[:, 0]))), atol=1e-15)
    np.testing.assert_allclose(np.asarray(Ja2)[[0, 3]], np.asarray(Ja)[[0, 3]], atol=0)


@op_by_op  # plain functions op by op: primitives the properties above already compiled
def test_representation_round_trips():
    R = spatial.rpy_to_matrix(jnp.array([0.3, -0.2, 1.0]))
    for rep in reps.REPRESENTATIONS:
        phi = reps.from_matrix(R, rep)
        np.testing.assert_allclose(np.asarray(reps.to_matrix(phi, rep)), np.asarray(R), atol=1e-14)
    with pytest.raises(jk.ShapeError, match=r"shape \(3, 3\)"):
        reps.from_matrix(jnp.eye(4), "rpy")
    with pytest.raises(jk.ShapeError, match=r"\(6, dof\)"):
        jk.analytical_from_geometric(jnp.zeros((3, 2)), jnp.zeros(3))


@pytest.mark.parametrize("rep", reps.REPRESENTATIONS)
@given(robot_q=jkt.robots_and_configurations(1, 7))
def test_analytical_chain_method_equals_full_jacfwd(rep, robot_q):
    """The default method (hand-built dR/dq chained with jacfwd of the representation map) and
    jax.jacfwd through all of forward kinematics agree."""
    robot, q = robot_q
    point = [0.1, -0.2, 0.3]
    with jax.disable_jit():  # op by op: a robot used once compiles nothing of its own
        Ja, margin = jk.analytical_jacobian(robot, q, rep, point=point, return_margin=True)
        Jf, _ = jk.analytical_jacobian(
            robot, q, rep, point=point, method="jacfwd", return_margin=True
        )
        Ja, margin, Jf, Ts = jax.device_get((Ja, margin, Jf, jk.fk_all(robot, q)))
        # only rotvec's branch cut needs phi itself
        phi = jax.device_get(_tip_phi(robot, Ts, rep)) if rep == "rotvec" else None
    margin = float(margin)
    if margin < 1e-3 or (rep == "rotvec" and np.linalg.norm(phi) > math.pi - 1e-3):
        return
    reach = max(1.0, float(np.max(np.linalg.norm(Ts[:, :3, 3] - Ts[:1, :3, 3], axis=1))))
    np.testing.assert_allclose(
        np.asarray(Ja), np.asarray(Jf), rtol=0, atol=1e-12 * reach / margin**2
    )
    with pytest.raises(jk.JaxkinError, match="method must be"):
        jk.analytical_jacobian(robot, q, rep, method="numeric")
