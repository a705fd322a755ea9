"""The code an error message suggests works when pasted.

Each public function that takes one configuration ``q`` (or one Jacobian ``J``) is called with a
batch; the ShapeError it raises suggests code ("... e.g. <code>."). That code is evaluated in a
namespace holding what a user who made the mistake has: ``jax``, ``jk``, ``robot``, the batches
``qs``, ``qds`` (5, dof), ``Js`` (5, 6, dof), ``vs`` (5, 6), and the other arguments of the call
under their parameter names (``point``, ``threshold``, ``wrench``, ...). It must run and return,
for every row, what the function returns for that row (so a hint that calls another function or
drops an argument fails).

Hints known to be wrong are marked ``xfail(strict=True)`` with what is wrong, so that the suite
stays green while they are fixed and the mark must go when they are.

A hint of the form ``jax.vmap(...)(...)`` is evaluated inside ``jax.jit`` (:func:`run_hint`, with
``_xla.FAST_COMPILE``: the same numbers, a cheaper compile): at
top level ``vmap`` runs the function op by op, compiling each primitive (600 compiles, most of
this file's time), and the mapped function sees the same batch tracers either way, so a hint
that raises or gives other numbers when pasted does so here too. Other hints run as pasted.
"""

from __future__ import annotations

import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE

import jaxkin as jk
import jaxkin.testing  # makes jk.testing an attribute

N = 5
# A four-joint arm (revolute and prismatic joints, general twists) for the hints of functions of
# q: what is tested is the hint, the same for every robot, and its kernels compile about twice
# as fast as a six-joint arm's. The wrist functions need a six-joint arm with a spherical wrist
# (the Puma), and the Jacobian batches are the Puma's.
ARM_ROWS = [
    dict(a=0.0, alpha=math.pi / 2, d=0.4, theta=0.0, joint="revolute", lower=-3, upper=3),
    dict(a=0.5, alpha=0.0, d=0.0, theta=0.2, joint="revolute", lower=-2, upper=2, offset=0.1),
    dict(a=0.1, alpha=-math.pi / 2, d=0.2, theta=0.0, joint="prismatic", lower=0, upper=1),
    dict(a=0.0, alpha=math.pi / 2, d=0.3, theta=0.0, joint="revolute", lower=-3, upper=3),
]
PUMA_ONLY = ("jk.wrist_centre(", "jk.wrist_decoupling(")


@pytest.fixture(scope="module")
def arm_ns(ns):
    """``ns`` with ``robot``, ``qs`` and ``qds`` of the four-joint arm (ARM_ROWS)."""
    robot = jk.Robot.from_dh(ARM_ROWS, tool=np.eye(4), name="arm")
    rng = np.random.default_rng(1)
    qs = jnp.asarray(rng.uniform(np.asarray(robot.lower), np.asarray(robot.upper), (N, 4)))
    return {**ns, "robot": robot, "qs": qs, "qds": jnp.asarray(rng.normal(size=qs.shape))}


@pytest.fixture(scope="module")
def ns():
    robot = jk.robots.load("puma560")
    rng = np.random.default_rng(0)  # any batch will do: numpy draws compile nothing
    qs = jnp.asarray(rng.uniform(np.asarray(robot.lower), np.asarray(robot.upper), (N, 6)))
    qds = jnp.asarray(rng.normal(size=qs.shape))
    Js = jnp.stack([jk.geometric_jacobian(robot, q) for q in qs])
    vs = jnp.asarray(rng.normal(size=(N, 6)))
    return {
        "jax": jax,
        "jk": jk,
        "robot": robot,
        "qs": qs,
        "qds": qds,
        "Js": Js,
        "vs": vs,
        # other arguments of the failing calls, as the user would have named them
        "point": [0.0, 0.0, 0.1],
        "threshold": 1e-3,
        "wrench": vs[0],
        "rcond": 1e-6,
        "damping": 0.05,
        "qd_secondary": qds[0],
        "max_damping": 0.05,
    }


def xfail(reason):
    return pytest.mark.xfail(reason=reason, strict=True)


# (failing call, the call for row i). Both are evaluated in the namespace above.
Q_CASES = [
    ("jk.fk(robot, qs)", "jk.fk(robot, qs[i])"),
    ("jk.fk_all(robot, qs)", "jk.fk_all(robot, qs[i])"),
    ("jk.geometric_jacobian(robot, qs)", "jk.geometric_jacobian(robot, qs[i])"),
    ("jk.analytical_jacobian(robot, qs)", "jk.analytical_jacobian(robot, qs[i])"),
    ("jk.jacobian_fwd(robot, qs)", "jk.jacobian_fwd(robot, qs[i])"),
    ("jk.jacobian_rev(robot, qs)", "jk.jacobian_rev(robot, qs[i])"),
    ("jk.jacobians.frame_jacobian(robot, qs)", "jk.jacobians.frame_jacobian(robot, qs[i])"),
    ("jk.twist(robot, qs, qds)", "jk.twist(robot, qs[i], qds[i])"),
    ("jk.point_velocity(robot, qs, qds, point)", "jk.point_velocity(robot, qs[i], qds[i], point)"),
    ("jk.jacobian_dot(robot, qs, qds)", "jk.jacobian_dot(robot, qs[i], qds[i])"),
    ("jk.jacobian_dot_qd(robot, qs, qds)", "jk.jacobian_dot_qd(robot, qs[i], qds[i])"),
    (
        "jk.analytical_jacobian_dot(robot, qs, qds)",
        "jk.analytical_jacobian_dot(robot, qs[i], qds[i])",
    ),
    (
        "jk.analytical_jacobian_dot_qd(robot, qs, qds)",
        "jk.analytical_jacobian_dot_qd(robot, qs[i], qds[i])",
    ),
    ("jk.kinematic_hessian(robot, qs)", "jk.kinematic_hessian(robot, qs[i])"),
    ("jk.manipulability_gradient(robot, qs)", "jk.manipulability_gradient(robot, qs[i])"),
    ("jk.wrist_centre(robot, qs)", "jk.wrist_centre(robot, qs[i])"),
    (
        "jk.testing.finite_difference_jacobian(robot, qs)",
        "jk.testing.finite_difference_jacobian(robot, qs[i])",
    ),
    ("jk.wrist_decoupling(robot, qs, threshold)", "jk.wrist_decoupling(robot, qs[i], threshold)"),
]

