"""Careless calls (issue 21) answered clearly: scaled quaternions, ``integrate``'s ``dt``,
robots pickled and copied, ``robot.replace`` with wrong shapes and ``solve_ik``'s ``lanes``
(the solutions an :class:`~jaxkin.IKError` keeps: tests/test_ik_defaults.py, which has the
batch compiled).

Small robots only: each test compiles at most a handful of tiny kernels.
"""

from __future__ import annotations

import copy
import pathlib
import pickle
import re
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sampling import random_q
from _xla import FAST_COMPILE

import jaxkin as jk

DATA = pathlib.Path(__file__).parent / "data"

FLOATING = jk.Robot.from_joints(
    [
        dict(name="root", type="free", child="body", xyz=[0.1, 0.0, 0.5]),
        dict(name="neck", type="ball", child="head", xyz=[0.0, 0.0, 0.3], rpy=[0.2, 0.0, 0.1]),
        dict(
            name="arm", type="revolute", parent="body", child="arm", xyz=[0.2, 0, 0], axis=[0, 1, 0]
        ),
        dict(name="cart", type="planar", child="cart", xyz=[0.3, 0, 0], rpy=[0.5, 0.4, 0.3]),
        dict(name="hand", type="fixed", parent="arm", child="hand", xyz=[0.1, 0.2, 0.0]),
    ],
    name="careless_floating",
    dtype=np.float64,
    default_frames=["hand"],
)


def re_escape(x) -> str:
    return re.escape(str(x))


# where the free joint's, the ball joint's quaternion and the planar (cos, sin) sit in q
ROTATIONS = (slice(3, 7), slice(7, 11), slice(14, 16))


# ----------------------------------------------------------------------------- quaternions
@pytest.mark.parametrize(
    "dtype, scales",
    [(np.float64, (1e200, 1e-200, 1e150)), (np.float32, (1e20, 1e-20, 1e30))],
)
def test_scaled_quaternions_give_the_unit_ones_pose(dtype, scales):
    """Before: a quaternion scaled by 1e200 (1e20 in float32) overflowed its squared norm and
    gave a finite pose off by about 1.9; 1e-200 underflowed it to NaN."""
    robot = FLOATING.astype(dtype)
    q = random_q(robot, 1, seed=4).astype(dtype)[0]  # numpy: the sampler is not under test
    qs = np.tile(q, (1 + len(scales), 1))
    for i, s in enumerate(scales, 1):
        for part in ROTATIONS:
            qs[i, part] = q[part] * dtype(s)
    assert np.all(np.isfinite(qs)) and len(np.unique(qs[:, 3])) == len(qs)
    v = np.linspace(-0.3, 0.3, robot.nv).astype(dtype)

    def outputs(q):
        return jk.fk_all(robot, q), jk.geometric_jacobian(robot, q), jk.integrate(robot, q, v)

    out = jax.jit(jax.vmap(outputs), compiler_options=FAST_COMPILE)(qs)
    tol = 1e-12 if dtype == np.float64 else 2e-6
    for x in out:
        for i in range(1, len(qs)):
            np.testing.assert_allclose(x[i], x[0], atol=tol, err_msg=str(scales[i - 1]))
    # the eager path (its own compiled executable) too
    np.testing.assert_allclose(jk.fk(robot, qs[1]), out[0][0, robot.tip_frame], atol=tol)


def test_quaternions_too_small_to_normalise_are_refused_eagerly_and_nan_under_jit():
    q = np.array(jk.neutral(FLOATING))
    q[7:11] = 1e-310  # subnormal: flushed to zero by XLA, no rotation left
    with pytest.raises(jk.JaxkinError, match=r"ball joint 'neck'.*too small to normalise"):
        jk.fk(FLOATING, q)
    head = jax.jit(lambda q: jk.fk(FLOATING, q, frame="head"), compiler_options=FAST_COMPILE)(q)
    assert np.all(np.isnan(np.asarray(head)[:3, :3]))


# ----------------------------------------------------------------------------- integrate's dt
@pytest.mark.parametrize("dt, shape", [([0.1, 0.2], (2,)), (np.ones((3, 1)), (3, 1))])
def test_integrate_names_dt_and_its_shape(dt, shape):
    q, v = jk.neutral(FLOATING), np.zeros(FLOATING.nv)
    wanted = rf"dt must be one number.*got shape {re_escape(shape)}"
    with pytest.raises(jk.ShapeError, match=wanted):
        jk.integrate(FLOATING, q, v, dt=dt)
    arm = jk.robots.load("two_link_planar")  # the vector-space path too
    with pytest.raises(jk.ShapeError, match=r"jk\.integrate: dt"):
        jk.integrate(arm, np.zeros(2), np.zeros(2), dt=dt)
    with pytest.raises(jk.ShapeError, match="dt must be one number"):
        jk.integrate(arm, np.zeros(2), np.zeros(2), dt="abc")
    assert jk.integrate(arm, np.zeros(2), np.ones(2), dt=np.float64(0.5)).tolist() == [0.5, 0.5]


# ----------------------------------------------------------------------------- pickling
def _robots():
    return {
        "dh": jk.robots.load("puma560", dtype=np.float64),
        "mimic": jk.load_urdf(DATA / "tree_mimic.urdf", dtype=np.float64),
        "floating": FLOATING,
        "float32": jk.robots.load("two_link_planar", dtype=np.float32),
    }


