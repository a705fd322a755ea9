"""Eager calls of the building blocks run a cached compiled executable (from the second call for a
robot), equal to the traced path, never stale for a changed robot, and the cache is bounded.

No wall-clock asserts: compile counts (the cache's entries and ``jax.jit``'s own cache size) and
equalities.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxkin as jk
from jaxkin import _jit

CALLS = {
    "fk": lambda r, q, qd: jk.fk(r, q),
    "fk_all": lambda r, q, qd: jk.fk_all(r, q),
    "geometric_jacobian": lambda r, q, qd: jk.geometric_jacobian(r, q, reference="local"),
    "frame_jacobian": lambda r, q, qd: jk.jacobians.frame_jacobian(r, q, point=[0, 0, 0.1]),
    "jacobian_fwd": lambda r, q, qd: jk.jacobian_fwd(r, q),
    "analytical_jacobian": lambda r, q, qd: jk.analytical_jacobian(r, q, "zyz"),
    "twist": lambda r, q, qd: jk.twist(r, q, qd),
    "jacobian_dot": lambda r, q, qd: jk.jacobian_dot(r, q, qd),
    "analytical_jacobian_dot": lambda r, q, qd: jk.analytical_jacobian_dot(r, q, qd),
    "kinematic_hessian": lambda r, q, qd: jk.kinematic_hessian(r, q),
}


@pytest.fixture
def puma():
    _jit.eager_cache_clear()
    robot = jk.robots.load("puma560", dtype=np.float64)
    q = jnp.asarray([0.1, -0.4, 0.3, 0.2, 0.5, -0.3])
    return robot, q, jnp.linspace(-1.0, 1.0, 6)


def _compiled(kernel_name: str):
    return [
        v
        for (kernel, _, _), v in _jit._eager_cache.items()
        if kernel.__name__ == kernel_name and v != 1
    ]


@pytest.mark.parametrize("name", sorted(CALLS))
def test_eager_equals_traced_and_compiles_once(puma, name):
    robot, q, qd = puma
    call = CALLS[name]
    first = call(robot, q, qd)  # op by op
    assert len(_jit._eager_cache) == 1 and next(iter(_jit._eager_cache.values())) == 1
    second = call(robot, q, qd)  # compiled now
    (entry,) = _jit._eager_cache.values()
    assert entry != 1 and entry._cache_size() == 1
    for _ in range(3):
        again = call(robot, q + 0.1, qd)  # new values: no new compile
    assert entry._cache_size() == 1
    traced = jax.jit(lambda q, qd: call(robot, q, qd))(q, qd)  # inline in the user's jit
    for a, b, c in zip(
        *(jax.tree_util.tree_leaves(x) for x in (first, second, traced)), strict=True
    ):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=0, atol=1e-13)
        np.testing.assert_allclose(np.asarray(a), np.asarray(c), rtol=0, atol=1e-13)
    assert not np.allclose(
        np.asarray(jax.tree_util.tree_leaves(again)[0]),
        np.asarray(jax.tree_util.tree_leaves(first)[0]),
    )
    assert len(_jit._eager_cache) == 1  # the user's jit did not touch the cache


def test_float32_input_compiles_once_more(puma):
    robot, q, _qd = puma
    for _ in range(3):
        jk.geometric_jacobian(robot, q)
    (entry,) = _jit._eager_cache.values()
    J32 = jk.geometric_jacobian(robot.astype(np.float32), q.astype(jnp.float32))
    assert J32.dtype == jnp.float32  # a float32 robot is another key
    jk.geometric_jacobian(robot, q.astype(jnp.float32))  # float64 robot, float32 q: float64
    assert entry._cache_size() == 2


def test_a_replaced_robot_gets_its_own_answer(puma):
    robot, q, _qd = puma
    for _ in range(3):
        T = jk.fk(robot, q)
    params = dict(robot.params)
    params["d"] = np.asarray(params["d"]) + 0.1
    moved = robot.replace(params=params)
    for _ in range(3):
        T_moved = jk.fk(moved, q)
    assert not np.allclose(np.asarray(T), np.asarray(T_moved))
    expected = jax.jit(lambda r, q: jk.fk(r, q))(moved, q)  # the robot traced: no folding
    np.testing.assert_allclose(np.asarray(T_moved), np.asarray(expected), atol=1e-13)
    again = jk.robots.load("puma560", dtype=np.float64)  # an equal robot shares the compile
    jk.fk(again, q)
    assert len(_compiled("frame_transform")) == 2


def test_grad_and_vmap_trace_inline(puma):
    robot, q, qd = puma
    jk.twist(robot, q, qd), jk.twist(robot, q, qd)
    n = len(_jit._eager_cache)
    g = jax.grad(lambda q: jk.twist(robot, q, qd)[0])(q)
    vs = jax.vmap(lambda q: jk.twist(robot, q, qd))(jnp.stack([q, q + 0.1]))
    gr = jax.grad(lambda r: jk.fk(r, q)[0, 3])(robot)  # gradient with respect to the robot
    assert len(_jit._eager_cache) == n
    assert np.all(np.isfinite(np.asarray(g))) and vs.shape == (2, 6)
    assert np.isfinite(np.asarray(gr.params["d"])).all()


def test_the_cache_is_bounded(monkeypatch):
    monkeypatch.setattr(_jit, "EAGER_CACHE_SIZE", 8)
    _jit.eager_cache_clear()
    base = jk.robots.load("two_link_planar", dtype=np.float64)
    q = jnp.zeros(2)
    for k in range(30):
        robot = base.replace(params={**base.params, "a": np.asarray(base.params["a"]) + k})
        jk.fk(robot, q), jk.fk(robot, q)
        assert len(_jit._eager_cache) <= 8
    _jit.eager_cache_clear()
