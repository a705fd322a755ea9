"""The chapter's worked answers, with their closed forms written out here as the oracle.

Closed forms are derived by hand from Spong's DH tables (positions) and, for practice question 2,
also checked symbolically with SymPy. Dimensions are drawn at random: the formulas hold for any.

Cost: the properties draw a new robot per example (new dimensions, the same structure). Their
jaxkin calls (example 4.1.1, practice questions 1, 2 and 4, Eq. 4.3) run in one ``jax.jit``
kernel per property that takes the robot as a traced argument: compiled once for every example
(jaxkin's eager calls close over the robot and compile once per example and function: 1.6-3.5x
the CPU time).
"""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE
from hypothesis import given
from hypothesis import strategies as st

import jaxkin as jk
from jaxkin import spatial

angle = st.floats(-math.pi, math.pi, allow_nan=False, allow_subnormal=False)
length = st.floats(0.05, 2.0, allow_nan=False)
extension = st.floats(0.0, 1.0, allow_nan=False)
rate = st.floats(-2.0, 2.0, allow_nan=False, allow_subnormal=False)
ATOL = 1e-12


# --- Example 4.1.1: three-link cylindrical robot --------------------------------------------
@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _pose_rpy_jacobian_and_twist(robot, q, qd):
    return jk.fk(robot, q), jk.analytical_jacobian(robot, q, "rpy"), jk.twist(robot, q, qd)


@given(length, angle, extension, extension, rate, rate, rate)
def test_example_4_1_1_cylindrical(d1, t1, d2, d3, w1, v2, v3):
    robot = jk.robots.load("cylindrical", d1=d1)
    q = jnp.array([t1, d2, d3])
    c1, s1 = math.cos(t1), math.sin(t1)
    # T_3^0 (Spong Example 3.2)
    T_expected = np.array(
        [[c1, 0, -s1, -s1 * d3], [s1, 0, c1, c1 * d3], [0, -1, 0, d1 + d2], [0, 0, 0, 1]]
    )
    qd = np.array([w1, v2, v3])
    T, Ja, V = (np.asarray(x) for x in _pose_rpy_jacobian_and_twist(robot, q, jnp.asarray(qd)))
    np.testing.assert_allclose(T, T_expected, atol=ATOL)
    # analytical Jacobian of x = (-s1 d3, c1 d3, d1 + d2) w.r.t. (theta1, d2, d3); orientation
    # in rpy is (-pi/2, 0, theta1), so only d(yaw)/d(theta1) = 1.
    Ja_expected = np.array(
        [
            [-c1 * d3, 0, -s1],
            [-s1 * d3, 0, c1],
            [0, 1, 0],
            [0, 0, 0],
            [0, 0, 0],
            [1, 0, 0],
        ]
    )
    np.testing.assert_allclose(Ja, Ja_expected, atol=ATOL)
    # end-effector velocity (Eq. 4.2): xdot = J_a qdot
    xdot = np.array([-c1 * d3 * w1 - s1 * v3, -s1 * d3 * w1 + c1 * v3, v2])
    np.testing.assert_allclose(Ja[:3] @ qd, xdot, atol=ATOL)
    np.testing.assert_allclose(V[:3], xdot, atol=ATOL)
    # geometric angular rows: omega = theta1_dot z0
    np.testing.assert_allclose(V[3:], [0, 0, w1], atol=ATOL)


# --- Practice question 1: two-link planar arm --------------------------------------------------
@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _pose_rpy_and_geometric_jacobians(robot, q):
    return jk.fk(robot, q), jk.analytical_jacobian(robot, q, "rpy"), jk.geometric_jacobian(robot, q)


@given(length, length, angle, angle)
def test_practice_question_1_two_link_planar(a1, a2, t1, t2):
    robot = jk.robots.load("two_link_planar", a1=a1, a2=a2)
    q = jnp.array([t1, t2])
    T, Ja, Jg = (np.asarray(x) for x in _pose_rpy_and_geometric_jacobians(robot, q))
    c1, s1 = math.cos(t1), math.sin(t1)
    c12, s12 = math.cos(t1 + t2), math.sin(t1 + t2)
    p = T[:3, 3]
    np.testing.assert_allclose(p, [a1 * c1 + a2 * c12, a1 * s1 + a2 * s12, 0.0], atol=ATOL)
    J_expected = np.array(
        [[-a1 * s1 - a2 * s12, -a2 * s12], [a1 * c1 + a2 * c12, a2 * c12], [0, 0]]
    )
    np.testing.assert_allclose(Ja[:3], J_expected, atol=ATOL)
    np.testing.assert_allclose(Ja[3:], [[0, 0], [0, 0], [1, 1]], atol=ATOL)  # yaw = t1 + t2
    np.testing.assert_allclose(Jg[:3], J_expected, atol=ATOL)
    np.testing.assert_allclose(Jg[3:], [[0, 0], [0, 0], [1, 1]], atol=ATOL)


