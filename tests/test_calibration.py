"""Kinematic calibration: recover perturbed parameters from noisy synthetic pose measurements.

The demonstration of ISSUE 5: the Niryo One's joint zero offsets and link lengths are perturbed
(offsets by ~1e-2 rad, lengths by ~1e-3 m), 100 poses of the perturbed robot are "measured" with
Gaussian noise (0.1 mm per axis, 0.1 mrad per axis), and ``jk.calibrate`` starting from the
nominal model recovers the perturbed values to within the noise: every error after the fit is
below 4 predicted standard deviations (Gauss-Newton covariance), about 1e-5, against 1e-3..1e-2
before. A DH robot (two-link planar arm) is recovered exactly from noise-free data, its base
transform too; unidentifiable choices are refused with the parameters named.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from _sampling import sample_configurations
from _xla import FAST_COMPILE

import jaxkin as jk
from jaxkin import spatial

SIGMA_P = 1e-4  # m, per axis
SIGMA_O = 1e-4  # rad, per axis
M = 100
M_PLANAR = 10  # poses of the two-link arm's data sets: one set of shapes for all of them
# Plain gradient descent, one object for the file (optimisers hash by identity: one compiled fit
# per robot, masks and max_steps), where the fit's outcome is not under test: its loop traces and
# compiles in a fraction of the default L-BFGS's (line search included).
_SGD = optax.sgd(1e-7)


def _measure(robot: jk.Robot, qs: np.ndarray, noise: np.ndarray | None) -> jax.Array:
    """Poses of ``robot`` at ``qs``, perturbed by ``noise`` (M, 6) (standard normal draws scaled
    by SIGMA_P and SIGMA_O), or exact for None: one compiled program per robot (the robot a
    constant of it), not hundreds of primitives dispatched op by op."""
    return _measure_kernel(robot, jnp.asarray(qs), None if noise is None else jnp.asarray(noise))


@functools.partial(jax.jit, static_argnums=0, compiler_options=FAST_COMPILE)
def _measure_kernel(robot: jk.Robot, qs: jax.Array, noise: jax.Array | None) -> jax.Array:
    Ts = jax.vmap(lambda q: jk.fk(robot, q))(qs)
    if noise is None:
        return Ts

    def perturb(T, n):
        R = T[:3, :3] @ spatial.exp_so3(n[3:] * SIGMA_O)
        return spatial.make_transform(R, T[:3, 3] + n[:3] * SIGMA_P)

    return jax.vmap(perturb)(Ts, noise)


def niryo_calibration_set():
    """Joint zero offsets of joints 1..6 and the link lengths along the arm: shoulder height
    (joint 2 z), upper arm (joint 3 x), elbow offset (joint 4 y), forearm (joint 5 z) and wrist
    offset (joint 6 x). Joint 4's x offset (0.037 m) is left out: it lies along joint 4's axis,
    like the forearm length, so only their sum is observable (checked below)."""
    xyz = np.zeros((8, 3), bool)
    xyz[2, 2] = xyz[3, 0] = xyz[4, 1] = xyz[5, 2] = xyz[6, 0] = True
    offset = np.zeros(8, bool)
    offset[1:7] = True
    return {"xyz": xyz, "offset": offset}


def test_recovers_perturbed_niryo_one_parameters_from_noisy_poses():
    nominal = jk.robots.load("niryo_one", dtype=np.float64)
    masks = niryo_calibration_set()
    rng = np.random.default_rng(0)
    xyz = np.asarray(nominal.params["xyz"]).copy()
    xyz[masks["xyz"]] += rng.normal(0.0, 2e-3, masks["xyz"].sum())
    offset = np.asarray(nominal.offset).copy()
    offset[masks["offset"]] += rng.normal(0.0, 1e-2, masks["offset"].sum())
    true = nominal.replace(
        params={**nominal.params, "xyz": jnp.asarray(xyz)}, offset=jnp.asarray(offset)
    )
    qs = sample_configurations(nominal, M, 1)
    Ts = _measure(true, qs, rng.normal(size=(M, 6)))

    res = jk.calibrate(nominal, qs, Ts, masks, position_sigma=SIGMA_P, orientation_sigma=SIGMA_O)
    assert bool(res.converged)
    err_before = {
        "xyz": np.abs(np.asarray(nominal.params["xyz"]) - xyz)[masks["xyz"]],
        "offset": np.abs(np.asarray(nominal.offset) - offset)[masks["offset"]],
    }
    for name in ("xyz", "offset"):
        fitted = np.asarray(res.params[name])[masks[name]]
        truth = (xyz if name == "xyz" else offset)[masks[name]]
        std = np.asarray(res.std[name])[masks[name]]
        err = np.abs(fitted - truth)
        assert np.all(std > 0) and np.all(std < 2e-4), (name, std)
        assert np.all(err <= 4 * std), (name, err / std)  # within the noise
        assert np.all(err < 2e-4), (name, err)
        assert err.max() < err_before[name].max() / 10, (name, err, err_before[name])
    # residuals fall from millimetres to the noise: rms of 3-d noise = sqrt(3) sigma
    assert float(res.rms_position_before) > 1e-3
    assert float(res.rms_position_after) == pytest.approx(math.sqrt(3) * SIGMA_P, rel=0.2)
    assert float(res.rms_orientation_after) == pytest.approx(math.sqrt(3) * SIGMA_O, rel=0.2)
    # the calibrated robot is a robot: its poses match the truth to the noise level
    T_fit = _measure(res.robot, qs, None)
    T_true = _measure(true, qs, None)
    assert float(jnp.max(jnp.abs(T_fit[:, :3, 3] - T_true[:, :3, 3]))) < 1e-4
    hist = np.asarray(res.loss_history)[: int(res.steps) - 1]
    assert np.all(np.isfinite(hist)) and hist[-1] < hist[0]


def test_identifiability_names_what_the_data_cannot_see():
    nominal = jk.robots.load("niryo_one", dtype=np.float64)
    # the configurations of the recovery test above: its regressor program is reused
    qs = sample_configurations(nominal, M, 1)
    masks = niryo_calibration_set()
    assert jk.identifiability(nominal, qs, masks).unidentifiable == []
    # joint 4's x offset and the forearm length both lie along joint 4's axis
    both = {k: v.copy() for k, v in masks.items()}
    both["xyz"][4, 0] = True
    ident = jk.identifiability(nominal, qs, both)
    assert ident.unidentifiable == ["xyz[5, 2]"]
    assert ident.rank == len(ident.names) - 1
    Ts = _measure(nominal, qs, None)
    with pytest.raises(jk.JaxkinError, match=r"xyz\[5, 2\]"):
        jk.calibrate(nominal, qs, Ts, both)


def test_dh_parameters_and_base_recovered_exactly_without_noise():
    nominal = jk.robots.load("two_link_planar", a1=1.0, a2=0.7, dtype=np.float64)
    # link lengths, the second joint's zero and a misplaced base (x, y, yaw); the first joint's
    # zero would duplicate the base yaw, so it stays fixed
    base = np.asarray(spatial.make_transform(spatial.rot_z(0.03), jnp.array([0.01, -0.02, 0.0])))
    true = nominal.replace(
        params={**nominal.params, "a": jnp.array([1.013, 0.688])},
        offset=jnp.array([0.0, -0.015]),
        base=jnp.asarray(base),
    )
    qs = sample_configurations(nominal, M_PLANAR, 3)  # shapes shared with the tests below
    Ts = _measure(true, qs, None)
    params = {
        "a": np.array([True, True]),
        "offset": np.array([False, True]),
        "base": np.array([True, True, False, False, False, True]),
    }
    res = jk.calibrate(nominal, qs, Ts, params)
    np.testing.assert_allclose(np.asarray(res.params["a"]), [1.013, 0.688], rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(res.params["offset"]), [0.0, -0.015], atol=1e-9)
    np.testing.assert_allclose(np.asarray(res.params["base"]), base, atol=1e-9)
    assert float(res.rms_position_after) < 1e-9
    assert float(res.rms_position_before) > 1e-3
    # with both zeros free, the base yaw (listed after them) adds nothing the first zero does not
    params["offset"] = np.array([True, True])
    assert jk.identifiability(nominal, qs, params).unidentifiable == ["base[5]"]
    # ... which calibrate refuses, fits anyway when asked, and reports (its identifiability
    # check runs the regressor program compiled just above). The report is what is tested, not
    # the fit: one step of plain gradient descent, whose loop compiles in a fraction of L-BFGS's
    with pytest.raises(jk.JaxkinError, match=r"base\[5\]"):
        jk.calibrate(nominal, qs, Ts, params)
    res = jk.calibrate(
        nominal, qs, Ts, params, check_identifiable=False, optimizer=_SGD, max_steps=1
    )
    assert not bool(res.identifiable) and int(res.steps) == 1


def test_errors():
    robot = jk.robots.load("two_link_planar", dtype=np.float64)
    qs = np.zeros((5, 2))
    Ts = np.broadcast_to(np.eye(4), (5, 4, 4))
    with pytest.raises(jk.JaxkinError, match="no calibratable parameter 'xyz'"):
        jk.calibrate(robot, qs, Ts, ["xyz"])
    with pytest.raises(jk.ShapeError, match=r"Ts_measured must have shape \(5, 4, 4\)"):
        jk.calibrate(robot, qs, Ts[:3], ["a"])
    with pytest.raises(jk.ShapeError, match="mask of 'a'"):
        jk.calibrate(robot, qs, Ts, {"a": np.ones(3, bool)})
    with pytest.raises(jk.JaxkinError, match="no tool"):
        jk.calibrate(robot, qs, Ts, ["tool"])


def test_batched_over_datasets_with_vmap():
    nominal = jk.robots.load("two_link_planar", dtype=np.float64)
    true_a = np.asarray(nominal.params["a"])[None] * np.array([[1.01, 0.99], [0.98, 1.02]])
    # M = 10 poses per data set, as _planar_data's: the fit, residual and regressor programs the
    # batched fit traces (one data set's shapes) are those the tests below trace for the same
    # robot and parameters, traced once for the file
    qs = np.stack([sample_configurations(nominal, M_PLANAR, k) for k in (4, 5)])
    Ts = jnp.stack(
        [
            _measure(nominal.replace(params={**nominal.params, "a": jnp.asarray(a)}), q, None)
            for a, q in zip(true_a, qs, strict=True)
        ]
    )
    free = {"a": np.array([True, True])}
    # one program for the whole batched fit (eagerly, vmap would compile each of calibrate's
    # inner programs batched and run the rest op by op)
    fit = jax.jit(
        jax.vmap(
            lambda q, T: jk.calibrate(nominal, q, T, free, check_identifiable=False).params["a"]
        ),
        compiler_options=FAST_COMPILE,
    )
    fitted = fit(jnp.asarray(qs), Ts)
    np.testing.assert_allclose(np.asarray(fitted), true_a, rtol=0, atol=1e-9)
    with pytest.raises(jk.JaxkinError, match="check_identifiable=False"):
        jax.vmap(lambda q, T: jk.calibrate(nominal, q, T, free).params["a"])(jnp.asarray(qs), Ts)


# ----------------------------------------------------------------------------- refused data, status
def _planar_data(m=M_PLANAR, seed=6):
    robot = jk.robots.load("two_link_planar", dtype=np.float64)
    qs = sample_configurations(robot, m, seed)
    true = robot.replace(params={**robot.params, "a": robot.params["a"] * 1.01})
    return robot, qs, _measure(true, qs, None)


def test_refuses_empty_transposed_and_nonfinite_measurements():
    robot, qs, Ts = _planar_data()
    with pytest.raises(jk.JaxkinError, match="no measurements"):
        jk.calibrate(robot, qs[:0], Ts[:0], ["a"])
    with pytest.raises(jk.JaxkinError, match="no measurements"):
        jk.identifiability(robot, qs[:0], ["a"])
    # transposed poses: the rotation block is still orthonormal but the translation sits in the
    # last row, so the offsets would be fitted to nonsense
    with pytest.raises(jk.JaxkinError, match=r"Ts_measured\[0\] is not a rigid transform"):
        jk.calibrate(robot, qs, jnp.swapaxes(Ts, 1, 2), ["a", "offset"], check_identifiable=False)
    with pytest.raises(jk.JaxkinError, match="Ts_measured contains NaN or inf"):
        jk.calibrate(robot, qs, Ts.at[3, 0, 3].set(jnp.inf), ["a"])
    with pytest.raises(jk.JaxkinError, match="qs contains NaN or inf"):
        jk.calibrate(robot, np.where(np.arange(qs.size).reshape(qs.shape) == 5, np.nan, qs), Ts,
                     ["a"])  # fmt: skip
    with pytest.raises(jk.JaxkinError, match="qs contains NaN or inf"):
        jk.identifiability(robot, np.full_like(qs, np.nan), ["a"])


def test_status_nan_loss_and_step_budget():
    import optax

    robot, qs, Ts = _planar_data()
    res = jk.calibrate(robot, qs, Ts, ["a"])
    assert bool(res.converged) and bool(res.identifiable)
    # an optimiser whose step is NaN: the loss becomes NaN, which is not convergence
    nan_step = optax.with_extra_args_support(
        optax.stateless(lambda g, p: jax.tree_util.tree_map(lambda x: x * jnp.nan, g))
    )
    res = jk.calibrate(robot, qs, Ts, ["a"], optimizer=nan_step)
    assert np.isnan(np.asarray(res.loss_history)).any() and not bool(res.converged)
    # the step budget runs out before the loss settles (gradient descent's small steps: the
    # loop's budget, not the optimiser, is under test)
    res = jk.calibrate(robot, qs, Ts, ["a"], optimizer=_SGD, max_steps=2)
    assert int(res.steps) == 2 and not bool(res.converged)
    assert np.all(np.isfinite(np.asarray(res.loss_history)[:1]))
    # unidentifiable, fitted anyway when asked, and reported: in the DH test above


def test_under_jit_nonfinite_data_do_not_converge():
    robot, qs, Ts = _planar_data()
    fit = jax.jit(
        lambda q, T: jk.calibrate(robot, q, T, ["a"], check_identifiable=False),
        compiler_options=FAST_COMPILE,
    )
    # The report of the fit (fitted robot, values, stds, RMS errors) is one compiled program,
    # cached like the fit, not dozens of operations run (and compiled per shape) one by one: in
    # the trace (which the call below reuses) each of those outputs comes straight out of it.
    traced = fit.trace(jnp.asarray(qs), Ts)
    eqns = traced.jaxpr.eqns
    programs = [e.params["name"] for e in eqns if e.primitive.name in ("jit", "pjit")]
    assert [p for p in programs if p != "_where"] == [
        "_fit_impl", "_regressor_impl", "_summary_impl"
    ], programs  # fmt: skip
    summary = next(e for e in eqns if e.params.get("name") == "_summary_impl").outvars
    out = jax.tree_util.tree_unflatten(
        jax.tree_util.tree_structure(traced.out_info), traced.jaxpr.jaxpr.outvars
    )
    report = (out.robot, out.params, out.std, out.rms_position_before, out.rms_position_after,
              out.rms_orientation_before, out.rms_orientation_after)  # fmt: skip
    assert all(any(v is s for s in summary) for v in jax.tree_util.tree_leaves(report))
    good = fit(jnp.asarray(qs), Ts)
    assert bool(good.converged)
    np.testing.assert_allclose(np.asarray(good.params["a"]), np.asarray(robot.params["a"]) * 1.01,
                               rtol=0, atol=1e-9)  # fmt: skip
    for q, T in ((jnp.asarray(qs).at[2, 1].set(jnp.nan), Ts), (qs, Ts.at[0, 1, 3].set(jnp.inf))):
        res = fit(jnp.asarray(q), T)
        assert not bool(res.converged) and not bool(res.identifiable)
        assert np.all(np.isnan(np.asarray(res.params["a"])))
