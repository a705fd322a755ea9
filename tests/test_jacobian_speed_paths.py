"""The geometric Jacobian's fast paths (issue 24) give today's numbers, and their structure.

* Zero columns (joints off the frame's path) are placed statically (a concatenation of zeros
  blocks and stacked column blocks), no longer scattered into a zeros matrix: checked equal, bit
  for bit, to the scatter of the same columns, and to ``jax.jacfwd`` of forward kinematics
  (1e-12 of the result's scale) on random trees.
* Below a free-flyer the columns are computed in the free-flyer's child frame and rotated once
  (``local``: by the relative rotation alone): checked against the columns of the world pass
  (the kernel before, ``world_jacobian_pass``; 1e-12 of the result's scale) on random
  floating-base trees and a humanoid, in every reference, and several frames in one call
  against the single-frame calls, bit for bit.
* Structure (compiled HLO, never the clock): one frame of a tree compiles to the program of its
  path built as a robot of its own (before: a scatter and more fusions).

Cost: everything op by op (``tests/_xla.op_by_op``) except two small compiles of a 6-joint arm.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import hlo_counts, op_by_op
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk
import jaxkin.testing as jkt
from jaxkin import _jacobian_pass

REFERENCES = ("world_aligned", "local", "world")


def _scattered(g) -> np.ndarray:
    """The (6, nv) matrix of a FrameJacobian's scalar columns, each column written into a zeros
    matrix (the assembly before static placement)."""
    Jv, Jw = g.columns()
    J = np.zeros((6, len(Jv)))
    for k, (v, w) in enumerate(zip(Jv, Jw, strict=True)):
        J[:, k] = [float(x) for x in (*v, *w)]
    return J


def _scale(J) -> float:
    return 1.0 + float(np.abs(np.asarray(J)).max())


# ----------------------------------------------------------------------------- random trees
@settings(max_examples=4)  # op by op; jax.jacfwd of each new robot costs seconds
@given(jkt.robots_and_configurations(2, 8, kind="tree"), st.data())
@op_by_op
def test_static_placement_equals_the_scattered_columns(robot_q, data):
    robot, q = robot_q
    frame = data.draw(st.integers(0, robot.n_frames - 1))
    reference = data.draw(st.sampled_from(REFERENCES))
    g = _jacobian_pass.jacobian_pass(robot, jnp.asarray(q), frame, None, reference)
    J = np.asarray(g.matrix())
    if isinstance(g.cv, list):  # unrolled (scanned paths assemble arrays)
        np.testing.assert_array_equal(J, _scattered(g))
    J_ad = np.asarray(jk.jacobian_fwd(robot, q, frame=frame, reference=reference))
    np.testing.assert_allclose(J, J_ad, rtol=0, atol=1e-12 * _scale(J_ad))
    off = np.setdiff1d(np.arange(robot.nv), [robot.v_index[j] for j in robot.ancestors(frame)])
    assert np.all(J[:, off] == 0.0)


# ----------------------------------------------------------------------------- floating bases
def _floating_tree(n: int, seed: int) -> jk.Robot:
    """A free-flyer root and a random tree of ``n`` revolute / prismatic / fixed joints below it
    (some +-90 degree placements, some tilted axes)."""
    rng = np.random.default_rng(seed)
    specs = [dict(name="root", type="free", parent="base", child="l_root")]
    for j in range(n):
        kind = str(rng.choice(["revolute", "revolute", "prismatic", "fixed"]))
        axis = [0.0, 0.0, 1.0] if rng.random() < 0.5 else rng.normal(size=3).tolist()
        specs.append(
            dict(
                name=f"j{j}",
                type=kind,
                parent="l_root"
                if j == 0
                else str(rng.choice(["l_root", f"l{rng.integers(0, j)}"])),
                child=f"l{j}",
                xyz=(0.2 * rng.normal(size=3)).tolist(),
                rpy=[float(rng.choice([0.0, np.pi / 2, rng.normal()])), 0.0, float(rng.normal())],
                axis=axis,
                lower=-1.0,
                upper=1.0,
            )
        )
    return jk.Robot.from_joints(specs)


def _configuration(robot: jk.Robot, seed: int) -> jnp.ndarray:
    """Uniform in [-1, 1] per entry (the kernels normalise the free joint's quaternion)."""
    return jnp.asarray(np.random.default_rng(seed).uniform(-1.0, 1.0, robot.nq))


@given(st.integers(1, 7), st.integers(0, 10_000), st.data())
@op_by_op
def test_free_flyer_columns_equal_the_world_pass(n, seed, data):
    robot = _floating_tree(n, seed)
    q = _configuration(robot, seed)
    frame = data.draw(st.integers(1, robot.n_frames - 1))
    point = data.draw(st.sampled_from([None, jnp.array([0.1, -0.2, 0.3])]))
    single = {}  # frame -> the single-frame "local" matrix without a point (op by op: reused)
    for reference in REFERENCES:
        fast = _jacobian_pass.jacobian_pass(robot, q, frame, point, reference)
        world = _jacobian_pass.world_jacobian_pass(robot, q, frame, point, reference)
        J, J_w = np.asarray(fast.matrix()), np.asarray(world.matrix())
        np.testing.assert_allclose(J, J_w, rtol=0, atol=1e-12 * _scale(J_w))
        np.testing.assert_array_equal(J, _scattered(fast))
        np.testing.assert_array_equal(np.asarray(fast.pose()), np.asarray(world.pose()))
        if point is None and reference == "local":
            single[frame] = J
    # several frames in one call: the single-frame calls, bit for bit
    frames = (frame, robot.n_frames - 1, frame)
    several = _jacobian_pass.jacobians_pass(robot, q, frames, None, "local")
    for f, g in zip(frames, several.each, strict=True):
        if f not in single:
            one = _jacobian_pass.jacobian_pass(robot, q, f, None, "local")
            single[f] = np.asarray(one.matrix())
        np.testing.assert_array_equal(np.asarray(g.matrix()), single[f])


@pytest.fixture(scope="module")
def humanoid():
    return jk.robots.load("erd/simple_humanoid", floating_base=True, dtype=np.float64)


@op_by_op
def test_humanoid_hands_and_feet_equal_the_world_pass(humanoid):
    robot = humanoid
    q = _configuration(robot, 7)
    frames = tuple(robot.frame_index(f) for f in ("r_wrist", "l_wrist", "l_ankle"))
    for reference in REFERENCES:
        several = _jacobian_pass.jacobians_pass(robot, q, frames, None, reference)
        for f, g in zip(frames, several.each, strict=True):
            world = _jacobian_pass.world_jacobian_pass(robot, q, f, None, reference)
            J_w = np.asarray(world.matrix())
            J = np.asarray(g.matrix())
            np.testing.assert_allclose(J, J_w, rtol=0, atol=1e-12 * _scale(J_w))
            np.testing.assert_array_equal(J, _scattered(g))


# ----------------------------------------------------------------------------- structure
def _arm_specs(extra: int) -> list:
    """A 6-joint arm with +-90 degree placements, and ``extra`` joints on a branch beside it."""
    axes = [(0, 0, 1), (0, 1, 0), (0, 0, 1), (0, 1, 0), (0, 0, 1), (1, 0, 0)]
    specs = [
        dict(
            name=f"a{i}",
            type="revolute",
            parent="base" if i == 0 else f"al{i - 1}",
            child=f"al{i}",
            xyz=[0.0, 0.05 * i, 0.1],
            rpy=[np.pi / 2 if i % 2 else 0.0, 0.0, 0.0],
            axis=list(axes[i]),
            lower=-2.0,
            upper=2.0,
        )
        for i in range(6)
    ]
    specs += [
        dict(
            name=f"x{k}",
            type="revolute",
            parent="base" if k == 0 else f"xl{k - 1}",
            child=f"xl{k}",
            xyz=[0.1, 0.0, 0.02],
            axis=[0.0, 0.0, 1.0],
            lower=-2.0,
            upper=2.0,
        )
        for k in range(extra)
    ]
    return specs


def test_one_frame_of_a_tree_compiles_to_the_program_of_its_path():
    """20 joints beside the arm leave its Jacobian's compiled program as it is (before: a scatter
    into a zeros matrix, 14 fusions against 12)."""
    counts = []
    for extra in (0, 20):
        robot = jk.Robot.from_joints(_arm_specs(extra))
        c = hlo_counts(
            jax.vmap(lambda q, r=robot: jk.geometric_jacobian(r, q, frame="al5")),
            jnp.zeros((4, robot.nq)),
        )
        counts.append({k: c[k] for k in ("fusion", "multiply", "add", "sine", "cosine")})
        assert c["scatter"] == 0, c
    assert counts[1] == counts[0], counts
