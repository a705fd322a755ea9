"""The suite compiles with LLVM's optimisation off; users compile with XLA's defaults.

tests/conftest.py puts ``QUICK_COMPILE_FLAGS`` into ``XLA_FLAGS`` for every process of the run (the
workers, and the CLI, README, doctest and notebook subprocesses, which inherit it): XLA then
builds the same optimised HLO but hands LLVM ``-O0`` code generation, and emits its fusions with
the older elemental emitter (as jaxkin's own jits do), which compiles jaxkin's kernels several
times faster and runs them about half as fast. Both compile one computation (no fast-math either
way); floating-point results may differ in the last bit where LLVM contracts a multiply and an
add into one FMA at ``-O3`` and not at ``-O0``, or where the two emitters round differently.

This file checks the numbers users get: kernels compiled here with the options a user's process
has (XLA's defaults under a user's own ``jax.jit``; plus jaxkin's compiler options under
jaxkin's jits) agree with the suite's compile to a few ulp and with Pinocchio to 1e-12 (the UR5
and the free-flyer Solo12), so every value the rest of the suite checks holds for the shipped
compile too.
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sampling import random_q
from conftest import QUICK_COMPILE_FLAGS

import jaxkin as jk
from bench import peers as P
from jaxkin import _jit

pin = pytest.importorskip("pinocchio")

# XLA's defaults for the options QUICK_COMPILE_FLAGS changes (xla/debug_options_flags.cc): what a
# user's own ``jax.jit`` around jaxkin compiles with; jaxkin's jits add their compiler options.
XLA_DEFAULTS = {
    "xla_backend_optimization_level": 3,
    "xla_llvm_disable_expensive_passes": False,
    "xla_cpu_parallel_codegen_split_count": 32,
    "xla_cpu_use_fusion_emitters": True,
}
USER_OPTIONS = {
    "a user's jax.jit": XLA_DEFAULTS,
    "jaxkin's jit": {**XLA_DEFAULTS, **_jit.compiler_options()},
}
ULP = 8 * np.finfo(np.float64).eps  # a few roundings apart, relative to max(1, |value|)
N = 16


def test_the_suite_compiles_with_the_quick_flags():
    if os.environ.get("JAXKIN_TESTS_XLA_DEFAULTS"):
        pytest.skip("JAXKIN_TESTS_XLA_DEFAULTS is set: this run compiles with XLA's defaults")
    flags = os.environ.get("XLA_FLAGS", "")
    for flag in QUICK_COMPILE_FLAGS:
        assert flag in flags, (flag, flags)


def _source_and_model(name: str):
    """The benchmark's robot source and Pinocchio's model of it: the UR5, or the Solo12 with a
    free-flyer root."""
    if name == "ur5":
        src = P.robot_sources(["ur5"])[0]
        return src, pin.buildModelFromXML(src.urdf)
    text = P.erd_urdf("erd/solo12")
    src = P.RobotSource("solo12", text, "FL_FOOT", "test", floating_base=True)
    return src, pin.buildModelFromXML(text, pin.JointModelFreeFlyer())


@pytest.mark.parametrize("compiled_by", list(USER_OPTIONS))
@pytest.mark.parametrize("name", ["ur5", "solo12"])
def test_user_compile_agrees_with_the_suite_and_pinocchio(name, compiled_by):
    src, model = _source_and_model(name)
    robot, _ = P.jaxkin_robot(src, np.float64)
    layout = P.PinocchioLayout(robot, model)
    qs = random_q(robot, N, seed=1)

    def jacobians(q):
        return jk.geometric_jacobian(robot, q, frame=src.tip)

    program = jax.jit(jax.vmap(jacobians)).lower(jnp.asarray(qs))
    user = np.asarray(program.compile(compiler_options=USER_OPTIONS[compiled_by])(qs))
    suite = np.asarray(program.compile()(qs))  # with the suite's XLA_FLAGS
    np.testing.assert_allclose(user, suite, rtol=0, atol=ULP * max(1.0, np.abs(suite).max()))

    data = model.createData()
    fid = model.getFrameId(src.tip)
    for q, J in zip(qs, user, strict=True):
        pin.computeJointJacobians(model, data, layout.q(q))
        pin.updateFramePlacements(model, data)
        Jp = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        np.testing.assert_allclose(J, layout.columns_to_jaxkin(Jp), rtol=0, atol=1e-12)
