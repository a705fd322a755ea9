"""Singularities, manipulability, ellipsoids, wrist decoupling and statics.

Oracles: NumPy's SVD and determinant (away from singularities), the Robotics Toolbox's
``manipulability`` and ``jacobm`` (Panda), the closed form ``dm/dq_k = m vec(J H_k^T) .
vec((J J^T)^-1)`` (Haviland & Corke 2022) and central finite differences; the singular
configurations are exact (UR5 q5 = 0, two-link arm stretched) and differentiated there.
"""

from __future__ import annotations

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sampling import sample_configurations
from _xla import FAST_COMPILE, jaxpr_eqns
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk
from jaxkin import analysis

N_WRIST = 2000
SEED = 5
ROWS = ("all", "translation", "rotation")


# ------------------------------------------------------------------------- UR5 wrist singularity
@pytest.fixture(scope="module")
def ur5_wrist():
    """UR5 at q5 = 0 (joints 4 and 6 aligned) with thousands of random other joints."""
    robot = jk.robots.load("ur5", dtype=np.float64)
    qs = sample_configurations(robot, N_WRIST, SEED)
    qs[:, 4] = 0.0

    def one(q):
        J = jk.geometric_jacobian(robot, q)
        out = {"J": J, "s": jk.singular_values(J), "rank": analysis.rank(J, rtol=1e-9)}
        for m in analysis.MEASURES:
            for r in ROWS:
                out[f"{m}/{r}"] = jk.manipulability(J, m, r)
                out[f"grad/{m}/{r}"] = jk.manipulability_gradient(robot, q, m, r)
        out["dep"] = jk.dependent_columns(J, rtol=1e-9).mask
        return out

    kernel = jax.jit(jax.vmap(one), compiler_options=FAST_COMPILE)
    out = jax.tree_util.tree_map(np.asarray, kernel(jnp.asarray(qs)))
    return robot, qs, out


def test_manipulability_never_nan_and_nonnegative_at_ur5_wrist_singularity(ur5_wrist):
    _, _, out = ur5_wrist
    for m in analysis.MEASURES:
        for r in ROWS:
            v = out[f"{m}/{r}"]
            assert np.all(np.isfinite(v)), (m, r)
            assert np.all(v >= 0.0), (m, r)
            g = out[f"grad/{m}/{r}"]
            assert np.all(np.isfinite(g)), (m, r)
    # The full 6x6 Jacobian is singular: every all-rows measure vanishes (to rounding).
    scale = np.max(out["s"][:, 0])
    assert np.all(out["yoshikawa/all"] <= 1e-14 * scale**6)
    assert np.all(out["min_singular_value/all"] <= 1e-14 * scale)
    assert np.all(out["rank"] == 5)


