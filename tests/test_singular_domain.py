"""Every public function of analysis.py, inverse_velocity.py and derivatives.py over its whole
documented domain, singular configurations included (and a float32 smoke test of calibrate).

* Batching: ``jax.jit(jax.vmap(f))`` over a batch equals ``jax.jit(f)`` item by item to 1e-12
  (float64).
* Singular inputs: values and derivatives are finite for the two-link arm stretched (q2 = 0)
  and folded (q2 = pi), the UR5 with q5 = 0 and at all zeros, the chapter's cylindrical arm with
  a spherical wrist at its arm (d3 = 0) and wrist (theta5 = 0) singularities, and the zero
  Jacobian. Derivatives are ``jax.grad`` of a random contraction (reverse mode: where a NaN from
  an unguarded ``where`` branch shows) and ``jax.jvp`` along random tangents, with respect to
  the arguments the docstrings call differentiable: J, v and the damping for matrix-level
  functions; q and qd for robot-level ones (a subset on the UR5, see ``_ROBOT_CHECKS``). Where
  the documented value is not a number (condition number and force-ellipsoid radii at a
  singular J: inf; the analytical J-dot at a representation singularity under jit: NaN), that
  value is what is checked.
* float32: the same kernels on float32 robots and inputs return float32 and agree with float64
  (``F32_RTOL`` and the comments where it is used say why that tolerance and where).
"""

from __future__ import annotations

import functools
import math
import zlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE

import jaxkin as jk
from jaxkin import analysis

PI = math.pi
ROWS = ("all", "translation", "rotation", (0, 1))
RANK_RTOL = 1e-5  # far above float32 rounding of an exactly singular J (~1e-8), far below 0.07
RCOND = 1e-4
DAMPING = 0.05
ADAPTIVE = {"max_damping": 0.1, "threshold": 0.2}
NEAR = 1e-3
VMAP_RTOL = 1e-12

# float32 against float64: the inputs are rounded to float32 (relative 6e-8) and each kernel is a
# few hundred operations on quantities of order one. Where the compared quantity is
# well-conditioned (a regular configuration, condition number below 30; or a quantity that is
# well-conditioned at any configuration, named where used), that leaves errors near 1e-6 of the
# output's scale; 1e-4 is a bound with headroom, not a fit to observed values.
F32_RTOL = 1e-4

# Configurations: exactly singular ones first, one regular one last.
PLANAR_QS = np.array([[0.3, 0.0], [0.3, PI], [0.0, 0.0], [0.4, 1.1]])
UR5_QS = np.array(
    [
        [0.1, -0.7, 0.9, 0.2, 0.0, 0.4],  # q5 = 0: joints 4 and 6 aligned (and 2, 3 parallel)
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],  # q5 = 0, elbow stretched
        [0.0, 0.0, 0.0, 0.0, 0.0, PI / 2],  # q5 = 0, and rpy pitch = pi/2 (tool x vertical)
        [0.3, -1.1, 1.4, -0.6, 1.2, 0.5],
    ]
)
UR5_RPY_SINGULAR = 2
WRIST_QS = np.array(
    [
        [0.3, 0.4, 0.0, 0.2, 0.7, -0.4],  # d3 = 0: wrist centre on the base axis (arm)
        [0.3, 0.4, 0.5, 0.2, 0.0, -0.4],  # theta5 = 0: joints 4 and 6 aligned (wrist)
        [0.3, 0.4, 0.0, 0.2, 0.0, -0.4],  # both
        [0.3, 0.4, 0.5, 0.2, 0.7, -0.4],
    ]
)


# ----------------------------------------------------------------------------- helpers
def _rand(tag: str, shape, dtype) -> np.ndarray:
    """A fixed pseudo-random array named by ``tag`` (a constant at trace time)."""
    rng = np.random.default_rng(zlib.crc32(tag.encode()))
    return rng.standard_normal(shape).astype(dtype)


