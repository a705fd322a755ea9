"""The ``lax.scan`` forward pass of long serial paths (issue 24): elementwise, batch-last under
``vmap``, and the numbers of the unrolled kernel.

* Values: the scan Jacobian (``scan_jacobian_pass``, any path of 1-dof and fixed joints) equals
  the unrolled kernel's (``world_jacobian_pass``, Table 4.1 from ``scalar_pass``) within 1e-12 of
  the result's scale on random DH and tree robots, every reference, with and without a point;
  the scan poses equal the unrolled ones, and so does a chain's Jacobian batched by ``vmap``.
* Structure (jaxpr, never the clock): the batched kernel has no ``dot_general`` and no
  ``scatter`` (before: 3x3 products batched first, small ``dot`` ops, 3-4x slower on the
  32-joint chain), and every carry of its scan is one (N,) array per pose entry.

Cost: op by op, or a jaxpr; no compile of a long chain.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import jaxpr_counts, jaxpr_eqns, op_by_op
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk
import jaxkin.testing as jkt
from jaxkin import _forward, _jacobian_pass

REFERENCES = ("world_aligned", "local", "world")


def _scale(J) -> float:
    return 1.0 + float(np.abs(np.asarray(J)).max())


def _chain(n: int, seed: int = 0, mimic: bool = True) -> jk.Robot:
    """A serial chain of ``n`` revolute and prismatic joints with tilted axes and placements (so
    :func:`~jaxkin._forward.scan_joints` scans it from 8 joints), a tool frame and (``mimic``) a
    mimic joint."""
    rng = np.random.default_rng(seed)
    specs = []
    for i in range(n):
        spec = dict(
            name=f"j{i}",
            type="prismatic" if i % 5 == 3 else "revolute",
            parent=f"l{i - 1}" if i else "base",
            child=f"l{i}",
            xyz=(0.1 * rng.normal(size=3)).tolist(),
            rpy=rng.normal(size=3).tolist(),
            axis=rng.normal(size=3).tolist(),
            lower=-2.0,
            upper=2.0,
        )
        if mimic and i == n - 2:
            spec["mimic"] = dict(joint="j0", multiplier=-1.5, offset=0.2)
        specs.append(spec)
    tip = dict(xyz=[0.0, 0.02, 0.05], rpy=[0.3, 0.0, 0.0])
    specs.append(dict(name="tip_joint", type="fixed", parent=f"l{n - 1}", child="tip", **tip))
    return jk.Robot.from_joints(specs, root="base", dtype=np.float64)


# ----------------------------------------------------------------------------- values
@settings(max_examples=5)
@given(jkt.robots_and_configurations(2, 8), st.data())
@op_by_op
def test_scan_jacobian_equals_the_unrolled_kernel(robot_q, data):
    robot, q = robot_q
    frame = data.draw(st.integers(0, robot.n_frames - 1))
    point = data.draw(st.sampled_from([None, jnp.array([0.1, -0.2, 0.3])]))
    reference = data.draw(st.sampled_from(REFERENCES))
    q = jnp.asarray(q)
    scan = _jacobian_pass.scan_jacobian_pass(robot, q, frame, point, reference)
    unrolled = _jacobian_pass.world_jacobian_pass(robot, q, frame, point, reference)
    J_u = np.asarray(unrolled.matrix())
    np.testing.assert_allclose(scan.matrix(), J_u, rtol=0, atol=1e-12 * _scale(J_u))
    np.testing.assert_allclose(scan.pose(), unrolled.pose(), rtol=0, atol=1e-12 * _scale(J_u))


def _values(x) -> np.ndarray:
    """Nested tuples of scalars (Python floats or 0-d arrays) as one float64 array."""
    return np.array(jax.tree_util.tree_map(float, x), dtype=np.float64)


@op_by_op
def test_scan_poses_equal_the_unrolled_pass():
    robot = _chain(8, seed=3)
    q = jnp.asarray(np.random.default_rng(1).uniform(-2.0, 2.0, robot.nq))
    assert _forward.scan_joints(robot) is not None
    fp = _forward.scan_pass(robot, q)
    sp = _forward.scalar_pass(robot, q)
    for name in ("R", "p", "z", "o"):
        np.testing.assert_allclose(
            getattr(fp, name), _values(getattr(sp, name)), rtol=0, atol=1e-12, err_msg=name
        )


@pytest.mark.parametrize(("mimic", "reference"), [(False, "local"), (True, "world")])
@op_by_op
def test_batched_scan_jacobian_equals_the_unrolled_kernel_per_configuration(
    mimic, reference, monkeypatch
):
    """Under ``vmap`` (the batch-last loop); ``mimic``: a velocity index shared by two joints
    (the columns added, not placed); without, the columns gathered (as on a path with more runs
    of columns than ``PLACED_RUNS``: slices are the hypothesis test's)."""
    monkeypatch.setattr(_jacobian_pass, "PLACED_RUNS", 0)
    robot = _chain(8, seed=5, mimic=mimic)
    tip = robot.n_frames - 1
    assert _forward.scan_joints(robot, tip) is not None
    qs = jnp.asarray(np.random.default_rng(2).uniform(-2.0, 2.0, (2, robot.nq)))
    pt = jnp.array([0.05, 0.0, -0.1])
    J = jax.vmap(lambda q: jk.geometric_jacobian(robot, q, tip, pt, reference))(qs)
    for q, J_q in zip(qs, J, strict=True):
        J_u = _jacobian_pass.world_jacobian_pass(robot, q, tip, pt, reference).matrix()
        np.testing.assert_allclose(J_q, J_u, rtol=0, atol=1e-12 * _scale(J_u))


# ----------------------------------------------------------------------------- structure
def _scan_eqn(fn, *args):
    scans = [e for e in jaxpr_eqns(fn, *args) if e.primitive.name == "scan"]
    assert len(scans) == 1, scans
    return scans[0]


@pytest.mark.parametrize("reference", REFERENCES)
def test_batched_scan_kernel_is_elementwise_and_batch_last(reference):
    robot = _chain(32, seed=7, mimic=False)
    n = 5
    fn = jax.vmap(lambda q: jk.geometric_jacobian(robot, q, reference=reference))
    qs = jnp.zeros((n, robot.nq))
    counts = jaxpr_counts(fn, qs)
    assert counts["dot_general"] == 0 and counts["scatter-add"] == 0, counts
    assert counts["sin"] == counts["cos"] == 1, counts  # once for the whole path
    eqn = _scan_eqn(fn, qs)
    carry = eqn.params["jaxpr"].in_avals[: eqn.params["num_carry"]]
    assert len(carry) == 12 and all(a.shape == (n,) for a in carry), carry