@pytest.mark.parametrize("kind", ["dh", "mimic", "floating", "float32"])
def test_robots_pickle_copy_and_deepcopy_to_equal_robots(kind):
    robot = _robots()[kind]
    hash(robot)  # a cached hash is not carried over
    copies = [pickle.loads(pickle.dumps(robot, protocol=p)) for p in range(6)]
    copies += [copy.copy(robot), copy.deepcopy(robot), pickle.loads(pickle.dumps(robot.params))]
    q = np.asarray(jk.neutral(robot))
    frame = robot.frame_names[-1]
    for c in copies[:-1]:
        assert c == robot and hash(c) == hash(robot) and repr(c) == repr(robot)
        assert c.dtype == robot.dtype and c.default_frames == robot.default_frames
        np.testing.assert_array_equal(jk.fk(c, q, frame=frame), jk.fk(robot, q, frame=frame))
        with pytest.raises(AttributeError):
            c.offset = c.offset + 1
        with pytest.raises(AttributeError):
            c.params.extra = 1
    assert dict(copies[-1]).keys() == dict(robot.params).keys()
    with pytest.raises(TypeError, match="traced robot"):
        jax.jit(lambda r: pickle.dumps(r) and 0.0)(robot)


def test_a_pickled_robot_loads_in_a_fresh_process():
    robot = jk.robots.load("two_link_planar", dtype=np.float32)
    code = (
        "import pickle, sys, jaxkin as jk; r = pickle.loads(sys.stdin.buffer.read()); "
        "print(r.name, r.dof, float(r.params['a'][1]))"
    )
    run = subprocess.run(
        [sys.executable, "-c", code], input=pickle.dumps(robot), capture_output=True, timeout=120
    )
    assert run.returncode == 0, run.stderr.decode()
    name, dof, x = run.stdout.decode().split()
    assert (name, int(dof)) == (robot.name, 2)
    assert float(x) == float(robot.params["a"][1])


# ----------------------------------------------------------------------------- replace
PUMA = jk.robots.load("puma560", dtype=np.float64)
WRONG = {
    "lower": (np.zeros(2), "(6,)", "(2,)"),
    "upper": (np.zeros((6, 1)), "(6,)", "(6, 1)"),
    "offset": (np.zeros(5), "(6,)", "(5,)"),
    "multiplier": (np.ones(7), "(6,)", "(7,)"),
    "axis": (np.zeros(3), "(6, 3)", "(3,)"),
    "base": (jnp.eye(3), "(4, 4)", "(3, 3)"),
    "tool": (np.eye(4)[None], "(4, 4)", "(1, 4, 4)"),
    "params": ({**PUMA.params, "a": np.zeros(2)}, "(6,)", "(2,)"),
}


@pytest.mark.parametrize("field", sorted(WRONG))
def test_replace_names_the_field_and_the_shapes(field):
    value, wanted, got = WRONG[field]
    name = "params['a']" if field == "params" else field
    wanted = rf"{re_escape(name)} must have shape {re_escape(wanted)}.*got shape {re_escape(got)}"
    with pytest.raises(jk.ShapeError, match=wanted):
        PUMA.replace(**{field: value})


def test_replace_refuses_unknown_fields_params_and_non_numbers():
    with pytest.raises(jk.ModelError, match="no attribute 'lowr'"):
        PUMA.replace(lowr=np.zeros(6))
    with pytest.raises(jk.ModelError, match=r"params.*\['a', 'alpha', 'd', 'theta'\]"):
        PUMA.replace(params={"a": PUMA.params["a"]})
    with pytest.raises(jk.ShapeError, match="tool must be an array of real numbers"):
        PUMA.replace(tool="eye")
    floating = FLOATING.replace(lower=np.zeros(FLOATING.nq), upper=np.ones(FLOATING.nq, int))
    assert floating.upper.dtype == np.float64  # integers take the robot's dtype
    with pytest.raises(jk.ShapeError, match=r"lower must have shape \(16,\)"):
        FLOATING.replace(lower=np.zeros(FLOATING.nv))
    with pytest.raises(jk.ShapeError, match=r"params\['xyz'\] must have shape \(5, 3\)"):
        FLOATING.replace(params={**FLOATING.params, "xyz": np.zeros((5,))})


def test_replace_keeps_working_for_right_shapes_stacks_and_traces():
    moved = PUMA.replace(base=np.eye(4), lower=-np.ones(6), params={**PUMA.params})
    assert moved == PUMA.replace(lower=-np.ones(6))
    stack = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), PUMA, PUMA)
    assert stack.replace(tool=jnp.stack([PUMA.tool] * 2)).tool.shape == (2, 4, 4)
    with pytest.raises(jk.ShapeError, match=r"tool must have shape \(2, 4, 4\)"):
        stack.replace(tool=PUMA.tool)
    tools = jax.vmap(lambda r: r.replace(tool=2 * r.tool).tool)(stack)
    assert tools.shape == (2, 4, 4)


# ----------------------------------------------------------------------------- solve_ik
PLANAR = jk.robots.load("two_link_planar", dtype=np.float64)


@pytest.mark.parametrize("lanes", [0, -3, True, 2.0, "4"])
def test_solve_ik_refuses_lanes_that_are_not_positive_integers(lanes):
    T = np.asarray(jk.fk(PLANAR, np.array([0.3, 0.4])))
    with pytest.raises(jk.JaxkinError, match=rf"lanes must be an integer >= 1, got {lanes!r}"):
        jk.solve_ik(PLANAR, np.stack([T, T]), np.zeros(2), lanes=lanes)