def _evaluate(
    functions: dict, others: dict, derivatives: tuple[str, ...], values: dict | None = None
) -> dict:
    """Values of ``functions`` (name -> (f, args), float outputs) and of ``others``, plus for
    each function the derivatives asked for: ``"grad"`` (a vector-Jacobian product per
    argument) and ``"jvp"`` (a Jacobian-vector product along random tangents).

    Both derivatives come from one ``jax.linearize`` of each function: its linear map is the
    jvp, and the map's transpose the vector-Jacobian product (what ``jax.grad`` of ``vdot(w, f)``
    computes), so f is traced twice (value, linearisation) instead of three times. ``values``
    (name -> value) holds the values of functions the caller already called with the same
    arguments (for ``others`` from the same call): those are not traced again."""
    out = {}
    values = values or {}
    for name, (f, args) in functions.items():
        # the value as called (an SVD without vectors, ...)
        out[name] = y = values[name] if name in values else f(*args)
        if not derivatives:
            continue
        f_jvp = jax.linearize(f, *args)[1]
        if "grad" in derivatives:
            w = _rand(name, y.shape, y.dtype)
            for i, g in enumerate(jax.linear_transpose(f_jvp, *args)(w)):
                out[f"{name}/grad{i}"] = g
        if "jvp" in derivatives:
            tangents = tuple(_rand(f"{name}/{i}", a.shape, a.dtype) for i, a in enumerate(args))
            out[f"{name}/jvp"] = f_jvp(*tangents)
    out.update(others)
    return out


def _is_derivative(key: str) -> bool:
    return "/grad" in key or key.endswith("/jvp")


def _tag(rows) -> str:
    return rows if isinstance(rows, str) else "xy"


def _np(tree):
    return jax.tree_util.tree_map(np.asarray, tree)


def _scale(x: np.ndarray) -> float:
    x = np.abs(x[np.isfinite(x)]) if x.dtype.kind == "f" else np.abs(x)
    return max(1.0, float(x.max())) if x.size else 1.0


def _assert_vmap_matches(single, batched: dict, inputs: tuple) -> None:
    """``single`` (jitted, one item, values only) equals row ``i`` of ``batched``. The items are
    sliced on the host (slicing a JAX array compiles an indexing program per shape)."""
    inputs = _np(tuple(inputs))
    for i in range(len(inputs[0])):
        one = _np(single(*(x[i] for x in inputs)))
        assert one, "nothing compared"
        for k, v in one.items():
            b = batched[k][i]
            assert b.dtype == v.dtype, k
            if v.dtype.kind in "biu":
                np.testing.assert_array_equal(b, v, err_msg=f"{k} item {i}")
            else:
                np.testing.assert_allclose(
                    b, v, rtol=VMAP_RTOL, atol=VMAP_RTOL * _scale(v), err_msg=f"{k} item {i}"
                )


def _assert_float32(out: dict) -> None:
    floats = {k: v.dtype for k, v in out.items() if v.dtype.kind == "f"}
    assert floats and all(d == np.float32 for d in floats.values()), floats


def _assert_finite(out: dict, items, may_be_inf=(), skip=()) -> None:
    """Every float output finite at ``items``; values (not derivatives) of keys starting with a
    prefix in ``may_be_inf`` may be +inf; keys starting with a prefix in ``skip`` are skipped."""
    checked = 0
    for k, v in out.items():
        if v.dtype.kind != "f" or k.startswith(tuple(skip)):
            continue
        x = v[items]
        if k.startswith(tuple(may_be_inf)) and not _is_derivative(k):
            x = np.where(x == np.inf, 0.0, x)
        assert np.all(np.isfinite(x)), (k, np.argwhere(~np.isfinite(x))[:3].tolist())
        checked += 1
    assert checked


def _assert_f32_close(out32: dict, out64: dict, items, keys, rtol=F32_RTOL) -> None:
    """float32 against float64 at ``items``, relative to each output's float64 scale; equal
    infinities count as equal."""
    keys = list(keys)
    assert keys
    for k in keys:
        a, b = out32[k][items], out64[k][items]
        if b.dtype.kind in "biu":
            np.testing.assert_array_equal(a, b, err_msg=k)
            continue
        same_inf = np.isinf(b) & (a == b)
        np.testing.assert_allclose(
            np.where(same_inf, 0.0, a),
            np.where(same_inf, 0.0, b),
            rtol=rtol,
            atol=rtol * _scale(b),
            err_msg=k,
        )


