"""jaxkin.testing used the way its users use it: property tests of their own robots with the
public strategies and the invariant check. This file doubles as the documented example."""

import math

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk
import jaxkin.testing as jkt

NIRYO = jk.robots.load("niryo_one")
PLANAR = jk.robots.load("two_link_planar", a1=1.0, a2=0.6)


# ---------------------------------------------------------------------- the example a user copies
@settings(max_examples=5)
@given(jkt.dh_robots(kinds="RRPRRR", convention="standard"), st.data())
def test_example_my_property_on_random_robots(robot, data):
    """A user's property: hand-built, autodiff and finite-difference Jacobians agree."""
    q = data.draw(jkt.configurations(robot))
    assert robot.joint_kinds == ("revolute",) * 2 + ("prismatic",) + ("revolute",) * 3
    assert np.all(q >= np.asarray(robot.lower)) and np.all(q <= np.asarray(robot.upper))
    jkt.assert_jacobian_consistent(robot, q, references=("world_aligned",))


@settings(max_examples=8)
@given(jkt.near_singular_configurations(NIRYO))
def test_example_near_singular_configurations_of_my_robot(q):
    """A user's property at the hard places: the Jacobian has (nearly) lost rank there, and the
    hand-built one still matches autodiff."""
    J = np.asarray(jk.geometric_jacobian(NIRYO, q))
    s = np.linalg.svd(J, compute_uv=False)
    assert s[-1] <= 1e-6 * s[0]
    assert np.all(q >= np.asarray(NIRYO.lower)) and np.all(q <= np.asarray(NIRYO.upper))
    # which singularity: the wrist (q5 = 0) or the shoulder (wrist centre on the base axis)
    wrist_centre = np.asarray(jk.fk(NIRYO, q, frame="wrist_link"))[:3, 3]
    assert abs(math.sin(q[4])) < 1e-4 or np.hypot(*wrist_centre[:2]) < 1e-4
    J_ad = np.asarray(jk.jacobian_fwd(NIRYO, q))
    np.testing.assert_allclose(J, J_ad, rtol=0, atol=1e-12)


# ---------------------------------------------------------------------- the strategies' contracts
@settings(max_examples=15)
@given(jkt.near_singular_configurations(PLANAR, rows="translation", tol=1e-8))
def test_near_singular_two_link_arm_is_stretched_or_folded(q):
    # the planar arm's J_v is singular exactly when sin(q2) = 0 (Practice question 1:
    # det = a1 a2 s2); its full 6 x 2 J never is (the angular row wz = qd1 + qd2 keeps rank 2)
    assert abs(math.sin(q[1])) < 1e-7


def test_near_singular_arguments_are_checked():
    with pytest.raises(ValueError, match="tol"):
        jkt.near_singular_configurations(NIRYO, tol=0.0)
    with pytest.raises(jk.JaxkinError, match="no frame"):
        jkt.near_singular_configurations(NIRYO, frame="nosuch")
    with pytest.raises(ValueError, match="no joint moves"):
        jkt.near_singular_configurations(NIRYO, frame="base_link")
    with pytest.raises(ValueError, match="rows"):
        jkt.near_singular_configurations(NIRYO, rows="linear")


@settings(max_examples=10)
@given(jkt.dh_robots(min_joints=2, max_joints=4, prismatic=False))
def test_dh_robots_size_and_joint_mix(robot):
    assert 2 <= robot.dof <= 4 and set(robot.joint_kinds) == {"revolute"}


def test_kinds_must_be_r_and_p():
    with pytest.raises(ValueError, match="'R' and 'P'"):
        jkt.dh_robots(kinds="RXR")


@given(jkt.rotations(), jkt.unit_vectors())
def test_rotations_and_unit_vectors(R, u):
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert abs(np.linalg.det(R) - 1.0) < 1e-12
    assert abs(np.linalg.norm(u) - 1.0) < 1e-12
    np.testing.assert_allclose(np.linalg.norm(R @ u), 1.0, atol=1e-12)


def test_assert_jacobian_consistent_catches_a_wrong_jacobian(monkeypatch):
    """The invariant check fails loudly when the hand-built Jacobian is wrong (on the planar
    arm: the robot is not the point, and its four programs compile in a fraction of a Niryo's)."""
    import jaxkin.testing as module

    real = module.geometric_jacobian
    monkeypatch.setattr(module, "geometric_jacobian", lambda *a, **k: real(*a, **k) * 1.001)
    q = jnp.array([0.2, -0.5])
    with pytest.raises(AssertionError, match="hand-built vs jacfwd"):  # one reference shows it
        jkt.assert_jacobian_consistent(PLANAR, q, references=("world_aligned",))