# --- Practice question 2: cylindrical arm with spherical wrist -------------------------------
def _pq2_position(t1, d2, d3, t4, t5, d1, d6, c=math.cos, s=math.sin):
    """o_6 = o_3 + R_3^0 d6 (c4 s5, s4 s5, c5), derived by hand from Spong's tables 3.2, 3.3."""
    c1, s1, c4, s4, c5, s5 = c(t1), s(t1), c(t4), s(t4), c(t5), s(t5)
    return (
        c1 * c4 * s5 * d6 - s1 * c5 * d6 - s1 * d3,
        s1 * c4 * s5 * d6 + c1 * c5 * d6 + c1 * d3,
        -s4 * s5 * d6 + d1 + d2,
    )


def _pq2_jacobian(t1, d2, d3, t4, t5, d1, d6):
    """The chapter's answer, written out: d(x, y, z) / d(t1, d2, d3, t4, t5, t6)."""
    c1, s1, c4, s4 = math.cos(t1), math.sin(t1), math.cos(t4), math.sin(t4)
    c5, s5 = math.cos(t5), math.sin(t5)
    return np.array(
        [
            [
                -s1 * c4 * s5 * d6 - c1 * c5 * d6 - c1 * d3,
                0,
                -s1,
                -c1 * s4 * s5 * d6,
                c1 * c4 * c5 * d6 + s1 * s5 * d6,
                0,
            ],
            [
                c1 * c4 * s5 * d6 - s1 * c5 * d6 - s1 * d3,
                0,
                c1,
                -s1 * s4 * s5 * d6,
                s1 * c4 * c5 * d6 - c1 * s5 * d6,
                0,
            ],
            [0, 1, 0, -c4 * s5 * d6, -s4 * c5 * d6, 0],
        ]
    )


def test_practice_question_2_closed_form_matches_sympy():
    import sympy as sp  # here, not at module level: each xdist worker imports every test module

    syms = sp.symbols("t1 d2 d3 t4 t5 t6 d1 d6")
    t1, d2, d3, t4, t5, t6, d1, d6 = syms
    pos = sp.Matrix(_pq2_position(t1, d2, d3, t4, t5, d1, d6, c=sp.cos, s=sp.sin))
    J_sym = pos.jacobian([t1, d2, d3, t4, t5, t6])
    f = sp.lambdify(syms, J_sym, "numpy")
    rng = np.random.default_rng(2)
    for _ in range(20):
        vals = rng.uniform(-2, 2, size=8)
        np.testing.assert_allclose(
            np.asarray(f(*vals), dtype=float),
            _pq2_jacobian(*vals[[0, 1, 2, 3, 4]], vals[6], vals[7]),
            atol=1e-13,
        )


@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _pose_and_geometric_jacobian(robot, q):
    return jk.fk(robot, q), jk.geometric_jacobian(robot, q)


@given(length, length, angle, extension, extension, angle, angle, angle)
def test_practice_question_2_cylindrical_spherical_wrist(d1, d6, t1, d2, d3, t4, t5, t6):
    robot = jk.robots.load("cylindrical_spherical_wrist", d1=d1, d6=d6)
    assert robot.joint_kinds == ("revolute", "prismatic", "prismatic") + ("revolute",) * 3
    q = jnp.array([t1, d2, d3, t4, t5, t6])
    T, Jg = (np.asarray(x) for x in _pose_and_geometric_jacobian(robot, q))
    p = T[:3, 3]
    np.testing.assert_allclose(p, _pq2_position(t1, d2, d3, t4, t5, d1, d6), atol=ATOL)
    np.testing.assert_allclose(Jg[:3], _pq2_jacobian(t1, d2, d3, t4, t5, d1, d6), atol=ATOL)
    # Table 4.1: prismatic columns have zero angular part
    np.testing.assert_array_equal(Jg[3:, 1:3], np.zeros((3, 2)))


# --- Practice question 4: revolute-prismatic arm (Table 4.1) -----------------------------------
@given(st.floats(0.0, 1.0), angle, extension)
def test_practice_question_4_rp_arm(d1, t1, d2):
    robot = jk.robots.load("rp_arm", d1=d1)
    q = jnp.array([t1, d2])
    c1, s1 = math.cos(t1), math.sin(t1)
    # z0 = (0, 0, 1), o0 = 0; z1 = (s1, -c1, 0); o2 = (s1 d2, -c1 d2, d1).
    # Column 1 (revolute): [z0 x (o2 - o0); z0]; column 2 (prismatic): [z1; 0].
    J_expected = np.array([[c1 * d2, s1], [s1 * d2, -c1], [0, 0], [0, 0], [0, 0], [1, 0]])
    T, J = (np.asarray(x) for x in _pose_and_geometric_jacobian(robot, q))
    np.testing.assert_allclose(J, J_expected, atol=ATOL)
    np.testing.assert_allclose(T[:3, 3], [s1 * d2, -c1 * d2, d1], atol=ATOL)