# ----------------------------------------------------------------------------- J-level kernel
def _matrix_kernel(J, v, qd0, F, *, derivatives=()):
    lam = jnp.asarray(DAMPING, J.dtype)
    fns = {}
    others = {}
    values = {}  # of functions in fns, from the calls that give others their entries
    for rows in ROWS:
        t = _tag(rows)
        fns[f"singular_values/{t}"] = (lambda J, r=rows: jk.singular_values(J, r), (J,))
        for m in analysis.MEASURES:
            fns[f"manipulability/{m}/{t}"] = (
                lambda J, m=m, r=rows: jk.manipulability(J, m, r),
                (J,),
            )
        fns[f"condition_number/{t}"] = (lambda J, r=rows: jk.condition_number(J, r), (J,))
        fns[f"velocity_ellipsoid/radii/{t}"] = (
            lambda J, r=rows: jk.velocity_ellipsoid(J, r).radii,
            (J,),
        )
        fns[f"force_ellipsoid/radii/{t}"] = (lambda J, r=rows: jk.force_ellipsoid(J, r).radii, (J,))
        others[f"rank/{t}"] = analysis.rank(J, rows, rtol=RANK_RTOL)
        others[f"near_singular/{t}"] = jk.near_singular(J, NEAR, rows=rows)
        ve, fe = jk.velocity_ellipsoid(J, rows), jk.force_ellipsoid(J, rows)
        values[f"velocity_ellipsoid/radii/{t}"] = ve.radii
        values[f"force_ellipsoid/radii/{t}"] = fe.radii
        others[f"velocity_ellipsoid/axes/{t}"] = ve.axes
        others[f"force_ellipsoid/axes/{t}"] = fe.axes
        # the ellipsoid without its (sign-ambiguous) basis: axes diag(radii^2) axes^T
        others[f"velocity_ellipsoid/shape/{t}"] = (ve.axes * ve.radii[None, :] ** 2) @ ve.axes.T
    dep = jk.dependent_columns(J, rtol=RANK_RTOL)
    others["dependent_columns/mask"] = dep.mask
    others["dependent_columns/nullity"] = dep.nullity
    others["dependent_columns/null_space"] = dep.null_space
    others["dependent_columns/projector"] = dep.null_space @ dep.null_space.T
    fns["joint_torques"] = (jk.joint_torques, (J, F))
    fns["pinv_velocity"] = (lambda J, v: jk.pinv_velocity(J, v, rcond=RCOND), (J, v))
    fns["damped_least_squares"] = (
        lambda J, v, lam: jk.damped_least_squares(J, v, damping=lam),
        (J, v, lam),
    )
    fns["adaptive_damping"] = (lambda J: jk.adaptive_damping(J, **ADAPTIVE), (J,))
    fns["damped_least_squares/adaptive"] = (
        lambda J, v: jk.damped_least_squares(J, v, damping=jk.adaptive_damping(J, **ADAPTIVE)),
        (J, v),
    )
    fns["null_space_projector/rcond"] = (lambda J: jk.null_space_projector(J, rcond=RCOND), (J,))
    fns["null_space_projector/damping"] = (
        lambda J, lam: jk.null_space_projector(J, damping=lam),
        (J, lam),
    )
    fns["null_space_velocity/rcond"] = (
        lambda J, v, s: jk.null_space_velocity(J, v, s, rcond=RCOND),
        (J, v, qd0),
    )
    fns["null_space_velocity/damping"] = (
        lambda J, v, s, lam: jk.null_space_velocity(J, v, s, damping=lam),
        (J, v, qd0, lam),
    )
    return _evaluate(fns, others, derivatives, values)


_matrix_single = jax.jit(_matrix_kernel, compiler_options=FAST_COMPILE)
_matrix_batched = jax.jit(
    jax.vmap(functools.partial(_matrix_kernel, derivatives=("grad", "jvp"))),
    compiler_options=FAST_COMPILE,
)

# Values documented as +inf at a singularity (their derivatives stay finite).
_MAY_BE_INF = ("condition_number/", "force_ellipsoid/radii/")
# Bases: unique only up to sign (and rotation among equal singular values), so compared between
# dtypes through the basis-free "shape" and "projector" outputs.
_BASES = ("velocity_ellipsoid/axes/", "force_ellipsoid/axes/", "dependent_columns/null_space")


def _jacobian_batch(name: str, dtype):
    """Geometric Jacobians at the configurations of ``name``, then the zero Jacobian; with
    random twists, secondary joint velocities and wrenches."""
    robot = jk.robots.load(name, dtype=dtype)
    qs = PLANAR_QS if name == "two_link_planar" else UR5_QS
    jacobians = jax.jit(
        jax.vmap(lambda q: jk.geometric_jacobian(robot, q)), compiler_options=FAST_COMPILE
    )
    # assembled on the host and put on the device as they are (op by op, the concatenation and
    # each jnp.asarray cast compiled a program)
    Js = np.asarray(jacobians(jax.device_put(qs.astype(dtype))))
    Js = np.concatenate([Js, np.zeros_like(Js[:1])])
    n, m, dof = Js.shape
    v, qd0, F = (_rand(t, s, np.float64).astype(dtype)
                 for t, s in (("v", (n, m)), ("qd0", (n, dof)), ("F", (n, m))))  # fmt: skip
    return jax.device_put((Js, v, qd0, F))