J_CASES = [
    ("jk.singular_values(Js)", "jk.singular_values(Js[i])"),
    ("jk.analysis.rank(Js)", "jk.analysis.rank(Js[i])"),
    ("jk.manipulability(Js)", "jk.manipulability(Js[i])"),
    ("jk.condition_number(Js)", "jk.condition_number(Js[i])"),
    ("jk.near_singular(Js, threshold)", "jk.near_singular(Js[i], threshold)"),
    ("jk.dependent_columns(Js)", "jk.dependent_columns(Js[i])"),
    ("jk.velocity_ellipsoid(Js)", "jk.velocity_ellipsoid(Js[i])"),
    ("jk.force_ellipsoid(Js)", "jk.force_ellipsoid(Js[i])"),
    ("jk.joint_torques(Js, wrench)", "jk.joint_torques(Js[i], wrench)"),
    ("jk.pinv_velocity(Js, vs, rcond=rcond)", "jk.pinv_velocity(Js[i], vs[i], rcond=rcond)"),
    (
        "jk.damped_least_squares(Js, vs, damping=damping)",
        "jk.damped_least_squares(Js[i], vs[i], damping=damping)",
    ),
    (
        "jk.adaptive_damping(Js, max_damping=max_damping, threshold=threshold)",
        "jk.adaptive_damping(Js[i], max_damping=max_damping, threshold=threshold)",
    ),
    ("jk.null_space_projector(Js, rcond=rcond)", "jk.null_space_projector(Js[i], rcond=rcond)"),
    (
        "jk.null_space_velocity(Js, vs, qd_secondary, rcond=rcond)",
        "jk.null_space_velocity(Js[i], vs[i], qd_secondary, rcond=rcond)",
    ),
]

_HINT = re.compile(r".*\be\.g\. (.+)\.\s*$", re.DOTALL)


def suggested_code(message: str) -> str:
    """The code after the message's last "e.g. ", up to its final period."""
    m = _HINT.match(message)
    assert m, f"no suggested code in: {message}"
    return m.group(1)


def run_hint(code: str, ns: dict):
    """The hint's value: ``jax.vmap(...)(...)`` compiled as one program (module doc), anything
    else evaluated as pasted."""
    if code.startswith("jax.vmap("):
        return jax.jit(lambda: eval(code, dict(ns)), compiler_options=FAST_COMPILE)()
    return eval(code, dict(ns))


def check_hint(ns, call: str, row: str) -> None:
    with pytest.raises(jk.ShapeError) as info:
        eval(call, dict(ns))
    code = suggested_code(str(info.value))
    try:
        got = run_hint(code, ns)
    except Exception as e:  # the report names the hint and what it raised
        pytest.fail(f"{call}: the suggested {code!r} raised {type(e).__name__}: {e}")
    got = jax.tree_util.tree_map(np.asarray, got)  # rows indexed on the host: no program each
    for i in (0, N - 1):
        want = eval(row, {**ns, "i": i})
        got_i = jax.tree_util.tree_map(lambda x, i=i: x[i], got)
        assert jax.tree_util.tree_structure(got_i) == jax.tree_util.tree_structure(want), (
            f"{call}: the suggested {code!r} returns {jax.tree_util.tree_structure(got)}"
        )
        for g, w in zip(
            jax.tree_util.tree_leaves(got_i), jax.tree_util.tree_leaves(want), strict=True
        ):
            assert np.shape(g) == np.shape(w), (
                f"{call}: the suggested {code!r} gives rows of shape {np.shape(g)}, "
                f"expected {np.shape(w)}"
            )
            np.testing.assert_allclose(
                np.asarray(g), np.asarray(w), rtol=1e-9, atol=1e-12, equal_nan=True, err_msg=code
            )


def _ids(cases) -> list[str]:
    return [c.values[0] if hasattr(c, "marks") else c[0] for c in cases]


@pytest.mark.parametrize(("call", "row"), Q_CASES, ids=_ids(Q_CASES))
def test_batch_of_q_hint_runs(ns, arm_ns, call, row):
    check_hint(ns if call.startswith(PUMA_ONLY) else arm_ns, call, row)


@pytest.mark.parametrize(("call", "row"), J_CASES, ids=_ids(J_CASES))
def test_batch_of_J_hint_runs(ns, call, row):
    check_hint(ns, call, row)


def test_batched_qd_hint_keeps_qd(arm_ns):
    """The twist and J-dot hints used to drop ``qd`` (regression: they now vmap over both)."""
    ns = arm_ns
    for fn in ("twist", "jacobian_dot", "jacobian_dot_qd"):
        with pytest.raises(jk.ShapeError) as info:
            getattr(jk, fn)(ns["robot"], ns["qs"], ns["qds"])
        code = suggested_code(str(info.value))
        assert "qd" in code.split("(qs")[0] and code.endswith("(qs, qds)"), code
        assert jnp.shape(run_hint(code, ns))[0] == N