# --- Section 4.2 and practice question 3: kinds of rigid-body motion ----------------------------
def _poses(fn, ts):
    return np.stack([np.asarray(spatial.make_transform(*fn(t))) for t in ts])


def test_practice_question_3_classification():
    ts = np.linspace(0.0, 1.5, 12)
    # (a) a body spinning about its centre, which stays put: pure rotation
    spin = _poses(lambda t: (spatial.rot_z(2 * t), jnp.array([0.3, -0.2, 0.1])), ts)
    assert jk.classify_motion(spin) == "pure_rotation"
    # ... also about a point away from the body origin (the arcs' common centre)
    c = np.array([1.0, 0.5, 0.0])
    orbit = _poses(
        lambda t: (spatial.rot_z(t), jnp.asarray(c - np.asarray(spatial.rot_z(t)) @ c)), ts
    )
    assert jk.classify_motion(orbit) == "pure_rotation"
    # (b) a wheel of radius r rolling along x: rotates and translates
    r = 0.4
    wheel = _poses(lambda t: (spatial.rot_y(t), jnp.array([r * t, 0.0, r])), ts)
    assert jk.classify_motion(wheel) == "general"
    # (c) a Ferris-wheel cabin: moves on a circle, never turns: pure translation
    L = 10.0
    cabin = _poses(lambda t: (jnp.eye(3), jnp.array([L * np.cos(t), 0.0, L * np.sin(t)])), ts)
    assert jk.classify_motion(cabin) == "pure_translation"
    assert jk.classify_motion(np.stack([np.eye(4)] * 3)) == "rest"


def test_instantaneous_twist_classification():
    # the rolling wheel's twist at its centre: v = (r w, 0, 0), omega = (0, w, 0); v . omega = 0,
    # so at each instant it is a pure rotation about the contact point (which is at rest)
    r, w = 0.4, 1.3
    V = np.array([r * w, 0, 0, 0, w, 0])
    assert jk.classify_twist(V) == "pure_rotation"
    contact = np.array([0.0, 0.0, -r])  # from the centre
    np.testing.assert_allclose(V[:3] + np.cross(V[3:], contact), 0.0, atol=1e-15)
    assert jk.classify_twist(np.array([1.0, 2, 0, 0, 0, 0])) == "pure_translation"
    assert jk.classify_twist(np.array([0.0, 0, 1, 0, 0, 2])) == "general"  # screw
    assert jk.classify_twist(np.zeros(6)) == "rest"


@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _link1_twist_and_pose(robot, q, qd):
    return jk.twist(robot, q, qd, frame="link1"), jk.fk(robot, q, frame="link1")


@given(angle, rate, length)
def test_eq_4_3_tangential_velocity_is_omega_cross_r(t1, w1, a1):
    """A point on a revolute link moves with v = omega x r (Eq. 4.3), |v| = |omega| |r|."""
    robot = jk.robots.load("two_link_planar", a1=a1, a2=0.5)
    q = jnp.array([t1, 0.0])
    V, T = (np.asarray(x) for x in _link1_twist_and_pose(robot, q, jnp.array([w1, 0.0])))
    r = T[:3, 3]
    np.testing.assert_allclose(V[:3], np.cross(V[3:], r), atol=ATOL)
    assert abs(np.linalg.norm(V[:3]) - abs(w1) * a1) < 1e-12


def test_zoo_chapter_robots_use_the_textbook_dh_tables():
    r = jk.robots.load("cylindrical_spherical_wrist", d1=0.7, d6=0.2)
    np.testing.assert_allclose(
        np.asarray(r.params["alpha"]), [0, -np.pi / 2, 0, -np.pi / 2, np.pi / 2, 0]
    )
    np.testing.assert_allclose(np.asarray(r.params["d"]), [0.7, 0, 0, 0, 0, 0.2])
    with pytest.raises(jk.JaxkinError, match="d6"):
        jk.robots.load("cylindrical", d6=1.0)


def test_jvp_of_forward_kinematics_is_the_velocity():
    """Eq. 4.21 read literally: the twist is the time derivative of the pose along q(t)."""
    robot = jk.robots.load("cylindrical_spherical_wrist")
    q = jnp.array([0.3, 0.4, 0.5, 0.2, 0.7, -0.4])
    qd = jnp.array([0.1, -0.2, 0.3, 0.4, -0.5, 0.6])
    T, Tdot = jax.jvp(lambda qq: jk.fk(robot, qq), (q,), (qd,))
    V = np.asarray(jk.twist(robot, q, qd))
    np.testing.assert_allclose(V[:3], np.asarray(Tdot[:3, 3]), atol=ATOL)
    np.testing.assert_allclose(
        V[3:], np.asarray(spatial.vee(Tdot[:3, :3] @ T[:3, :3].T)), atol=ATOL
    )