@pytest.fixture(scope="module", params=["two_link_planar", "ur5"])
def matrix_case(request):
    inputs = _jacobian_batch(request.param, np.float64)
    return request.param, inputs, _np(_matrix_batched(*inputs))


def test_matrix_functions_vmap_equals_per_item_calls(matrix_case):
    _, inputs, out = matrix_case
    _assert_vmap_matches(_matrix_single, out, inputs)


def test_matrix_functions_finite_at_singular_and_zero_jacobians(matrix_case):
    name, (Js, v, _, _), out = matrix_case
    n, _, dof = Js.shape
    _assert_finite(out, slice(None), may_be_inf=_MAY_BE_INF)
    # The inputs really are singular: in the task rows (x, y for the planar arm) the smallest
    # singular value is rounding at the singular configurations and exactly 0 for J = 0, where
    # the documented infinities appear.
    task = "xy" if name == "two_link_planar" else "all"
    singular, regular, zero = list(range(n - 2)), n - 2, n - 1
    s = out[f"singular_values/{task}"]
    assert np.all(s[singular, -1] <= 1e-15 * s[singular, 0]) and s[regular, -1] > 0.05
    np.testing.assert_array_equal(out["singular_values/all"][zero], 0.0)
    for m in analysis.MEASURES:
        assert np.all(out[f"manipulability/{m}/{task}"][[*singular, zero]] <= 1e-15), m
    assert np.all(out[f"condition_number/{task}"][singular] > 1e14)
    assert np.isinf(out[f"condition_number/{task}"][zero])
    assert np.all(np.isinf(out[f"force_ellipsoid/radii/{task}"][zero]))
    np.testing.assert_array_equal(
        out["adaptive_damping"][[*singular, zero]], ADAPTIVE["max_damping"]
    )
    assert out["dependent_columns/nullity"][zero] == dof
    for k in ("pinv_velocity", "damped_least_squares", "damped_least_squares/adaptive"):
        np.testing.assert_array_equal(out[k][zero], 0.0)
    np.testing.assert_array_equal(out["null_space_projector/rcond"][zero], np.eye(dof))
    # the damped solution obeys its documented bound |qd| <= |v| / (2 lambda) everywhere
    bound = np.linalg.norm(np.asarray(v), axis=1) / (2 * DAMPING)
    assert np.all(np.linalg.norm(out["damped_least_squares"], axis=1) <= bound * (1 + 1e-12))


def test_matrix_functions_float32(matrix_case):
    name, _, out64 = matrix_case
    inputs32 = _jacobian_batch(name, np.float32)
    assert all(x.dtype == np.float32 for x in inputs32)
    out32 = _np(_matrix_batched(*inputs32))
    _assert_float32(out32)
    # An exactly singular J is singular only to rounding in float32 (its "zero" singular value is
    # ~1e-8): the infinities become large finite numbers, nothing becomes NaN, derivatives
    # included.
    _assert_finite(out32, slice(None), may_be_inf=_MAY_BE_INF)
    n = len(inputs32[0])
    regular, zero = n - 2, n - 1
    everything = [k for k in out32 if not k.startswith(_BASES)]
    _assert_f32_close(out32, out64, [regular, zero], everything)
    # At the singular configurations, what is well-conditioned there: singular values move by at
    # most |dJ|_2 (Weyl), so the values built from them are accurate to rounding relative to
    # sigma_max; rank and dependent columns, decided with RANK_RTOL far above that rounding, are
    # the same; damping bounds the damped solutions' gain by 1 / (2 lambda) = 10.
    stable = (
        "singular_values/", "manipulability/", "rank/", "near_singular/",
        "velocity_ellipsoid/radii/", "velocity_ellipsoid/shape/", "dependent_columns/mask",
        "dependent_columns/nullity", "dependent_columns/projector", "joint_torques",
        "damped_least_squares", "adaptive_damping", "null_space_projector/damping",
        "null_space_velocity/damping",
    )  # fmt: skip
    keys = [k for k in out32 if k.startswith(stable) and not _is_derivative(k)]
    _assert_f32_close(out32, out64, slice(0, n - 2), keys)


