"""The non-finite policy ("Non-finite input" in jaxkin.analysis) for every public function of
analysis.py and inverse_velocity.py, and for classify_twist/classify_motion.

A property test per function: hypothesis (the derandomized "ci" profile of conftest, few
examples) picks an argument, an entry of it and NaN, +inf or -inf. Eagerly the call raises a
JaxkinError naming that argument; under ``jax.jit`` the result is poisoned (every float NaN, every
flag True, every count -1); under ``jax.jit(jax.vmap(...))`` over a batch of a clean and the
corrupted input only the corrupted item is poisoned, the clean one equals the single call.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk
from jaxkin import analysis

PLANAR = jk.robots.load("two_link_planar", dtype=np.float64)
WRIST = jk.robots.load("cylindrical_spherical_wrist", dtype=np.float64)

_rng = np.random.default_rng(7)
J = _rng.standard_normal((6, 6))
V = _rng.standard_normal(6)
Q_WRIST = np.array([0.3, 0.4, 0.5, 0.2, 0.7, -0.4])
T0 = np.asarray(jk.fk(PLANAR, jnp.array([0.4, 1.1])))
PATH = np.stack([T0, T0, T0])


def _dls(J, v, damping, joint_weights):
    return jk.damped_least_squares(J, v, damping=damping, joint_weights=joint_weights)


def _rrc(q0, T_path):
    return jk.resolved_rate_control(PLANAR, q0, T_path, 0.01)


# name -> (function of keyword arrays, the arrays); every array is corrupted in turn
CASES = {
    "singular_values": (lambda J: jk.singular_values(J, "translation"), {"J": J}),
    "rank": (lambda J: analysis.rank(J), {"J": J}),
    **{
        f"manipulability/{m}": (lambda J, m=m: jk.manipulability(J, m), {"J": J})
        for m in analysis.MEASURES
    },
    "condition_number": (jk.condition_number, {"J": J}),
    "near_singular": (
        lambda J, threshold: jk.near_singular(J, threshold),
        {"J": J, "threshold": np.array(1e-3)},
    ),
    "dependent_columns": (jk.dependent_columns, {"J": J[:, :4] @ _rng.standard_normal((4, 6))}),
    "velocity_ellipsoid": (jk.velocity_ellipsoid, {"J": J}),
    "force_ellipsoid": (jk.force_ellipsoid, {"J": J}),
    "joint_torques": (jk.joint_torques, {"J": J, "wrench": V}),
    "manipulability_gradient": (
        lambda q, point: jk.manipulability_gradient(PLANAR, q, rows=(0, 1), point=point),
        {"q": np.array([0.4, 1.1]), "point": np.array([0.1, 0.0, 0.0])},
    ),
    "wrist_centre": (lambda q: jk.wrist_centre(WRIST, q), {"q": Q_WRIST}),
    "wrist_decoupling": (
        lambda q, threshold: jk.wrist_decoupling(WRIST, q, threshold),
        {"q": Q_WRIST, "threshold": np.array(1e-6)},
    ),
    "pinv_velocity": (lambda J, v: jk.pinv_velocity(J, v, rcond=1e-6), {"J": J, "v": V}),
    "damped_least_squares": (
        _dls,
        {"J": J, "v": V, "damping": np.array(0.05), "joint_weights": np.linspace(1.0, 2.0, 6)},
    ),
    "adaptive_damping": (
        lambda J: jk.adaptive_damping(J, max_damping=0.1, threshold=0.2),
        {"J": J},
    ),
    "null_space_projector": (
        lambda J, damping: jk.null_space_projector(J, damping=damping),
        {"J": J[:4], "damping": np.array(0.05)},
    ),
    "null_space_velocity": (
        lambda J, v, qd_secondary: jk.null_space_velocity(J, v, qd_secondary, rcond=1e-6),
        {"J": J[:4], "v": V[:4], "qd_secondary": V[::-1].copy()},
    ),
    "resolved_rate_control": (_rrc, {"q0": np.array([0.4, 1.1]), "T_path": PATH}),
}

_BAD = st.sampled_from([np.nan, np.inf, -np.inf])


@functools.cache
def _jitted(name):
    """``(kw, batch) -> (f(**kw), vmap(f)(batch))``: the single and the batched call in one
    program (one compile per function instead of two; each output is what its own jit gives)."""
    f = CASES[name][0]

    def both(kw, batch):
        return f(**kw), jax.vmap(lambda kw: f(**kw))(batch)

    return jax.jit(both, compiler_options=FAST_COMPILE)


@functools.cache
def _eager_clean(name):
    """The eager call on the clean inputs (the same for every example: computed once; op by op
    a robot-level function dispatches hundreds of primitives)."""
    f, clean = CASES[name]
    return jax.tree_util.tree_map(np.asarray, f(**clean))


def _corrupt(data, inputs):
    arg = data.draw(st.sampled_from(sorted(inputs)), label="argument")
    x = np.array(inputs[arg], dtype=np.float64)
    i = data.draw(st.integers(0, x.size - 1), label="entry")
    x.reshape(-1)[i] = data.draw(_BAD, label="value")
    return arg, {**inputs, arg: x}


def _assert_poisoned(tree, what):
    leaves = jax.tree_util.tree_leaves(tree)
    assert leaves, what
    for x in map(np.asarray, leaves):
        if x.dtype.kind == "f":
            assert np.all(np.isnan(x)), (what, x)
        elif x.dtype.kind == "b":
            assert np.all(x), (what, x)
        else:
            assert x.dtype.kind in "iu" and np.all(x == -1), (what, x)


def _assert_same(a, b, what):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-12, atol=1e-12,
                                   err_msg=what)  # fmt: skip


@pytest.mark.parametrize("name", sorted(CASES))
@settings(max_examples=4)
@given(data=st.data())
def test_nonfinite_input_raises_eagerly_and_poisons_under_jit_and_vmap(name, data):
    f, clean = CASES[name]
    arg, dirty = _corrupt(data, clean)
    with pytest.raises(jk.JaxkinError, match=rf"{arg} contains NaN or inf"):
        f(**dirty)
    program = _jitted(name)
    # numpy in, numpy out: the jitted programs take numpy arrays as they are, and stacking or
    # indexing jax arrays eagerly would compile a program per primitive and shape
    clean_j = {k: np.asarray(v, dtype=np.float64) for k, v in clean.items()}
    dirty_j = {k: np.asarray(v, dtype=np.float64) for k, v in dirty.items()}
    bad_first = data.draw(st.booleans(), label="bad item first")
    order = (dirty_j, clean_j) if bad_first else (clean_j, dirty_j)
    batch = jax.tree_util.tree_map(lambda a, b: np.stack([a, b]), *order)
    reference, out = program(clean_j, batch)  # the clean input's single call, and the batch
    # the clean call is finite (else the poisoning below proves nothing) and matches eager
    for x in jax.tree_util.tree_leaves(reference):
        assert np.all(np.isfinite(np.asarray(x, dtype=float))), name
    _assert_same(reference, _eager_clean(name), name)
    _assert_poisoned(program(dirty_j, batch)[0], f"{name} jit, {arg} corrupted")
    out = jax.tree_util.tree_map(np.asarray, out)
    bad, good = (0, 1) if bad_first else (1, 0)
    _assert_poisoned(jax.tree_util.tree_map(lambda x: x[bad], out), f"{name} vmap bad item")
    _assert_same(jax.tree_util.tree_map(lambda x: x[good], out), reference, f"{name} vmap clean")


def test_exact_singularities_are_finite_input():
    """The policy is about NaN and inf, not singularity: the zero Jacobian is answered."""
    Z = jnp.zeros((6, 6))
    assert int(analysis.rank(Z)) == 0 and int(jk.dependent_columns(Z).nullity) == 6
    assert bool(jk.near_singular(Z, 1e-3)) and float(jk.manipulability(Z, "inverse_condition")) == 0
    assert float(jk.condition_number(Z)) == np.inf
    assert int(jax.jit(analysis.rank)(Z)) == 0


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_classify_refuses_nonfinite_and_traced_input(value):
    Vt = np.array([0.0, 0.0, 0.1, 0.0, 0.0, 1.0])
    assert jk.classify_twist(Vt) == "general"
    with pytest.raises(jk.JaxkinError, match="V contains NaN or inf"):
        jk.classify_twist(np.where(np.arange(6) == 4, value, Vt))
    with pytest.raises(jk.JaxkinError, match="tol contains NaN or inf"):
        jk.classify_twist(Vt, tol=value)
    with pytest.raises(jk.JaxkinError, match="outside jit"):
        jax.jit(jk.classify_twist)(jnp.asarray(Vt))
    Ts = np.stack([np.eye(4), np.eye(4)])
    assert jk.classify_motion(Ts) == "rest"
    Ts[1, 0, 3] = value
    with pytest.raises(jk.JaxkinError, match="Ts contains NaN or inf"):
        jk.classify_motion(Ts)
    with pytest.raises(jk.JaxkinError, match="outside jit"):
        jax.jit(jk.classify_motion)(jnp.stack([jnp.eye(4), jnp.eye(4)]))
