"""Eager calls of the building blocks run a cached compiled executable: equal to the traced path,
never stale for a changed robot, one compile per (robot, shape, dtype), and a bounded cache.

No wall-clock asserts: compile counts (the cache's entries and ``jax.jit``'s own cache size) and
equalities.

The robot is a four-joint DH arm (revolute and prismatic joints, a tool offset): what is tested is
the cache and the dispatch, which are the same for every robot, and each kernel's compiles cost
about half of a six-joint arm's. The user's ``jit``, ``vmap`` and ``grad`` are compiled programs
(:func:`compiled`; ``vmap`` and ``grad`` inside ``jit``): at top level they run the kernel op by
op, compiling each primitive (2-7 CPU s per kernel), and the kernel sees the same tracers and the
same trace state either way; op by op is covered by ``jax.disable_jit()`` below, and a ``vmap``
at top level by the pasted hints of ``test_error_hints.py``.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE
from hypothesis import given, settings

import jaxkin as jk
import jaxkin.testing as jkt
from jaxkin import _jit

CALLS = {
    "fk": lambda r, q, qd: jk.fk(r, q),
    "fk_all": lambda r, q, qd: jk.fk_all(r, q),
    "geometric_jacobian": lambda r, q, qd: jk.geometric_jacobian(r, q, reference="local"),
    "frame_jacobian": lambda r, q, qd: jk.jacobians.frame_jacobian(r, q, point=[0, 0, 0.1]),
    "jacobian_fwd": lambda r, q, qd: jk.jacobian_fwd(r, q),
    "jacobian_rev": lambda r, q, qd: jk.jacobian_rev(r, q, reference="world"),
    "analytical_jacobian": lambda r, q, qd: jk.analytical_jacobian(r, q, "zyz"),
    "twist": lambda r, q, qd: jk.twist(r, q, qd),
    "twist_of_frames": lambda r, q, qd: jk.twist(r, q, qd, frame=["link2", 5, "link2"]),
    "jacobian_dot": lambda r, q, qd: jk.jacobian_dot(r, q, qd),
    "jacobian_dot_qd": lambda r, q, qd: jk.jacobian_dot_qd(r, q, qd),
    "analytical_jacobian_dot": lambda r, q, qd: jk.analytical_jacobian_dot(r, q, qd),
    "analytical_jacobian_dot_qd": lambda r, q, qd: jk.analytical_jacobian_dot_qd(r, q, qd, "zyz"),
    "kinematic_hessian": lambda r, q, qd: jk.kinematic_hessian(r, q),
}


ROWS = [  # revolute and prismatic joints, general twists: every orientation is reachable
    dict(a=0.0, alpha=math.pi / 2, d=0.4, theta=0.0, joint="revolute", lower=-3, upper=3),
    dict(a=0.5, alpha=0.0, d=0.0, theta=0.2, joint="revolute", offset=0.1),
    dict(a=0.1, alpha=-math.pi / 2, d=0.2, theta=0.0, joint="prismatic", lower=0, upper=1),
    dict(a=0.0, alpha=math.pi / 2, d=0.3, theta=0.0, joint="revolute"),
]
TOOL = np.array([[1.0, 0, 0, 0], [0, 1, 0, 0.05], [0, 0, 1, 0.1], [0, 0, 0, 1]])


def _load_arm():
    return jk.Robot.from_dh(ROWS, tool=TOOL, name="arm", dtype=np.float64)


@pytest.fixture
def arm():
    _jit.eager_cache_clear()
    robot = _load_arm()
    q = jnp.asarray([0.1, -0.4, 0.3, 0.2])
    yield robot, q, jnp.linspace(-1.0, 1.0, 4)
    _jit.eager_cache_clear()


def compiled(f):
    """``jax.jit(f)`` with the suite's options for one-off test programs (``_xla.FAST_COMPILE``:
    no fast-math, the same numbers; these kernels compile several times faster than with XLA's
    defaults). What is tested, the kernel traced inline and the cache left alone, does not
    depend on them."""
    return jax.jit(f, compiler_options=FAST_COMPILE)


def _leaves(x):
    return [np.asarray(a) for a in jax.tree_util.tree_leaves(x)]


@pytest.mark.parametrize("name", sorted(CALLS))
def test_eager_equals_traced_and_compiles_once(arm, name):
    robot, q, qd = arm
    call = CALLS[name]
    first = call(robot, q, qd)
    assert _jit.eager_cache_info() == {"entries": 1, "executables": 1}
    for k in range(3):  # new values, same shapes: no new compile
        again = call(robot, q + 0.1 * (k + 1), qd)
    assert _jit.eager_cache_info()["executables"] == 1

    # inline in the user's jit, vmap and grad: the same numbers, and the cache is not touched
    # (the jit and the vmap inside it in one program: one compile)
    def inline(q, qd):
        return call(robot, q, qd), jax.vmap(lambda q, qd: call(robot, q, qd))(q[None], qd[None])

    traced, mapped = compiled(inline)(q, qd)
    for a, b, c in zip(_leaves(first), _leaves(traced), _leaves(mapped), strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-15 * max(1.0, np.abs(b).max()))
        np.testing.assert_allclose(a, c[0], rtol=0, atol=1e-15 * max(1.0, np.abs(c).max()))
    assert not np.allclose(_leaves(again)[0], _leaves(first)[0])
    assert _jit.eager_cache_info()["entries"] == 1
    _check_host_input(robot, q, qd, call, _leaves(first))  # on the executable compiled above


def test_a_new_dtype_or_shape_compiles_once_more(arm):
    robot, q, _qd = arm
    for _ in range(3):
        jk.geometric_jacobian(robot, q)
    J32 = jk.geometric_jacobian(robot.astype(np.float32), q.astype(jnp.float32))
    assert J32.dtype == jnp.float32  # a float32 robot is another key
    assert _jit.eager_cache_info() == {"entries": 2, "executables": 2}
    J = jk.geometric_jacobian(robot, q.astype(jnp.float32))  # float64 robot, float32 q
    assert J.dtype == jnp.float64
    assert _jit.eager_cache_info() == {"entries": 2, "executables": 3}
    jk.geometric_jacobian(robot, q.astype(jnp.float32))
    assert _jit.eager_cache_info()["executables"] == 3


def test_a_replaced_robot_gets_its_own_answer(arm):
    robot, q, _qd = arm
    T = jk.fk(robot, q)
    params = dict(robot.params)
    params["d"] = np.asarray(params["d"]) + 0.1
    moved = robot.replace(params=params)
    T_moved = jk.fk(moved, q)
    assert not np.allclose(np.asarray(T), np.asarray(T_moved))
    expected = compiled(lambda r, q: jk.fk(r, q))(moved, q)  # the robot traced: nothing folded
    np.testing.assert_allclose(np.asarray(T_moved), np.asarray(expected), rtol=0, atol=1e-15)
    assert _jit.eager_cache_info()["entries"] == 2
    again = _load_arm()  # an equal robot shares the executable
    np.testing.assert_array_equal(np.asarray(jk.fk(again, q)), np.asarray(T))
    assert _jit.eager_cache_info()["entries"] == 2


def test_grad_of_the_robot_and_of_q_trace_inline(arm):
    robot, q, qd = arm
    jk.twist(robot, q, qd)
    before = _jit.eager_cache_info()
    # with respect to q, and to the robot (traced), in one program
    g, gr = compiled(
        lambda q, r: (
            jax.grad(lambda q: jk.twist(robot, q, qd)[0])(q),
            jax.grad(lambda r: jk.fk(r, q)[0, 3])(r),
        )
    )(q, robot)
    assert _jit.eager_cache_info() == before
    eps = 1e-6
    for k in range(4):
        dq = eps * np.eye(4)[k]  # on the host: no program per step
        fd = (jk.twist(robot, q + dq, qd)[0] - jk.twist(robot, q - dq, qd)[0]) / (2 * eps)
        assert abs(float(g[k]) - float(fd)) < 1e-7
    assert np.isfinite(np.asarray(gr.params["d"])).all()


def test_the_cache_is_bounded(monkeypatch):
    monkeypatch.setattr(_jit, "EAGER_CACHE_SIZE", 4)
    _jit.eager_cache_clear()
    base = jk.robots.load("two_link_planar", dtype=np.float64)
    q = jnp.asarray([0.3, -0.2])
    for k in range(10):
        robot = base.replace(params={**base.params, "a": np.asarray(base.params["a"]) + k})
        T = jk.fk(robot, q)
        assert _jit.eager_cache_info()["entries"] <= 4
        # still the right answer: planar two-link closed form
        a1, a2 = (np.asarray(robot.params["a"])[i] for i in range(2))
        x = a1 * np.cos(0.3) + a2 * np.cos(0.1)
        assert abs(float(T[0, 3]) - x) < 1e-12
    _jit.eager_cache_clear()


@settings(max_examples=10)
@given(jkt.robots_and_configurations(max_joints=4))
def test_the_cache_bound_holds_over_random_robots(robot_and_q):
    robot, q = robot_and_q
    size = _jit.EAGER_CACHE_SIZE
    _jit.EAGER_CACHE_SIZE = 3  # small enough that every example evicts (fixtures and @given)
    try:
        J = jk.geometric_jacobian(robot, q)
        T = jk.fk(robot, q)
        jk.fk_all(robot, q)
        assert _jit.eager_cache_info()["entries"] <= 3
        J2, T2 = compiled(lambda q: (jk.geometric_jacobian(robot, q), jk.fk(robot, q)))(q)
        np.testing.assert_allclose(np.asarray(J), np.asarray(J2), rtol=0, atol=1e-13)
        np.testing.assert_allclose(np.asarray(T), np.asarray(T2), rtol=0, atol=1e-13)
    finally:
        _jit.EAGER_CACHE_SIZE = size


def test_disable_jit_runs_op_by_op_and_caches_nothing(arm):
    robot, q, qd = arm
    with jax.disable_jit():
        J = jk.geometric_jacobian(robot, q)
        V = jk.twist(robot, q, qd)
    assert _jit.eager_cache_info()["entries"] == 0
    np.testing.assert_allclose(np.asarray(V), np.asarray(J @ qd), rtol=0, atol=1e-14)
    np.testing.assert_allclose(
        np.asarray(J), np.asarray(jk.geometric_jacobian(robot, q)), rtol=0, atol=1e-15
    )


def _check_host_input(robot, q, qd, call, expected):
    """numpy arrays and lists go to the executable as they are (no device round trip first):
    the same numbers and dtypes as JAX arrays (``expected``: ``call(robot, q, qd)``), integers
    take the robot's dtype, float64 input becomes float32 while x64 is off (as jnp.asarray
    does), op by op too. Called by :func:`test_eager_equals_traced_and_compiles_once`, which
    compiled the executable already."""
    for host in ((np.asarray(q), np.asarray(qd)), (np.asarray(q).tolist(), np.asarray(qd))):
        got = _leaves(call(robot, *host))
        for a, b in zip(got, expected, strict=True):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
    ints = _leaves(call(robot, np.array([1, -1, 1, 2], np.int32), np.ones(4, np.int64)))
    assert ints[0].dtype == np.float64
    with jax.disable_jit():
        for a, b in zip(_leaves(call(robot, np.asarray(q), np.asarray(qd))), expected, strict=True):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-14 * max(1.0, np.abs(b).max()))
    robot32 = robot.astype(np.float32)
    with jax.enable_x64(False):
        got32 = _leaves(call(robot32, np.asarray(q), np.asarray(qd)))
    assert all(a.dtype == np.float32 for a in got32)
    for a, b in zip(got32, expected, strict=True):
        np.testing.assert_allclose(a, b, rtol=0, atol=2e-5 * max(1.0, np.abs(b).max()))