# ----------------------------------------------------------------------------- robot kernels
def _robot_functions(robot: jk.Robot, q, qd) -> dict:
    """The robot-level functions at (q, qd), as name -> (function, arguments)."""
    fns = {}
    # On the UR5, only rows="all": test_analysis covers the others there (vmap, q5 = 0).
    for rows in ROWS if robot.dof == 2 else ("all",):
        for m in analysis.MEASURES:
            fns[f"manipulability_gradient/{m}/{_tag(rows)}"] = (
                lambda q, m=m, r=rows: jk.manipulability_gradient(robot, q, m, r),
                (q,),
            )
    fns["jacobian_dot"] = (lambda q, qd: jk.jacobian_dot(robot, q, qd), (q, qd))
    fns["jacobian_dot/local"] = (
        lambda q, qd: jk.jacobian_dot(robot, q, qd, reference="local"),
        (q, qd),
    )
    fns["jacobian_dot_qd"] = (lambda q, qd: jk.jacobian_dot_qd(robot, q, qd), (q, qd))
    fns["kinematic_hessian"] = (lambda q: jk.kinematic_hessian(robot, q), (q,))
    fns["analytical_jacobian_dot"] = (
        lambda q, qd: jk.analytical_jacobian_dot(robot, q, qd, "rpy"),
        (q, qd),
    )
    fns["analytical_jacobian_dot_qd"] = (
        lambda q, qd: jk.analytical_jacobian_dot_qd(robot, q, qd, "rpy"),
        (q, qd),
    )
    fns["rpy_margin"] = (
        lambda q, qd: jk.analytical_jacobian_dot(robot, q, qd, "rpy", return_margin=True)[1],
        (q, qd),
    )
    return fns


def _robot_kernel(robot: jk.Robot, q, qd, *, names=None, derivatives=(), differentiate=()):
    """Values of the robot-level functions (those in ``names``, default all) and the
    derivatives asked for, with respect to q and qd, of those in ``differentiate`` (whose values
    ``_evaluate`` computes as called, so they are not traced a second time here)."""
    fns = _robot_functions(robot, q, qd)
    values = {
        k: f(*a)
        for k, (f, a) in fns.items()
        if (names is None or k in names) and k not in differentiate
    }
    return _evaluate({k: fns[k] for k in differentiate}, values, derivatives)


def _robot_batched(robot, q, qd, **kw):
    kernel = functools.partial(_robot_kernel, robot, **kw)
    return _np(jax.jit(jax.vmap(kernel), compiler_options=FAST_COMPILE)(q, qd))


_ANALYTICAL = ("analytical_jacobian_dot",)  # both of them, by prefix
# What each robot is checked for, beyond values: derivatives with respect to q and qd (not of the
# manipulability gradient, itself a derivative: its own, second derivatives of singular values,
# are not documented). The J-dot terms are trigonometric polynomials in q whose derivatives do
# not see a kinematic singularity, and differentiating them again is a third derivative of an
# unrolled kernel, slow to compile for the UR5: there only forward mode of the analytical term,
# through the rpy map and its singularity guard. Per-item calls: every function on the planar
# arm; on the UR5 the analytical terms, whose NaN masking is per item.
_ROBOT_CHECKS = {
    "two_link_planar": {
        "batched": {
            "derivatives": ("grad", "jvp"),
            "differentiate": (
                "jacobian_dot",
                "jacobian_dot_qd",
                "kinematic_hessian",
                "analytical_jacobian_dot",
                "analytical_jacobian_dot_qd",
            ),
        },
        "single": {},
    },
    "ur5": {
        "batched": {"derivatives": ("jvp",), "differentiate": ("analytical_jacobian_dot_qd",)},
        "single": {"names": (*_ANALYTICAL, "analytical_jacobian_dot_qd", "rpy_margin")},
    },
}


def _robot_inputs(name: str, dtype):
    robot = jk.robots.load(name, dtype=dtype)
    qs = PLANAR_QS if name == "two_link_planar" else UR5_QS
    qd = _rand("qd", qs.shape, np.float64)
    return robot, *jax.device_put((qs.astype(dtype), qd.astype(dtype)))


@pytest.fixture(scope="module", params=["two_link_planar", "ur5"])
def robot_case(request):
    robot, q, qd = _robot_inputs(request.param, np.float64)
    out = _robot_batched(robot, q, qd, **_ROBOT_CHECKS[request.param]["batched"])
    return request.param, robot, q, qd, out


def test_robot_functions_vmap_equals_per_item_calls(robot_case):
    name, robot, q, qd, out = robot_case
    kernel = functools.partial(_robot_kernel, robot, **_ROBOT_CHECKS[name]["single"])
    single = jax.jit(kernel, compiler_options=FAST_COMPILE)
    _assert_vmap_matches(single, out, (q, qd))


