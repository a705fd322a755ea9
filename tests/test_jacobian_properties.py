"""The Jacobian triangle and reference identities as properties over random robots.

Random DH robots (1 to 12 joints, revolute and prismatic, both conventions, random base and tool)
and random URDF-style trees (arbitrary axes, fixed joints, branches): hand-built (Table 4.1) ==
jax.jacfwd == jax.jacrev (1e-12) == central finite differences on SE(3) (1e-7), for every
reference and for any frame and point.
"""

import jax
import jax.numpy as jnp
import numpy as np
from _padded import padded
from _xla import op_by_op
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk
import jaxkin.testing as jkt
from jaxkin import spatial


def _reach(robot, q):
    Ts = np.asarray(jk.fk_all(robot, q))  # the arithmetic on the host: no op compiled per size
    return max(1.0, float(np.max(np.linalg.norm(Ts[:, :3, 3] - Ts[:1, :3, 3], axis=1))))


@settings(max_examples=5)  # up to 12 joints: each example compiles a large program
@given(jkt.robots_and_configurations(1, 12, kind="dh"))  # compiled: op by op costs more here
def test_triangle_dh(robot_q):
    robot, q = robot_q
    jkt.assert_jacobian_consistent(robot, q)


@given(jkt.robots_and_configurations(1, 8, kind="tree"), st.data())
@op_by_op
def test_triangle_tree_any_frame_and_point(robot_q, data):
    robot, q = robot_q
    frame = data.draw(st.sampled_from(robot.frame_names))
    point = data.draw(st.one_of(st.none(), st.tuples(*[st.floats(-0.5, 0.5)] * 3)))
    jkt.assert_jacobian_consistent(robot, q, frame=frame, point=point)


@given(jkt.robots_and_configurations(1, 10), st.data())
@op_by_op
def test_reference_identities(robot_q, data):
    robot, q = robot_q
    frame = data.draw(st.sampled_from(robot.frame_names))
    T = np.asarray(jk.fk(robot, q, frame=frame))
    R = T[:3, :3]
    Jwa = np.asarray(jk.geometric_jacobian(robot, q, frame=frame))
    Jl = np.asarray(jk.geometric_jacobian(robot, q, frame=frame, reference="local"))
    Jw = np.asarray(jk.geometric_jacobian(robot, q, frame=frame, reference="world"))
    tol = 1e-12 * _reach(robot, q)
    blk = np.block([[R.T, np.zeros((3, 3))], [np.zeros((3, 3)), R.T]])
    np.testing.assert_allclose(Jl, blk @ Jwa, rtol=0, atol=tol)
    np.testing.assert_allclose(Jw, np.asarray(spatial.adjoint(T)) @ Jl, rtol=0, atol=tol)
    np.testing.assert_allclose(
        Jw[:3], Jwa[:3] + np.asarray(spatial.skew(T[:3, 3])) @ Jwa[3:], rtol=0, atol=tol
    )
    # change_reference maps every reference to every other (column by column: on padded
    # columns, its operations compile once for every robot up to 8 joints, not once per size)
    for a, Ja in (("world_aligned", Jwa), ("local", Jl), ("world", Jw)):
        for b, Jb in (("world_aligned", Jwa), ("local", Jl), ("world", Jw)):
            np.testing.assert_allclose(
                padded(jk.change_reference, Ja, T, a, b), Jb, rtol=0, atol=10 * tol
            )


@given(jkt.robots_and_configurations(1, 10), st.data())
@op_by_op
def test_twist_equals_J_qd_equals_jvp_of_fk(robot_q, data):
    robot, q = robot_q
    qd = data.draw(jkt.configurations(robot))
    frame = data.draw(st.sampled_from(robot.frame_names))
    V = np.asarray(jk.twist(robot, q, qd, frame=frame))
    J = np.asarray(jk.geometric_jacobian(robot, q, frame=frame))
    tol = 1e-12 * _reach(robot, q) * max(1.0, float(np.abs(qd).sum()))
    np.testing.assert_allclose(V, J @ qd, rtol=0, atol=tol)
    # independent path: the time derivative of the pose along q(t) = q + t qd, by jax.jvp
    T, Tdot = jax.jvp(
        lambda qq: jk.fk(robot, qq, frame=frame), (jnp.asarray(q),), (jnp.asarray(qd),)
    )
    T, Tdot = np.asarray(T), np.asarray(Tdot)
    v = Tdot[:3, 3]
    w = np.asarray(spatial.vee(Tdot[:3, :3] @ T[:3, :3].T))
    np.testing.assert_allclose(V, np.concatenate([v, w]), rtol=0, atol=tol)
    # local and world twists are the same motion seen differently
    Vl = np.asarray(jk.twist(robot, q, qd, frame=frame, reference="local"))
    np.testing.assert_allclose(Vl, np.concatenate([T[:3, :3].T @ v, T[:3, :3].T @ w]), atol=tol)


@given(jkt.robots_and_configurations(1, 8), st.data())
@op_by_op
def test_point_velocity_is_rigid_body_transport(robot_q, data):
    robot, q = robot_q
    qd = data.draw(jkt.configurations(robot))
    r = np.array(data.draw(st.tuples(*[st.floats(-0.5, 0.5)] * 3)))
    V = np.asarray(jk.twist(robot, q, qd))
    R = np.asarray(jk.fk(robot, q))[:3, :3]
    vp = np.asarray(jk.point_velocity(robot, q, qd, r))
    tol = 1e-12 * _reach(robot, q) * max(1.0, float(np.abs(qd).sum()))
    np.testing.assert_allclose(vp, V[:3] + np.cross(V[3:], R @ r), rtol=0, atol=tol)


def test_joint_not_on_path_gives_zero_column():
    robot = jk.Robot.from_joints(
        [
            dict(name="a", type="revolute", parent="root", child="A", axis=(0, 0, 1)),
            dict(
                name="b", type="revolute", parent="root", child="B", xyz=(1, 0, 0), axis=(0, 1, 0)
            ),
            dict(name="c", type="prismatic", parent="A", child="C", xyz=(0, 1, 0), axis=(1, 0, 0)),
        ],
        root="root",
    )
    q = jnp.array([0.3, -0.2, 0.1])
    J_C = np.asarray(jk.geometric_jacobian(robot, q, frame="C"))
    J_B = np.asarray(jk.geometric_jacobian(robot, q, frame="B"))
    assert np.all(J_C[:, 1] == 0.0)  # joint b is on another branch
    assert np.all(J_B[:, [0, 2]] == 0.0)
    assert np.any(J_C[:, 0] != 0.0) and np.any(J_C[:, 2] != 0.0)