def test_yoshikawa_is_the_product_of_singular_values(ur5_wrist):
    _, _, out = ur5_wrist
    J = out["J"]
    s_np = np.linalg.svd(J, compute_uv=False)
    np.testing.assert_allclose(out["s"], s_np, rtol=0, atol=1e-13)
    np.testing.assert_allclose(out["yoshikawa/all"], np.prod(s_np, axis=1), rtol=0, atol=1e-15)
    for r, sl in (("translation", slice(0, 3)), ("rotation", slice(3, 6))):
        s_r = np.linalg.svd(J[:, sl], compute_uv=False)
        np.testing.assert_allclose(out[f"yoshikawa/{r}"], np.prod(s_r, axis=1), rtol=1e-12)
        # away from their own singularities the sub-blocks also equal sqrt(det(J J^T))
        # (sqrt(det) is the less accurate side: about eps * cond(J J^T) relative, so only
        # configurations with a block condition number below 100 are compared)
        away = s_r[:, -1] > 1e-2 * s_r[:, 0]
        assert away.mean() > 0.5
        det = np.linalg.det(J[away][:, sl] @ np.swapaxes(J[away][:, sl], 1, 2))
        np.testing.assert_allclose(
            out[f"yoshikawa/{r}"][away], np.sqrt(np.abs(det)), rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(
            out[f"inverse_condition/{r}"], s_r[:, -1] / s_r[:, 0], rtol=1e-12, atol=1e-15
        )
        np.testing.assert_allclose(out[f"min_singular_value/{r}"], s_r[:, -1], atol=1e-14)


def test_dependent_columns_at_ur5_wrist_singularity(ur5_wrist):
    # q5 = 0 aligns joint 6 with joints 2, 3, 4 (all parallel): their columns span only 3
    # dimensions, and those four are the dependent ones.
    _, _, out = ur5_wrist
    expected = np.array([False, True, True, True, False, True])
    frac = np.mean(np.all(out["dep"] == expected, axis=1))
    assert frac >= 0.99, frac


def test_gradients_finite_exactly_at_singular_configurations():
    planar = jk.robots.load("two_link_planar", dtype=np.float64)
    ur5 = jk.robots.load("ur5", dtype=np.float64)

    @jax.jit(compiler_options=FAST_COMPILE)
    def grads(q2, q6):
        out = {}
        for m in analysis.MEASURES:
            for rows in ("all", "translation", (0, 1)):
                out[f"planar/{m}/{rows}"] = jk.manipulability_gradient(planar, q2, m, rows)
            out[f"ur5/{m}"] = jk.manipulability_gradient(ur5, q6, m, "all")
            # and with respect to J itself, at the zero matrix
            out[f"zero/{m}"] = jax.grad(lambda J, m=m: jk.manipulability(J, m))(jnp.zeros((6, 6)))
        out["planar/m"] = jk.manipulability(jk.geometric_jacobian(planar, q2), rows=(0, 1))
        return out

    for q2 in (jnp.zeros(2), jnp.array([0.3, math.pi])):  # stretched, folded
        out = jax.tree_util.tree_map(np.asarray, grads(q2, jnp.array(ur5.configurations["qz"])))
        for k, v in out.items():
            assert np.all(np.isfinite(v)), k
        assert out["planar/m"] == pytest.approx(0.0, abs=1e-15)
    # stretched: m = |a1 a2 sin(q2)|, so |dm/dq2| = a1 a2 = 1 (a one-sided derivative)
    out = grads(jnp.zeros(2), jnp.zeros(6))
    assert abs(float(out["planar/yoshikawa/(0, 1)"][1])) == pytest.approx(1.0, abs=1e-12)


def test_manipulability_gradient_matches_closed_form_toolbox_and_fd():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        rtb = pytest.importorskip("roboticstoolbox")
    robot = jk.robots.load("panda", dtype=np.float64)
    model = rtb.models.DH.Panda()
    model.tool = np.asarray(robot.tool)
    qs = sample_configurations(robot, 3, 1)
    h = 1e-6

    @jax.jit(compiler_options=FAST_COMPILE)
    def kernel(q):
        J = jk.geometric_jacobian(robot, q)
        steps = h * jnp.eye(7)
        m_of = jax.vmap(lambda qq: jk.manipulability(jk.geometric_jacobian(robot, qq)))
        return (
            J,
            jk.kinematic_hessian(robot, q),
            jk.manipulability(J),
            jk.manipulability_gradient(robot, q),
            # the row subsets (all rows: the default call above)
            {r: jk.manipulability_gradient(robot, q, "yoshikawa", r) for r in ROWS[1:]},
            (m_of(q[None] + steps) - m_of(q[None] - steps)) / (2 * h),
        )

    for q in qs:
        J, H, m, g, g_rows, fd = jax.tree_util.tree_map(np.asarray, kernel(jnp.asarray(q)))
        inv = np.linalg.inv(J @ J.T)
        closed = np.array([m * np.sum((J @ H[k].T) * inv) for k in range(7)])
        np.testing.assert_allclose(g, closed, rtol=1e-9, atol=1e-12)
        assert m == pytest.approx(model.manipulability(q), rel=1e-12)
        np.testing.assert_allclose(g, model.jacobm(q).ravel(), rtol=1e-9, atol=1e-12)
        for r, axes in (("translation", "trans"), ("rotation", "rot")):
            np.testing.assert_allclose(
                g_rows[r], model.jacobm(q, axes=axes).ravel(), rtol=1e-9, atol=1e-12
            )
        np.testing.assert_allclose(g, fd, rtol=0, atol=1e-7)


def test_manipulability_gradients_trace_the_jacobian_once():
    # Every gradient of one robot and frame uses the same traced (and differentiated) Jacobian
    # program, whatever the measure: traced once per computation, not once per call.
    planar = jk.robots.load("two_link_planar", dtype=np.float64)

    def grads(q):
        return [jk.manipulability_gradient(planar, q, m) for m in analysis.MEASURES]

    eqns = jaxpr_eqns(grads, jnp.zeros(2))
    calls = [e for e in eqns if "jacobian_matrix" in str(e.params.get("name"))]
    assert len(calls) >= len(analysis.MEASURES)
    # one program for the linearised pass, one for its transpose, each shared by the measures
    assert len({id(e.params["jaxpr"]) for e in calls}) <= 2


@jax.jit(compiler_options=FAST_COMPILE)
def _flags_of(J, tall):
    """The measures, ranks and flags of the test below as one program (op by op, each call
    compiled its primitives anew: 55 compiles)."""
    return {
        "w": jk.manipulability(J),
        "inv": jk.manipulability(J, "inverse_condition"),
        "min": jk.manipulability(J, "min_singular_value"),
        "w_t": jk.manipulability(J, rows="translation"),
        "w_r": jk.manipulability(J, rows="rotation"),
        "rank": analysis.rank(J),
        "rank_rtol": analysis.rank(J, rtol=1e-6),
        "rank_atol": analysis.rank(J, atol=0.6),
        "near": jk.near_singular(J, 1e-6),
        "near_t": jk.near_singular(J, 1e-6, rows="translation"),
        "near_ic": jk.near_singular(J, 0.1, measure="inverse_condition"),
        "cond": jk.condition_number(J),
        "cond0": jk.condition_number(jnp.zeros((6, 6))),
        "tall": {m: jk.manipulability(tall, m) for m in analysis.MEASURES},
        "square": jk.manipulability(tall[:2] * 0 + jnp.eye(2), rows=(0, 1)),
    }


def test_measures_rank_and_near_singular_flag():
    J = jnp.diag(jnp.array([2.0, 1.0, 0.5, 1e-9, 3.0, 1.0]))
    # m > dof: the task-space ellipsoid is flat, every measure is 0 (as sqrt(det(J J^T)))
    tall = jnp.ones((6, 2)) * jnp.array([[1.0, 2.0]])
    out = _flags_of(J, tall)
    assert float(out["w"]) == pytest.approx(2 * 1 * 0.5 * 1e-9 * 3 * 1, rel=1e-12)
    assert float(out["inv"]) == pytest.approx(1e-9 / 3, rel=1e-12)
    assert float(out["min"]) == pytest.approx(1e-9, rel=1e-12)
    assert float(out["w_t"]) == pytest.approx(1.0, rel=1e-12)
    assert float(out["w_r"]) == pytest.approx(3e-9, rel=1e-12)
    assert int(out["rank"]) == 6
    assert int(out["rank_rtol"]) == 5
    assert int(out["rank_atol"]) == 4
    assert bool(out["near"])
    assert not bool(out["near_t"])
    assert bool(out["near_ic"])
    assert float(out["cond"]) == pytest.approx(3e9, rel=1e-9)
    assert float(out["cond0"]) == math.inf
    for m in analysis.MEASURES:
        assert float(out["tall"][m]) == 0.0
    assert float(out["square"]) == 1.0


@jax.jit(compiler_options=FAST_COMPILE)
def _scattered_rows(J):
    """Rows given out of order and in separate runs (selected as slices joined together), and
    the same rows taken out first."""
    rows, Jr = (4, 0, 1, 5), J[jnp.array([4, 0, 1, 5])]
    return {
        "s": (jk.singular_values(J, rows), jk.singular_values(Jr)),
        "grad": (
            jax.grad(lambda J: jk.manipulability(J, rows=rows))(J),
            jax.grad(jk.manipulability)(Jr),
        ),
        "dep": (jk.dependent_columns(J, rows).nullity, jk.dependent_columns(Jr).nullity),
    }


def test_rows_in_any_order_select_those_rows():
    J = np.random.default_rng(3).normal(size=(6, 5))
    J[4] = 2.0 * J[0]  # rank 3 in the selected rows
    out = jax.tree_util.tree_map(np.asarray, _scattered_rows(J))
    s, s_ref = out["s"]
    np.testing.assert_array_equal(s, s_ref)
    np.testing.assert_allclose(s, np.linalg.svd(J[[4, 0, 1, 5]], compute_uv=False), atol=1e-14)
    assert tuple(out["dep"]) == (2, 2)
    g, g_ref = out["grad"]
    np.testing.assert_array_equal(g[[2, 3]], 0.0)  # rows not selected
    np.testing.assert_allclose(g[[4, 0, 1, 5]], g_ref, rtol=0, atol=1e-15)


def test_velocity_and_force_ellipsoids():
    robot = jk.robots.load("puma560", dtype=np.float64)
    q = jnp.array([0.1, 0.7, -0.4, 0.3, 0.6, -0.2])
    cases = (("translation", slice(0, 3)), ("rotation", slice(3, 6)), ("all", slice(0, 6)))

    @jax.jit(compiler_options=FAST_COMPILE)  # one program (op by op: each SVD shape compiles)
    def ellipsoids(q):
        J = jk.geometric_jacobian(robot, q)
        return J, {r: (jk.velocity_ellipsoid(J, r), jk.force_ellipsoid(J, r)) for r, _ in cases}

    J, out = jax.tree_util.tree_map(np.asarray, ellipsoids(q))
    for rows, sl in cases:
        ve, fe = out[rows]
        U, r = ve.axes, ve.radii
        Jr = J[sl]
        np.testing.assert_allclose(U.T @ U, np.eye(len(r)), atol=1e-13)
        np.testing.assert_allclose(U @ np.diag(r**2) @ U.T, Jr @ Jr.T, atol=1e-13)
        np.testing.assert_allclose(fe.radii, 1.0 / r, rtol=1e-12)
        np.testing.assert_allclose(fe.axes, U, atol=0)
    # At a singularity the force ellipsoid has an infinite axis; its gradient stays finite.
    planar = jk.robots.load("two_link_planar", dtype=np.float64)

    def radii_sum(q):
        Jp = jk.geometric_jacobian(planar, q)
        fe = jk.force_ellipsoid(Jp, rows=(0, 1))
        return jnp.sum(jnp.where(jnp.isfinite(fe.radii), fe.radii, 0.0))

    fe = jk.force_ellipsoid(jk.geometric_jacobian(planar, jnp.zeros(2)), rows=(0, 1))
    assert np.isinf(np.asarray(fe.radii)).sum() == 1
    grad = jax.jit(jax.grad(radii_sum), compiler_options=FAST_COMPILE)(jnp.zeros(2))
    assert np.all(np.isfinite(np.asarray(grad)))


def test_joint_torques_statics_and_power():
    robot = jk.robots.load("ur5", dtype=np.float64)
    rng = np.random.default_rng(2)
    q, qd, F = rng.normal(size=6), rng.normal(size=6), rng.normal(size=6)
    J = jk.geometric_jacobian(robot, q)
    tau = jk.joint_torques(J, F)
    np.testing.assert_allclose(np.asarray(tau), np.asarray(J).T @ F, atol=1e-14)
    # virtual work: F . (J qd) == tau . qd
    assert float(F @ (np.asarray(J) @ qd)) == pytest.approx(float(np.asarray(tau) @ qd), rel=1e-12)
    # gravity-like check: a pure vertical force at the tip loads joint 1 (vertical axis) not at all
    tau_z = jk.joint_torques(J, jnp.array([0.0, 0.0, -10.0, 0.0, 0.0, 0.0]))
    assert abs(float(tau_z[0])) < 1e-12
    with pytest.raises(jk.ShapeError, match=r"wrench must have shape \(6,\)"):
        jk.joint_torques(J, np.zeros(3))


# ----------------------------------------------------------------------------- spherical wrist
@pytest.mark.parametrize(
    "name", ["puma560", "niryo_one", "stanford", "cylindrical_spherical_wrist"]
)
def test_wrist_decoupling_det_factorises(name):
    robot = jk.robots.load(name, dtype=np.float64)
    qs = sample_configurations(robot, 20, 9)

    def one(q):
        return jk.wrist_decoupling(robot, q, 1e-6, check=False), jk.geometric_jacobian(robot, q)

    kernel = jax.jit(jax.vmap(one), compiler_options=FAST_COMPILE)
    out, J = jax.tree_util.tree_map(np.asarray, kernel(jnp.asarray(qs)))
    J = J[:3]
    np.testing.assert_allclose(out.det_J[:3], np.linalg.det(J), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(out.det_J, out.det_arm * out.det_wrist, rtol=1e-10, atol=1e-14)
    assert np.all(out.coupling <= 1e-12)
    assert np.all(out.axis_distance <= 1e-12)


def test_wrist_decoupling_reports_arm_and_wrist_singularities():
    robot = jk.robots.load("cylindrical_spherical_wrist", dtype=np.float64)
    # theta5 = 0: joints 4 and 6 aligned, a wrist singularity
    w = jk.wrist_decoupling(robot, [0.3, 0.4, 0.5, 0.2, 0.0, -0.4], 1e-6)
    assert bool(w.wrist_singular) and not bool(w.arm_singular)
    assert abs(float(w.det_J)) < 1e-12
    # d3 = 0: the wrist centre on the base axis (radius 0), an arm singularity
    w = jk.wrist_decoupling(robot, [0.3, 0.4, 0.0, 0.2, 0.7, -0.4], 1e-6)
    assert bool(w.arm_singular) and not bool(w.wrist_singular)
    w = jk.wrist_decoupling(robot, [0.3, 0.4, 0.5, 0.2, 0.7, -0.4], 1e-6)
    assert not bool(w.arm_singular) and not bool(w.wrist_singular)
    assert float(w.det_J) == pytest.approx(float(w.det_arm * w.det_wrist), rel=1e-12)
    # PUMA: q5 = 0 is its wrist singularity
    puma = jk.robots.load("puma560", dtype=np.float64)
    w = jk.wrist_decoupling(puma, [0.1, 0.7, -0.4, 0.3, 0.0, -0.2], 1e-6)
    assert bool(w.wrist_singular)


def test_wrist_decoupling_rejects_non_spherical_wrists():
    ur5 = jk.robots.load("ur5", dtype=np.float64)
    with pytest.raises(jk.JaxkinError, match="no spherical wrist"):
        jk.wrist_decoupling(ur5, np.full(6, 0.3), 1e-6)
    with pytest.raises(jk.JaxkinError, match="6-dof"):
        jk.wrist_decoupling(jk.robots.load("panda"), np.zeros(7), 1e-6)
    with pytest.raises(jk.JaxkinError, match="revolute"):
        jk.wrist_decoupling(jk.robots.load("stanford"), np.zeros(6), 1e-6, wrist_joints=(1, 2, 3))


@jax.jit(compiler_options=FAST_COMPILE)
def _measures_of(J):
    """The measures of the property below as one program per shape of J (op by op, each new
    shape of a random J compiled every primitive anew)."""
    dep = jk.dependent_columns(J)
    return {
        "s": jk.singular_values(J),
        "inv": jk.manipulability(J, "inverse_condition"),
        "w": jk.manipulability(J),
        "nullity": dep.nullity,
        "null_space": dep.null_space,
        "rank": analysis.rank(J),
    }


@settings(max_examples=10)
@given(
    st.sampled_from([2, 3, 6]),
    st.integers(1, 7),
    st.integers(0, 2**32 - 1),
)
def test_property_measures_bounded_and_consistent(m, n, seed):
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(m, n))
    if n > 1 and seed % 3 == 0:
        J[:, -1] = J[:, 0]  # a repeated column: rank deficient when n <= m
    out = jax.tree_util.tree_map(np.asarray, _measures_of(J))
    s = out["s"]
    inv = float(out["inv"])
    w = float(out["w"])
    assert 0.0 <= inv <= 1.0 + 1e-15
    assert w >= 0.0
    expected = np.prod(s) if m <= n else 0.0
    assert w == pytest.approx(expected, rel=1e-12, abs=1e-300)
    assert int(out["nullity"]) == n - int(out["rank"])
    N = out["null_space"][:, : int(out["nullity"])]
    np.testing.assert_allclose(J @ N, 0.0, atol=1e-12 * max(1.0, float(s[0])))


def test_errors():
    J = np.zeros((6, 6))
    with pytest.raises(jk.JaxkinError, match="measure must be one of"):
        jk.manipulability(J, "volume")
    with pytest.raises(jk.JaxkinError, match="rows must be one of"):
        jk.manipulability(J, rows="linear")
    with pytest.raises(jk.ShapeError, match="needs a \\(6, dof\\) Jacobian"):
        jk.manipulability(np.zeros((3, 6)), rows="rotation")
    with pytest.raises(jk.ShapeError, match=r"jax\.vmap"):
        jk.manipulability(np.zeros((4, 6, 6)))
    with pytest.raises(jk.JaxkinError, match="row index 7"):
        jk.manipulability(J, rows=(0, 7))