def test_robot_functions_finite_at_singular_configurations(robot_case):
    name, robot, q, _, out = robot_case
    n = len(q)
    rep = [UR5_RPY_SINGULAR] if name == "ur5" else []
    fine = [i for i in range(n) if i not in rep]
    _assert_finite(out, fine)
    _assert_finite(out, rep, skip=_ANALYTICAL)
    # documented: under jit/vmap the analytical J-dot is all NaN at a representation singularity
    # (and only there), whatever the kinematic singularity
    tol = math.sqrt(np.finfo(np.float64).eps)
    np.testing.assert_array_equal(out["rpy_margin"] < tol, [i in rep for i in range(n)])
    for k in ("analytical_jacobian_dot", "analytical_jacobian_dot_qd"):
        assert np.all(np.isnan(out[k][rep])), k
    # and the configurations are singular: the task rows' Yoshikawa measure vanishes
    task = (0, 1) if name == "two_link_planar" else "all"

    def measure(q):
        return jk.manipulability(jk.geometric_jacobian(robot, q), rows=task)

    m = np.asarray(jax.jit(jax.vmap(measure), compiler_options=FAST_COMPILE)(q))
    assert np.all(m[:-1] <= 1e-15) and m[-1] > 1e-3


def test_robot_functions_float32(robot_case):
    name, _, _, _, out64 = robot_case
    robot32, q32, qd32 = _robot_inputs(name, np.float32)
    assert robot32.dtype == np.float32
    out32 = _robot_batched(robot32, q32, qd32)
    _assert_float32(out32)
    n = len(q32)
    rep = [UR5_RPY_SINGULAR] if name == "ur5" else []
    fine = [i for i in range(n) if i not in rep]
    _assert_finite(out32, fine)
    _assert_finite(out32, rep, skip=_ANALYTICAL)
    if rep:
        assert np.all(out32["rpy_margin"][rep] < math.sqrt(np.finfo(np.float32).eps))
        assert np.all(np.isnan(out32["analytical_jacobian_dot"][rep]))
    # Forward kinematics and its derivatives are well-conditioned at every configuration: the
    # J-dot and Hessian values agree everywhere (the analytical ones away from the representation
    # singularity).
    mg = [k for k in out32 if k.startswith("manipulability_gradient/")]
    smooth = [k for k in out32 if k not in mg and k != "rpy_margin"]
    _assert_f32_close(out32, out64, fine, smooth)
    _assert_f32_close(out32, out64, rep, [k for k in smooth if not k.startswith(_ANALYTICAL)])
    # The manipulability gradient agrees at the regular configuration. At a singularity the
    # measure has a kink (|sin q2| for the planar arm) and its gradient is a one-sided
    # derivative whose sign follows the rounding of the zero singular value; its size does not.
    _assert_f32_close(out32, out64, [n - 1], mg)
    abs32 = {k: np.abs(out32[k]) for k in mg}
    _assert_f32_close(abs32, {k: np.abs(out64[k]) for k in mg}, slice(0, n - 1), mg)


# ----------------------------------------------------------------------------- spherical wrist
_DECOUPLING_FLOATS = (
    "det_J", "det_arm", "det_wrist", "sigma_min_arm", "sigma_min_wrist", "wrist_centre",
    "coupling", "axis_distance",
)  # fmt: skip


def _decoupling_floats(w) -> jax.Array:
    return jnp.concatenate([jnp.ravel(getattr(w, k)) for k in _DECOUPLING_FLOATS])


def _wrist_kernel(robot: jk.Robot, q, *, derivatives=()):
    def decoupling(q):
        return _decoupling_floats(jk.wrist_decoupling(robot, q, 1e-6))

    w = jk.wrist_decoupling(robot, q, 1e-6)  # one call for its floats and its flags
    centre, distance = jk.wrist_centre(robot, q)
    fns = {
        "wrist_centre/centre": (lambda q: jk.wrist_centre(robot, q)[0], (q,)),
        "wrist_centre/distance": (lambda q: jk.wrist_centre(robot, q)[1], (q,)),
        "wrist_decoupling": (decoupling, (q,)),
    }
    others = {"arm_singular": w.arm_singular, "wrist_singular": w.wrist_singular}
    values = {
        "wrist_centre/centre": centre,
        "wrist_centre/distance": distance,
        "wrist_decoupling": _decoupling_floats(w),
    }
    return _evaluate(fns, others, derivatives, values)


