"""MJCF ``free`` and ``ball`` joints against MuJoCo: ``q == qpos``, body and site poses against
``mj_kinematics``, Jacobian columns against ``mj_jac`` (MuJoCo's free-joint ``qvel`` has its
linear part in world axes, jaxkin's velocity in the body's own: ``J_mujoco[:, :3] = J[:, :3]
R^T``), and ball-joint integration against ``mj_integratePos`` (the free joint's differs on
purpose: MuJoCo moves the position along the world velocity, jaxkin along SE(3)'s exponential,
as Pinocchio). One jitted ``vmap`` for all configurations.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE

import jaxkin as jk

mujoco = pytest.importorskip("mujoco")

XML = """<mujoco model="free_ball">
  <worldbody>
    <body name="torso" pos="0.1 0.2 1" quat="0.9 0.1 0.2 0.3">
      <freejoint name="root"/><geom size=".1"/>
      <body name="arm" pos="0.3 0 0" euler="10 20 30">
        <joint name="shoulder" type="ball" pos="0.05 0.02 0"/><geom size=".05"/>
        <body name="fore" pos="0.4 0 0">
          <joint name="elbow" axis="0 1 0" ref="0.3" range="-90 90"/><geom size=".05"/>
          <site name="hand" pos="0.3 0 0.1"/>
        </body>
      </body>
      <body name="leg" pos="0 0 -0.3" quat="0 1 0 0">
        <joint name="hip" type="ball"/><geom size=".05"/>
        <body name="shin" pos="0 0 0.4"><joint name="knee" type="slide" axis="0 0 1"/>
          <geom size=".05"/></body>
      </body>
    </body>
    <body name="crate" pos="2 0 0.5"><joint type="free"/><geom size=".2"/></body>
  </worldbody>
</mujoco>"""
N = 10
POINT = np.array([0.02, -0.03, 0.04])


@functools.cache
def case():
    robot = jk.load_mjcf(XML, dtype=np.float64)
    m = mujoco.MjModel.from_xml_string(XML)
    qs = np.asarray(jk.sample_configurations(robot, N, key=4))
    vs = np.random.default_rng(4).uniform(-1.0, 1.0, (N, robot.nv))
    frames = ["hand", "shin", "torso", "crate"]

    def one(q, v):
        out = {"Ts": jk.fk_all(robot, q), "q1": jk.integrate(robot, q, v, dt=0.1)}
        for f in frames:
            out[f] = jk.geometric_jacobian(robot, q, frame=f, point=POINT)
        return out

    f = jax.jit(jax.vmap(one), compiler_options=FAST_COMPILE)
    out = jax.tree_util.tree_map(np.asarray, f(qs, vs))
    return robot, m, qs, vs, frames, out


def test_layout_is_mujocos_qpos():
    robot, m, *_ = case()
    assert (robot.nq, robot.nv) == (m.nq, m.nv) == (24, 20)
    assert robot.kinds.count("free") == 2 and robot.kinds.count("ball") == 2
    assert robot.joint_names[7:11] == ("shoulder.qw", "shoulder.qx", "shoulder.qy", "shoulder.qz")
    np.testing.assert_array_equal(jk.neutral(robot)[:7], [0, 0, 0, 1, 0, 0, 0])


def test_poses_and_jacobians_match_mujoco():
    robot, m, qs, _, frames, out = case()
    d = mujoco.MjData(m)
    free = [(robot.q_index[j], robot.v_index[j]) for j in robot.multi_dof_joints]
    free = [
        (qi, vi)
        for (qi, vi), j in zip(free, robot.multi_dof_joints, strict=True)
        if robot.kinds[j] == "free"
    ]
    for k, q in enumerate(qs):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        Ts = out["Ts"][k]
        for b in range(1, m.nbody):
            T = Ts[robot.frame_names.index(m.body(b).name)]
            np.testing.assert_allclose(T[:3, 3], d.xpos[b], atol=1e-12)
            np.testing.assert_allclose(T[:3, :3], d.xmat[b].reshape(3, 3), atol=1e-12)
        for f in frames:
            T = Ts[robot.frame_names.index(f)]
            J = out[f][k].copy()
            for qi, vi in free:  # jaxkin: body-axes linear velocity; MuJoCo: world axes
                R = np.asarray(jk.spatial.quaternion_to_matrix_np(q[qi + 3 : qi + 7]))
                J[:, vi : vi + 3] = J[:, vi : vi + 3] @ R.T
            jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
            body = m.site_bodyid[0] if f == "hand" else m.body(f).id
            mujoco.mj_jac(m, d, jacp, jacr, T[:3, :3] @ POINT + T[:3, 3], body)
            np.testing.assert_allclose(J[:3], jacp, atol=1e-12, err_msg=f)
            np.testing.assert_allclose(J[3:], jacr, atol=1e-12, err_msg=f)


def test_ball_joint_integration_matches_mujoco():
    robot, m, qs, vs, _, out = case()
    balls = [j for j in robot.multi_dof_joints if robot.kinds[j] == "ball"]
    for k, (q, v) in enumerate(zip(qs, vs, strict=True)):
        qpos = q.copy()
        mujoco.mj_integratePos(m, qpos, v, 0.1)  # ball qvel: body-axes angular velocity
        for j in balls:
            s = slice(robot.q_index[j], robot.q_index[j] + 4)
            a, b = out["q1"][k][s], qpos[s]
            np.testing.assert_allclose(a * np.sign(a @ b), b, atol=1e-12)


def test_eager_calls_and_zero_quaternion_refusal():
    robot, _, qs, *_ = case()
    np.testing.assert_allclose(
        jk.fk(robot, jnp.asarray(qs[0]), frame="hand"),
        case()[5]["Ts"][0][robot.frame_names.index("hand")],
        atol=1e-14,
    )
    bad = qs[0].copy()
    bad[-4:] = 0.0  # the crate's quaternion
    with pytest.raises(jk.JaxkinError, match="free joint"):
        jk.fk(robot, bad)
