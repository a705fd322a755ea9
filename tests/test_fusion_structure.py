"""The batched Jacobian kernels compute each joint's sine and cosine once (issue 24).

XLA's CPU pipeline drops ``optimization_barrier`` and fuses an elementwise producer into every
consumer, so a batched Jacobian, which XLA splits into one fusion per shared intermediate,
re-derived the sines and cosines of its path in each of them (a Talos hand: 36 sin/cos ops for 9
joints, 54 in ``local``). The kernels now read them through an identity gather, which XLA
computes once. Guarded by counting operations in the compiled HLO (never the clock) of a small
free-flyer arm, which shows the same duplication as the humanoids at a fraction of their
compile time; the values are checked against the same kernel run op by op (where the gather is
a copy), in float64 and float32, and the forward kinematics keep their program.
"""

from __future__ import annotations

import re
from collections import Counter

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxkin as jk
from jaxkin import _fold as fold

EPS = {np.float64: float(np.finfo(np.float64).eps), np.float32: float(np.finfo(np.float32).eps)}


def _arm(n: int = 3) -> jk.Robot:
    """A free-flyer root and a serial arm of ``n`` revolute joints, offsets along the links and
    axes alternating between y and z (a humanoid's arm: its constants fold below the root)."""
    rng = np.random.default_rng(24)
    specs = [dict(name="root", type="free", parent="base", child="l_root")]
    for j in range(n):
        specs.append(
            dict(
                name=f"j{j}",
                type="revolute",
                parent="l_root" if j == 0 else f"l{j - 1}",
                child=f"l{j}",
                xyz=(0.2 * rng.normal(size=3)).tolist(),
                axis=[0.0, 0.0, 1.0] if j % 2 else [0.0, 1.0, 0.0],
                lower=-2.0,
                upper=2.0,
            )
        )
    return jk.Robot.from_joints(specs)


def _hlo_counts(fn, x) -> Counter:
    text = jax.jit(fn).lower(x).compile().as_text()
    return Counter(re.findall(r"=\s*[^\s=]+\s+([a-z][a-z0-9\-]*)\(", text))


def _qs(robot: jk.Robot, n: int, dtype) -> jnp.ndarray:
    return jnp.asarray(np.random.default_rng(7).uniform(-1.0, 1.0, (n, robot.nq)), dtype)


@pytest.mark.parametrize("reference", ["world_aligned", "local"])
def test_batched_jacobian_computes_each_sine_and_cosine_once(reference):
    """One sine and one cosine op (each over the stacked path angles) in the compiled program;
    before: 19 and 19 (world_aligned), 27 and 26 (local) for this 3-joint arm."""
    robot = _arm()
    fn = jax.vmap(lambda q: jk.geometric_jacobian(robot, q, frame="l2", reference=reference))
    c = _hlo_counts(fn, _qs(robot, 4, np.float64))
    assert c["sine"] <= 1 and c["cosine"] <= 1, (c["sine"], c["cosine"])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_batched_jacobian_equals_the_kernel_run_op_by_op(dtype):
    """The compiled kernel gives the op-by-op numbers (the gather is a copy) to a few ulps of
    the result's scale (XLA contracts products and sums into FMAs where it fuses them)."""
    robot = _arm().astype(dtype)
    qs = _qs(robot, 8, dtype)
    fn = jax.vmap(lambda q: jk.geometric_jacobian(robot, q, frame="l2", reference="local"))
    J = np.asarray(jax.jit(fn)(qs))
    with jax.disable_jit():
        J_op = np.asarray(fn(qs))
    assert J.dtype == J_op.dtype == dtype
    scale = 1.0 + float(np.abs(J_op).max())
    np.testing.assert_allclose(J, J_op, rtol=0, atol=16 * EPS[dtype] * scale)