def test_wrist_functions_vmap_finite_and_float32():
    robot = jk.robots.load("cylindrical_spherical_wrist", dtype=np.float64)
    q = jnp.asarray(WRIST_QS)
    batched = jax.vmap(functools.partial(_wrist_kernel, robot, derivatives=("grad",)))
    out = _np(jax.jit(batched, compiler_options=FAST_COMPILE)(q))
    single = jax.jit(functools.partial(_wrist_kernel, robot), compiler_options=FAST_COMPILE)
    _assert_vmap_matches(single, out, (q,))
    _assert_finite(out, slice(None))
    np.testing.assert_array_equal(out["arm_singular"], [True, False, True, False])
    np.testing.assert_array_equal(out["wrist_singular"], [False, True, True, False])
    assert np.all(np.abs(out["wrist_decoupling"][:3, 0]) < 1e-14)  # det J

    robot32 = jk.robots.load("cylindrical_spherical_wrist", dtype=np.float32)
    batched32 = jax.vmap(functools.partial(_wrist_kernel, robot32))
    q32 = jax.device_put(WRIST_QS.astype(np.float32))  # a cast on the device compiles
    out32 = _np(jax.jit(batched32, compiler_options=FAST_COMPILE)(q32))
    _assert_float32(out32)
    _assert_finite(out32, slice(None))
    np.testing.assert_array_equal(out32["arm_singular"], out["arm_singular"])
    np.testing.assert_array_equal(out32["wrist_singular"], out["wrist_singular"])
    # The centre, determinants and singular values of 3x3 blocks are well-conditioned everywhere.
    # The axis distance is 0 for a spherical wrist, so float32 gives rounding (< 1e-5 m) there.
    dist = _DECOUPLING_FLOATS.index("axis_distance") + 2  # wrist_centre spans 3 entries
    _assert_f32_close(out32, out, slice(None), ["wrist_centre/centre"])
    d32, d64 = (
        np.delete(out32["wrist_decoupling"], dist, 1),
        np.delete(out["wrist_decoupling"], dist, 1),
    )
    np.testing.assert_allclose(d32, d64, rtol=F32_RTOL, atol=F32_RTOL * _scale(d64))
    assert np.all(out32["wrist_decoupling"][:, dist] < 1e-5)
    assert np.all(out32["wrist_centre/distance"] < 1e-5)


# ----------------------------------------------------------------------------- pose error
def _rot(w) -> np.ndarray:
    """Rotation matrix of rotation vector ``w`` (Rodrigues), in numpy."""
    w = np.asarray(w, dtype=np.float64)
    theta = np.linalg.norm(w)
    if theta == 0.0:
        return np.eye(3)
    k = w / theta
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(theta) * K + (1.0 - np.cos(theta)) * K @ K


