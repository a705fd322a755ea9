"""Robots are values: immutable, equal when built from the same description, and every cache
keyed on a robot answers for the robot it is given, never for an earlier one.

Before robots were values, ``robot.params["xyz"] = ...`` edited a robot in place and the next
``solve_ik`` / ``calibrate`` / ``resolved_rate_control`` call reused the solver compiled for the
old numbers (converged, residual 2e-16, true error 0.042 m).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE
from hypothesis import given
from hypothesis import strategies as st

import jaxkin as jk
from jaxkin.testing import dh_robots


def _niryo():
    return jk.robots.load("niryo_one", dtype=np.float64)


def _longer(robot, dx=0.05):
    """The same robot with the upper arm (joint 3's x offset, 0.21 m) ``dx`` metres longer."""
    xyz = np.array(robot.params["xyz"])
    xyz[3, 0] += dx
    return robot.replace(params={**robot.params, "xyz": xyz})


def test_leaves_cannot_be_assigned_in_place():
    robot = _niryo()
    with pytest.raises(TypeError):
        robot.params["xyz"] = robot.params["xyz"] * 2
    with pytest.raises(AttributeError):
        robot.params.extra = 1
    with pytest.raises(dataclasses.FrozenInstanceError):
        robot.offset = robot.offset + 1
    with pytest.raises((TypeError, ValueError)):  # JAX arrays are immutable
        robot.offset[0] = 1.0


def test_replace_returns_an_independent_robot():
    robot = _niryo()
    before = np.array(robot.params["xyz"])
    xyz = np.array(robot.params["xyz"])
    changed = robot.replace(params={**robot.params, "xyz": xyz})
    xyz[0, 0] += 1.0  # editing the caller's array afterwards changes neither robot
    np.testing.assert_array_equal(np.asarray(changed.params["xyz"]), before)
    np.testing.assert_array_equal(np.asarray(robot.params["xyz"]), before)
    longer = _longer(robot)
    assert longer != robot and hash(longer) != hash(robot)
    np.testing.assert_array_equal(np.asarray(robot.params["xyz"]), before)


def test_robots_from_the_same_description_compare_equal():
    assert _niryo() == _niryo() and hash(_niryo()) == hash(_niryo())
    panda = jk.robots.load("erd/panda", dtype=np.float64)
    again = jk.robots.load("erd/panda", dtype=np.float64)
    assert panda is not again and panda == again and hash(panda) == hash(again)
    assert panda != panda.astype(np.float32)  # another dtype is another value
    assert _niryo() != _niryo().with_configurations(extra=np.zeros(6))


@given(dh_robots(max_joints=6, dtype=np.float64), st.floats(1e-6, 1.0))
def test_equality_follows_every_number(robot, delta):
    assert robot == robot.replace()
    leaves, treedef = jax.tree_util.tree_flatten(robot)
    for i, leaf in enumerate(leaves):
        bumped = np.array(leaf)
        bumped.flat[0] += delta
        other = jax.tree_util.tree_unflatten(treedef, [*leaves[:i], bumped, *leaves[i + 1 :]])
        assert other != robot


def test_traced_robots_compare_by_identity():
    robot = _niryo()

    @functools.partial(jax.jit, compiler_options=FAST_COMPILE)
    def f(r):
        assert r == r and r != robot and hash(r) == id(r)
        return jk.fk(r, jnp.zeros(r.dof))

    f(robot)


def _reach(robot, q):
    return np.asarray(jk.fk(robot, q))


def _path(robot, qs):
    """The tip's pose at each configuration: eager ``jk.fk`` calls, which share the kernel
    compiled once per robot value with :func:`_reach` (a ``jax.vmap`` outside ``jit`` would
    dispatch, and compile, every primitive of the batched kernel op by op)."""
    return np.stack([_reach(robot, q) for q in qs])


def test_solve_ik_answers_for_the_robot_it_is_given():
    robot = _niryo()
    q_star = np.array([0.3, -0.4, 0.5, 0.2, -0.6, 0.1])
    q0 = np.zeros(6)
    T = _reach(robot, q_star)
    sol = jk.solve_ik(robot, T, q0, throw=False)
    assert bool(sol.converged)
    longer = _longer(robot)
    sol2 = jk.solve_ik(longer, T, q0, throw=False)
    assert bool(sol2.converged)
    np.testing.assert_allclose(_reach(longer, sol2.q), T, atol=1e-9)  # the new robot reaches T
    assert np.abs(_reach(robot, sol2.q) - T).max() > 1e-3  # ... and it is not the old answer


def test_resolved_rate_control_answers_for_the_robot_it_is_given():
    robot = _niryo()
    q0 = np.array([0.1, -0.3, 0.4, 0.0, 0.5, 0.0])
    qs = q0 + np.linspace(0, 0.2, 20)[:, None] * np.array([1, 0.5, -0.5, 0.3, 0.2, 0.1])
    path = _path(robot, qs)
    out = jk.resolved_rate_control(robot, q0, path, 0.01)
    longer = _longer(robot, dx=0.02)
    path2 = _path(longer, qs)
    out2 = jk.resolved_rate_control(longer, q0, path2, 0.01)
    assert float(out.max_position_error) < 1e-3 and float(out2.max_position_error) < 1e-3
    # the second run moved the longer arm along its path; the old arm at those joints is elsewhere
    end = np.asarray(path2[-1])
    np.testing.assert_allclose(_reach(longer, out2.q[-1]), end, atol=1e-3)
    assert np.abs(_reach(robot, out2.q[-1]) - end).max() > 5e-3


def test_calibrate_answers_for_the_robot_it_is_given():
    """The fit is compiled for its nominal robot (a static value): a second nominal gets its own
    fit, started from its own numbers. A two-link arm (its link length ``a[0]``, a leaf of
    ``params`` like the Niryo's ``xyz``): the cache, not the robot, is what is tested, and its
    fits compile several times faster than the Niryo's."""
    truth = jk.robots.load("two_link_planar", dtype=np.float64)
    # within the limits, drawn by numpy (nothing to compile; the sampler is not under test)
    qs = np.random.default_rng(3).uniform(np.asarray(truth.lower), np.asarray(truth.upper), (40, 2))
    Ts = _path(truth, qs)
    masks = {"a": np.array([True, False])}

    def longer(dx):
        return truth.replace(params={**truth.params, "a": truth.params["a"] + np.array([dx, 0.0])})

    start = longer(0.01)
    res = jk.calibrate(start, qs, Ts, masks)
    np.testing.assert_allclose(np.asarray(res.params["a"])[0], truth.params["a"][0])
    start2 = longer(-0.02)  # a different nominal: the fit starts from its numbers
    assert start2 != start and hash(start2) != hash(start)
    res2 = jk.calibrate(start2, qs, Ts, masks)
    np.testing.assert_allclose(np.asarray(res2.params["a"])[0], truth.params["a"][0])
    assert int(res2.steps) > 0