def test_several_frames_compute_the_union_sines_once():
    """Two frames on one arm in one call: still one sine and one cosine op (before: 20 and 20)."""
    robot = _arm()
    fn = jax.vmap(lambda q: jk.geometric_jacobian(robot, q, frame=["l1", "l2"]))
    c = _hlo_counts(fn, _qs(robot, 4, np.float64))
    assert c["sine"] <= 1 and c["cosine"] <= 1, (c["sine"], c["cosine"])


def _compiled(fn, x) -> tuple[Counter, list[int]]:
    """Operation counts of the compiled program and, per concatenate in it (fused or not), its
    number of operands."""
    text = jax.jit(fn).lower(x).compile().as_text()
    ops = Counter(re.findall(r"=\s*[^\s=]+\s+([a-z][a-z0-9\-]*)\(", text))
    calls = re.findall(r"\sconcatenate\(([^)]*)\)", text)
    return ops, [len(re.findall(r"%", c)) for c in calls]


def test_wide_stacks_fuse_into_the_output():
    """A free-flyer root and a 9-joint arm: its frame's 15 columns form one run and its 9 angles
    one stack. XLA's CPU compiler fuses nothing into a concatenate of more than 8 operands, so
    rows stacked 15 wide left each entry a fusion of its own, each recomputing the forward pass
    (before: 97 fusions, 5,962 multiplies, a 15-operand concatenate; now 44 and 575, none
    wider than 8)."""
    robot = _arm(9)
    fn = jax.vmap(lambda q: jk.geometric_jacobian(robot, q, frame="l8"))
    c, widths = _compiled(fn, _qs(robot, 4, np.float64))
    assert c["multiply"] <= 800 and c["fusion"] <= 55, (c["multiply"], c["fusion"])
    assert max(widths) <= 8, widths


def test_stack_vector_equals_a_stack():
    """``fold.stack_vector`` (nested stacks of at most 8) gives ``jnp.stack``'s array, for
    lengths around one and two levels of nesting."""
    for k in (1, 8, 9, 70):
        values = [jnp.float64(i + 0.5) for i in range(k)]
        got = np.asarray(jax.jit(lambda *v: fold.stack_vector(v, jnp.float64))(*values))
        np.testing.assert_array_equal(got, np.arange(k) + 0.5)


def test_several_frames_share_one_fused_assembly():
    """Four frames of a 3-joint arm under a free-flyer (9 columns each) in one call: each
    frame's block fuses into the output (before: 46 fusions, 563 multiplies; now 28 and 182,
    against 22 and 105 for the deepest frame alone)."""
    robot = _arm()
    x = _qs(robot, 4, np.float64)
    fn = jax.vmap(lambda q: jk.geometric_jacobian(robot, q, frame=["l0", "l1", "l2", "l2"]))
    c = _hlo_counts(fn, x)
    assert c["multiply"] <= 250 and c["fusion"] <= 35, (c["multiply"], c["fusion"])


@pytest.mark.parametrize(
    ("reference", "fusions", "multiplies"), [("world_aligned", 20, 200), ("world", 22, 300)]
)
def test_rotation_below_a_free_flyer_fuses_into_the_output(reference, fusions, multiplies):
    """The columns below a free-flyer are rotated into world axes as rows of stacked columns, so
    each entry of the free-flyer's rotation is read by a few operations and XLA fuses it into
    the output; rotated column by column, each entry was read by every rotated column, more
    than XLA duplicates, and became a fusion of its own (a 5-joint arm, world_aligned: 26
    fusions, 234 multiplies before, 16 and 188 now; world: 29 and 413, now 18 and 287; the
    values are checked against the world pass in test_jacobian_speed_paths)."""
    robot = _arm(5)
    fn = jax.vmap(lambda q: jk.geometric_jacobian(robot, q, frame="l4", reference=reference))
    c = _hlo_counts(fn, _qs(robot, 4, np.float64))
    assert c["fusion"] <= fusions and c["multiply"] <= multiplies, (c["fusion"], c["multiply"])