def _transform(R, p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def _pose_pairs(dtype):
    T = _transform(_rot([0.3, -0.2, 0.9]), [0.4, -0.1, 0.6])
    axis = np.array([0.48, -0.6, 0.64])  # a unit vector
    # zero error; half turns (the end of log_so3's regular branch); a generic error
    turns = [np.zeros(3), [PI, 0.0, 0.0], PI * axis, [0.5, 0.1, -0.3]]
    Tb = np.stack([T @ _transform(_rot(w), 0.1 * i * axis) for i, w in enumerate(turns)])
    Ta = np.broadcast_to(T, Tb.shape)
    return jax.device_put((Ta.astype(dtype), Tb.astype(dtype)))  # a cast on the device compiles


def _pose_kernel(T, Td, *, derivatives=()):
    return _evaluate({"pose_error": (jk.pose_error, (T, Td))}, {}, derivatives)


def test_pose_error_vmap_finite_at_zero_and_half_turn_and_float32():
    Ta, Tb = _pose_pairs(np.float64)
    kernel = functools.partial(_pose_kernel, derivatives=("grad", "jvp"))
    batched = jax.jit(jax.vmap(kernel), compiler_options=FAST_COMPILE)
    out = _np(batched(Ta, Tb))
    _assert_vmap_matches(jax.jit(_pose_kernel, compiler_options=FAST_COMPILE), out, (Ta, Tb))
    _assert_finite(out, slice(None))
    e = out["pose_error"]
    np.testing.assert_array_equal(e[0], 0.0)
    np.testing.assert_allclose(np.linalg.norm(e[1:3, 3:], axis=1), PI, rtol=1e-12)

    out32 = _np(batched(*_pose_pairs(np.float32)))
    _assert_float32(out32)
    _assert_finite(out32, slice(None))
    # the value is well-conditioned everywhere (up to the sign of a half turn: +-pi axis) ...
    np.testing.assert_allclose(np.abs(out32["pose_error"]), np.abs(e), rtol=0, atol=F32_RTOL)
    # ... and so are the derivatives away from the half turn
    _assert_f32_close(out32, out, [0, 3], out)


# ----------------------------------------------------------------------------- resolved rate
N_STEPS, DT = 4, 0.01


def _rrc_paths(robot: jk.Robot, q0s):
    """From fk(q0), 2 cm along world x (for the stretched arm: outward, out of reach)."""
    T0 = jax.jit(jax.vmap(lambda q: jk.fk(robot, q)), compiler_options=FAST_COMPILE)(q0s)
    ramp = jnp.linspace(0.0, 0.02, N_STEPS, dtype=T0.dtype)
    step = jnp.zeros((N_STEPS, 4, 4), T0.dtype).at[:, 0, 3].set(ramp)
    return T0[:, None] + step[None]


def _rrc(robot, q0, Ts, damping=DAMPING, rcond=None):
    return jk.resolved_rate_control(robot, q0, Ts, DT, damping=damping, rcond=rcond)._asdict()


def test_resolved_rate_control_vmap_gradient_and_float32():
    robot = jk.robots.load("two_link_planar", dtype=np.float64)
    q0s = jnp.asarray(PLANAR_QS)
    paths = _rrc_paths(robot, q0s)

    def loss(q0, Ts):
        res = jk.resolved_rate_control(robot, q0, Ts, DT, damping=DAMPING)
        return jnp.sum(res.q[-1]) + res.max_position_error + res.max_orientation_error

    @functools.partial(jax.jit, compiler_options=FAST_COMPILE)
    def batched(q0s, paths):
        return (
            jax.vmap(lambda q0, Ts: _rrc(robot, q0, Ts))(q0s, paths),
            jax.vmap(lambda q0, Ts: _rrc(robot, q0, Ts, damping=None, rcond=RCOND))(q0s, paths),
            jax.vmap(jax.grad(loss, argnums=(0, 1)))(q0s, paths),
        )

    dls, pinv, grads = _np(batched(q0s, paths))
    single = jax.jit(lambda q0, Ts: _rrc(robot, q0, Ts), compiler_options=FAST_COMPILE)
    _assert_vmap_matches(single, dls, (q0s, paths))
    _assert_finite(dls, slice(None))
    _assert_finite(pinv, slice(None))
    assert all(np.all(np.isfinite(g)) for g in grads)

    robot32 = jk.robots.load("two_link_planar", dtype=np.float32)
    q32 = jax.device_put(PLANAR_QS.astype(np.float32))
    run32 = jax.jit(jax.vmap(lambda q0, Ts: _rrc(robot32, q0, Ts)), compiler_options=FAST_COMPILE)
    out32 = _np(run32(q32, _rrc_paths(robot32, q32)))
    _assert_float32(out32)
    _assert_finite(out32, slice(None))
    # a few damped steps are a smooth map of the inputs with gain at most 1 / (2 lambda) = 10
    for k in ("q", "qd"):
        np.testing.assert_allclose(out32[k], dls[k], rtol=0, atol=F32_RTOL * _scale(dls[k]))


# ----------------------------------------------------------------------------- calibration
def test_calibrate_float32_reduces_the_error():
    nominal = jk.robots.load("two_link_planar", a1=1.0, a2=0.7, dtype=np.float32)
    a_true = jax.device_put(np.array([1.013, 0.688], np.float32))
    true = nominal.replace(params={**nominal.params, "a": a_true})
    qs = np.random.default_rng(4).uniform(-PI, PI, size=(30, 2)).astype(np.float32)
    Ts = jax.jit(jax.vmap(lambda q: jk.fk(true, q)), compiler_options=FAST_COMPILE)(jnp.asarray(qs))
    assert Ts.dtype == np.float32
    res = jk.calibrate(nominal, qs, Ts, ["a"])
    assert res.robot.dtype == np.float32
    leaves = jax.tree_util.tree_leaves({k: v for k, v in res._asdict().items() if k != "robot"})
    assert {np.asarray(x).dtype for x in leaves if np.asarray(x).dtype.kind == "f"} == {
        np.dtype(np.float32)
    }
    assert float(res.rms_position_before) > 1e-2
    # float32 poses of a 1.7 m arm carry ~1e-7 m of rounding; the fit gets near that, three
    # orders of magnitude below the 1.3 cm it started from
    assert float(res.rms_position_after) < 1e-5
    np.testing.assert_allclose(np.asarray(res.params["a"]), [1.013, 0.688], rtol=0, atol=1e-5)
    hist = np.asarray(res.loss_history)[: max(int(res.steps) - 1, 1)]
    assert np.all(np.isfinite(hist)) and hist[-1] < hist[0]
