"""Robots with no moving joint (dof 0) load and compute: poses against Pinocchio, Jacobians of
shape (6, 0), J-dot (6, 0), Hessian (0, 6, 0), eager, under jit and vmap, float64 and float32;
the command line says there is nothing to move. (MJCF with no joint: tests/test_mjcf.py.)"""

from __future__ import annotations

import jax
import numpy as np
import pinocchio as pin
import pytest

import jaxkin as jk
from jaxkin.cli import main
from jaxkin.robots import example_robot_data as erd

ZERO_DOF = ["erd/quadrotor_base", "erd/iris_simple"]


@pytest.mark.parametrize("name", ZERO_DOF)
def test_zero_dof_erd_poses_match_pinocchio(name):
    robot = jk.robots.load(name, dtype=np.float64)
    assert robot.dof == 0 and robot.joint_names == () and robot.lower.shape == (0,)
    model = pin.buildModelFromXML(erd.path(name).read_text())
    assert model.nq == 0 and model.nv == 0
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.zeros(0))
    bodies = {f.name: i for i, f in enumerate(model.frames) if f.type == pin.BODY}
    assert set(robot.frame_names) == set(bodies)
    Ts = np.asarray(jk.fk_all(robot, np.zeros(0)))
    for k, frame in enumerate(robot.frame_names):
        np.testing.assert_allclose(
            Ts[k], data.oMf[bodies[frame]].homogeneous, rtol=0, atol=1e-12, err_msg=frame
        )
        np.testing.assert_array_equal(np.asarray(jk.fk(robot, [], frame=frame)), Ts[k])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_zero_dof_shapes_eager_jit_vmap(dtype):
    robot = jk.robots.load("erd/iris_simple", dtype=dtype)
    q = np.zeros(0, dtype)
    frame = robot.frame_names[-1]
    for reference in ("world_aligned", "local", "world"):
        J = jk.geometric_jacobian(robot, q, frame=frame, reference=reference)
        assert J.shape == (6, 0) and J.dtype == dtype
    if dtype == np.float32:  # the float32 subset: the rest compiles the same code again
        return
    assert jk.geometric_jacobian(robot, q, point=[0.1, 0.2, 0.3]).shape == (6, 0)
    assert jk.analytical_jacobian(robot, q).shape == (6, 0)
    assert jk.jacobian_fwd(robot, q).shape == (6, 0)
    assert jk.jacobian_dot(robot, q, q).shape == (6, 0)
    assert jk.kinematic_hessian(robot, q).shape == (0, 6, 0)
    np.testing.assert_array_equal(np.asarray(jk.twist(robot, q, q)), np.zeros(6))
    T = jk.fk(robot, q)
    assert np.array_equal(np.asarray(jax.jit(jk.fk)(robot, q)), np.asarray(T))
    assert jax.jit(jk.geometric_jacobian)(robot, q).shape == (6, 0)
    qs = np.zeros((3, 0), dtype)
    assert jax.vmap(lambda x: jk.geometric_jacobian(robot, x))(qs).shape == (3, 6, 0)
    Ts = jax.vmap(lambda x: jk.fk(robot, x))(qs)
    assert Ts.shape == (3, 4, 4) and np.array_equal(np.asarray(Ts[1]), np.asarray(T))


def test_robot_with_no_joint_at_all():
    """A URDF with one link, and ``from_joints([])``: only the root frame, at the identity."""
    for robot in (
        jk.load_urdf('<robot name="one"><link name="a"/></robot>', dtype=np.float64),
        jk.Robot.from_joints([], root="a", dtype=np.float64),
    ):
        assert robot.dof == 0 and robot.frame_names == ("a",)
        np.testing.assert_array_equal(np.asarray(jk.fk(robot, [])), np.eye(4))
        assert jk.geometric_jacobian(robot, []).shape == (6, 0)


def test_zero_dof_wrong_q_is_refused():
    robot = jk.robots.load("erd/quadrotor_base")
    with pytest.raises(jk.JaxkinError, match="0"):
        jk.fk(robot, [0.0])


@pytest.mark.parametrize("command", ["jacobian", "velocities"])
def test_cli_says_there_is_nothing_to_move(capsys, command):
    assert main([command, "erd/iris_simple"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert "no moving joint" in err and "nothing to move" in err and "erd/iris_simple" in err


def test_measures_of_a_zero_dof_jacobian():
    """A robot with no moving joint moves along no axis: every task-space singular value is 0,
    so manipulability 0, condition number inf, rank 0, near-singular for any threshold > 0; the
    null-space analysis refuses it (there are no columns to name)."""
    robot = jk.robots.load("erd/quadrotor_base")
    J = jk.geometric_jacobian(robot, np.zeros(0))
    for measure in jk.analysis.MEASURES:
        for rows in ("all", "translation", [0, 5]):
            assert float(jk.manipulability(J, measure, rows)) == 0.0
    assert float(jk.condition_number(J)) == np.inf
    assert int(jk.analysis.rank(J)) == 0
    assert jk.singular_values(J).shape == (0,)
    assert bool(jk.near_singular(J, 1e-6))
    np.testing.assert_array_equal(np.asarray(jk.analysis.velocity_ellipsoid(J).radii), 0.0)
    assert float(jax.jit(jk.manipulability)(J)) == 0.0
    assert np.all(np.isfinite(np.asarray(jax.grad(jk.manipulability)(J))))
    with pytest.raises(jk.ShapeError, match=r"\(6, 0\)"):
        jk.analysis.dependent_columns(J)
