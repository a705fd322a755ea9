"""Singularities, manipulability, ellipsoids and statics of a Jacobian.

Most functions take a Jacobian ``J`` of shape (m, dof) (typically the (6, dof) geometric Jacobian
of :func:`jaxkin.geometric_jacobian`, rows ``[v; omega]``) and work on one Jacobian; batch with
``jax.vmap``. ``rows`` selects the task-space rows analysed:

=================  =======================================================================
``rows``           rows of a (6, dof) Jacobian
=================  =======================================================================
``"all"``          all rows (any m); mixes metres and radians, so its values depend on units
``"translation"``  rows 0..2 (linear velocity)
``"rotation"``     rows 3..5 (angular velocity)
a sequence         those row indices, e.g. ``(0, 1)`` for a planar arm's x and y
=================  =======================================================================

Everything is computed from singular values (``jnp.linalg.svd(..., compute_uv=False)``, whose
derivative ``u_i^T dJ v_i`` is finite everywhere), never from ``sqrt(det(J J^T))``, whose value
is NaN and gradient infinite at exact singularities. The measures consider the m task-space axes
of the selected rows: when m > dof the last m - dof axes have length 0 (the velocity ellipsoid is
flat), exactly as ``sqrt(det(J J^T))`` would say.

Translational and rotational measures do not depend on the basis (``"world_aligned"`` and
``"local"`` Jacobians give the same values) but do depend on the point: use the Jacobian of the
point you care about (for the wrist decoupling below, the wrist centre).

Non-finite input
----------------
NaN or inf in an input (a Jacobian, a configuration, a twist or wrench, a target pose, a
threshold or tolerance) never yields a confident finite answer. One policy, the same for every
public function of :mod:`jaxkin.analysis`, :mod:`jaxkin.inverse_velocity`,
:mod:`jaxkin.calibration` and :func:`jaxkin.classify_twist`/:func:`jaxkin.classify_motion`:

* called eagerly (no JAX tracer among the inputs), the function raises
  :class:`~jaxkin.JaxkinError` naming the argument that holds NaN or inf, before computing;
* under a trace (``jit``, ``vmap``, ``grad``), where values cannot raise, the result of a call
  (of each item, under ``vmap``) with a non-finite input is poisoned: floating-point values are
  NaN, boolean flags are True ("possibly singular"), integer
  counts (:func:`rank`, ``DependentColumns.nullity``) are the sentinel -1, and convergence flags
  (``converged`` of :func:`jaxkin.calibrate`) are False ("not converged");
* host-side results (Python strings and lists: :func:`jaxkin.classify_twist`,
  :func:`jaxkin.identifiability`) cannot be poisoned: those functions raise under a trace too.

Exact singularities are finite input: their values stay finite (or the documented ``inf``), and
finite inputs give bit for bit the results they gave without the check.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import (
    check_J,
    check_point,
    check_q,
    check_reference,
    finite_guard,
    is_traced,
    refuse_multi_dof,
    result_dtype,
)
from ._forward import forward_pass
from ._jacobian_pass import jacobian_pass
from ._jit import eager, robot_jit
from .errors import JaxkinError, ShapeError
from .model import Robot
from .spatial import safe_sqrt

__all__ = [
    "MEASURES",
    "ROWS",
    "DependentColumns",
    "Ellipsoid",
    "WristDecoupling",
    "condition_number",
    "dependent_columns",
    "force_ellipsoid",
    "joint_torques",
    "manipulability",
    "manipulability_gradient",
    "near_singular",
    "rank",
    "singular_values",
    "velocity_ellipsoid",
    "wrist_centre",
    "wrist_decoupling",
]

MEASURES = ("yoshikawa", "inverse_condition", "min_singular_value")
ROWS = ("all", "translation", "rotation")
_NAMED_ROWS = {"translation": (0, 1, 2), "rotation": (3, 4, 5)}


# ----------------------------------------------------------------------------- validation
def _row_indices(rows: Any, m: int, fn: str) -> tuple[int, ...] | None:
    """Row indices selected by ``rows`` (None: all rows)."""
    if isinstance(rows, str):
        if rows == "all":
            return None
        if rows in _NAMED_ROWS:
            if m != 6:
                raise ShapeError(
                    f"{fn}: rows={rows!r} needs a (6, dof) Jacobian with rows [v; omega], got "
                    f"{m} rows. Pass explicit row indices instead, e.g. rows=(0, 1)."
                )
            return _NAMED_ROWS[rows]
        raise JaxkinError(
            f"{fn}: rows must be one of {ROWS} or a sequence of row indices, got {rows!r}."
        )
    if isinstance(rows, Sequence) and len(rows) > 0:
        idx = []
        for r in rows:
            if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or not -m <= r < m:
                raise JaxkinError(
                    f"{fn}: row index {r!r} is not an integer in [0, {m}) for a Jacobian with "
                    f"{m} rows."
                )
            idx.append(int(r) % m)
        if len(set(idx)) != len(idx):
            raise JaxkinError(f"{fn}: rows {tuple(rows)} repeats a row.")
        return tuple(idx)
    raise JaxkinError(
        f"{fn}: rows must be one of {ROWS} or a non-empty sequence of row indices, got {rows!r}."
    )


def _guarded(
    J: Any, rows: Any, fn: str, batch_hint: str | None = None, zero_dof=True, **others: Any
):
    """The selected rows of the checked ``J`` and the non-finite guard of ``J`` and ``others``
    (module doc, "Non-finite input"): the guard checks all of J, not only the selected rows.
    ``batch_hint``: the code suggested for a batch of Jacobians (see ``check_J``); ``zero_dof``:
    whether a (m, 0) Jacobian (a robot with no moving joint) is accepted."""
    Jc = check_J(J, fn, batch_hint, zero_dof=zero_dof)
    idx = _row_indices(rows, Jc.shape[0], fn)
    guard = finite_guard(fn, J=Jc, **others)
    Jc = guard.clean(Jc)
    return (Jc if idx is None else _take_rows(Jc, idx)), guard


def _take_rows(J: jax.Array, idx: tuple[int, ...]) -> jax.Array:
    """Rows ``idx`` of ``J`` as static slices, one per run of consecutive indices: a gather, and
    under differentiation its scatter-add transpose, compile to far more code than slices and
    their pads. The rows are the same copies; a backward pass that goes on past ``J`` (to q)
    may round in the last bit differently, as XLA drops the rows it knows are zero."""
    runs = [[idx[0], idx[0] + 1]]
    for i in idx[1:]:
        if i == runs[-1][1]:
            runs[-1][1] += 1
        else:
            runs.append([i, i + 1])
    parts = [jax.lax.slice_in_dim(J, a, b, axis=0) for a, b in runs]
    return parts[0] if len(parts) == 1 else jnp.concatenate(parts, axis=0)


def _check_measure(measure: str, fn: str) -> str:
    if measure not in MEASURES:
        raise JaxkinError(f"{fn}: measure must be one of {MEASURES}, got {measure!r}.")
    return measure


def _task_singular_values(Jr: jax.Array) -> jax.Array:
    """The m singular values of an (m, n) matrix along the task-space axes, descending.

    ``min(m, n)`` come from the SVD; for ``m > n`` the remaining ``m - n`` axes have length 0.
    """
    m, n = Jr.shape
    if n == 0:  # a robot with no moving joint moves along no axis
        return jnp.zeros(m, dtype=Jr.dtype)
    s = jnp.linalg.svd(Jr, compute_uv=False)
    if m > n:
        s = jnp.concatenate([s, jnp.zeros(m - n, dtype=s.dtype)])
    return s


def _safe_ratio(num: jax.Array, den: jax.Array) -> jax.Array:
    """``num / den``, 0 where ``den == 0`` (double-where: finite gradient there too)."""
    ok = den > 0
    safe = jnp.where(ok, den, jnp.ones_like(den))
    return jnp.where(ok, num / safe, jnp.zeros_like(num))


# ----------------------------------------------------------------------------- singular values
def singular_values(J: Any, rows: Any = "all") -> jax.Array:
    """Singular values of the selected rows of ``J``, descending; shape (min(m, dof),).

    ``m`` is the number of selected rows (6, 3 or ``len(rows)``). Differentiable everywhere
    (``d sigma_i = u_i^T dJ v_i``), including at repeated and zero singular values. Non-finite
    ``J``: see the module doc (raises eagerly; NaN under a trace).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))
    >>> jk.singular_values(J, rows=[0, 1]).round(6).tolist()  # the (v_x, v_y) rows
    [1.618034, 0.618034]
    >>> J0 = jk.geometric_jacobian(robot, jnp.zeros(2))  # stretched out: rank 1
    >>> jk.singular_values(J0, rows=[0, 1]).round(6).tolist()
    [2.236068, 0.0]
    """
    Jr, guard = _guarded(J, rows, "jk.singular_values")
    return guard(jnp.linalg.svd(Jr, compute_uv=False))


def _default_rtol(shape, dtype) -> float:
    return float(max(shape) * np.finfo(dtype).eps)


def rank(J: Any, rows: Any = "all", *, rtol: float | None = None, atol: float = 0.0) -> jax.Array:
    """Numerical rank of the selected rows of ``J``: the number of singular values above
    ``max(atol, rtol * sigma_max)``; int32 scalar.

    ``rtol`` defaults to ``max(m, dof) * eps`` (NumPy's ``matrix_rank``); both thresholds are in
    the Jacobian's units (m/rad or 1). For "is the robot close to a singularity" use
    :func:`near_singular` with a threshold that means something for your task.

    Non-finite ``J``, ``rtol`` or ``atol`` (module doc): raises eagerly; under a trace the rank
    is the sentinel -1.
    """
    hint = "jax.vmap(jk.analysis.rank)(Js)"
    Jr, guard = _guarded(J, rows, "jk.rank", hint, rtol=rtol, atol=atol)
    s = jnp.linalg.svd(Jr, compute_uv=False)
    rt = _default_rtol(Jr.shape, Jr.dtype) if rtol is None else rtol
    largest = s[0] if s.shape[0] else jnp.zeros((), s.dtype)  # no column: rank 0
    tol = jnp.maximum(jnp.asarray(atol, s.dtype), rt * largest)
    return guard(jnp.sum(s > tol).astype(jnp.int32))


def manipulability(J: Any, measure: str = "yoshikawa", rows: Any = "all") -> jax.Array:
    """A manipulability measure of the selected rows of ``J``; scalar, >= 0, never NaN.

    With ``sigma_1 >= ... >= sigma_m`` the task-space singular values of the m selected rows
    (zeros for the ``m - dof`` axes a robot with fewer joints than rows cannot move along):

    * ``"yoshikawa"``: ``w = sigma_1 * ... * sigma_m``, which equals ``sqrt(det(J J^T))``
      (Yoshikawa 1985): the volume of the velocity ellipsoid (up to a constant); 0 at a singularity.
      Computed as a product of singular values, never as ``sqrt(det)``;
    * ``"inverse_condition"``: ``sigma_m / sigma_1`` in [0, 1] (1: isotropic; 0: singular, also
      for a zero Jacobian);
    * ``"min_singular_value"``: ``sigma_m``, the smallest velocity gain (m/s or rad/s per unit
      joint speed): the distance to the nearest singular matrix in the 2-norm.

    ``rows`` is ``"all"``, ``"translation"`` (rows 0..2), ``"rotation"`` (rows 3..5) or a
    sequence of row indices. ``"all"`` mixes metres and radians. Values and gradients (``jax.grad``
    with respect to ``J``) are finite at exact singularities. Non-finite ``J`` (module doc): raises
    eagerly; NaN under a trace.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))
    >>> round(float(jk.manipulability(J, rows=[0, 1])), 6)  # |det J| = l1 l2 |sin q2|
    1.0
    >>> round(float(jk.manipulability(J, "min_singular_value", rows=[0, 1])), 6)
    0.618034
    """
    fn = "jk.manipulability"
    _check_measure(measure, fn)
    Jr, guard = _guarded(J, rows, fn)
    return guard(_manipulability(Jr, measure))


def _manipulability(Jr: jax.Array, measure: str) -> jax.Array:
    s = _task_singular_values(Jr)
    if measure == "yoshikawa":
        return jnp.prod(s)
    if measure == "min_singular_value":
        return s[-1]
    return _safe_ratio(s[-1], s[0])


def condition_number(J: Any, rows: Any = "all") -> jax.Array:
    """``sigma_1 / sigma_m`` of the selected rows (task-space axes); ``inf`` at a singularity.

    For a bounded, differentiable measure use ``manipulability(J, "inverse_condition")``.
    Non-finite ``J`` (module doc): raises eagerly; NaN (not ``inf``) under a trace.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))
    >>> round(float(jk.condition_number(J, rows=[0, 1])), 6)  # 1.618034 / 0.618034
    2.618034
    >>> float(jk.condition_number(jk.geometric_jacobian(robot, jnp.zeros(2)), rows=[0, 1]))
    inf
    """
    Jr, guard = _guarded(J, rows, "jk.condition_number")
    s = _task_singular_values(Jr)
    inv = _safe_ratio(s[-1], s[0])
    return guard(jnp.where(inv > 0, 1.0 / jnp.where(inv > 0, inv, 1.0), jnp.inf))


def near_singular(
    J: Any, threshold: float, *, measure: str = "min_singular_value", rows: Any = "all"
) -> jax.Array:
    """True where ``manipulability(J, measure, rows) < threshold``; bool scalar.

    The threshold has no default on purpose: it is in the measure's units (the default measure,
    the smallest singular value, is in m/s or rad/s per rad/s of joint speed) and depends on the
    task. ``measure`` and ``rows`` as in :func:`manipulability`.

    Non-finite ``J`` or ``threshold`` (module doc): raises eagerly; True ("possibly singular")
    under a trace.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, 0.01]))  # nearly stretched out
    >>> bool(jk.near_singular(J, 0.05, rows=[0, 1]))
    True
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))  # elbow at a right angle
    >>> bool(jk.near_singular(J, 0.05, rows=[0, 1]))
    False
    """
    fn = "jk.near_singular"
    _check_measure(measure, fn)
    hint = f"jax.vmap(lambda J: {fn}(J, threshold))(Js)"
    Jr, guard = _guarded(J, rows, fn, hint, threshold=threshold)
    return guard(_manipulability(Jr, measure) < threshold)


class DependentColumns(NamedTuple):
    """Which columns (joints) of a Jacobian are linearly dependent.

    ``mask`` (dof,) bool: column i takes part in a linear dependency (it has a non-zero
    coefficient in some null-space vector). ``null_space`` (dof, dof): the first ``nullity``
    columns are an orthonormal basis of the null space (joint velocities that do not move the
    selected task-space rows); the others are zero. ``nullity``: int32 scalar, dof - rank.

    From a non-finite Jacobian under a trace (module doc): ``mask`` all True, ``null_space`` NaN,
    ``nullity`` -1.
    """

    mask: jax.Array
    null_space: jax.Array
    nullity: jax.Array


def dependent_columns(
    J: Any,
    rows: Any = "all",
    *,
    rtol: float | None = None,
    atol: float = 0.0,
    coefficient_tol: float = 1e-6,
) -> DependentColumns:
    """The linearly dependent columns of the selected rows of ``J`` (see :class:`DependentColumns`).

    Singular values at or below ``max(atol, rtol * sigma_max)`` (``rtol`` default
    ``max(m, dof) * eps``, as :func:`rank`) count as zero; a column is dependent when its
    coefficient in a unit null-space vector exceeds ``coefficient_tol`` in magnitude. A redundant
    robot (dof > rank) has a null space everywhere; at a singularity of a 6-dof arm the mask names
    the joints whose motions became dependent (e.g. UR5 at q5 = 0: joints 2, 3, 4 and 6, whose axes
    are then all parallel).

    The basis is returned without derivative (``stop_gradient``): a null-space basis is not a
    differentiable function of ``J`` where the rank changes. Non-finite ``J`` or tolerances
    (module doc): raises eagerly; under a trace see :class:`DependentColumns`.
    """
    Jr, guard = _guarded(
        J,
        rows,
        "jk.dependent_columns",
        zero_dof=False,
        rtol=rtol,
        atol=atol,
        coefficient_tol=coefficient_tol,
    )
    n = Jr.shape[1]
    _, s, Vt = jnp.linalg.svd(jax.lax.stop_gradient(Jr), full_matrices=True)
    rt = _default_rtol(Jr.shape, Jr.dtype) if rtol is None else rtol
    tol = jnp.maximum(jnp.asarray(atol, s.dtype), rt * s[0])
    s_full = jnp.zeros(n, dtype=s.dtype).at[: s.shape[0]].set(s)
    is_null = s_full <= tol  # (n,), ordered: null directions last
    if s.shape[0] < n:
        is_null = is_null.at[s.shape[0] :].set(True)
    V = Vt.T  # columns: right singular vectors
    N = jnp.where(is_null[None, :], V, 0.0)
    nullity = jnp.sum(is_null).astype(jnp.int32)
    # Put the null directions first.
    order = jnp.argsort(~is_null, stable=True)
    N = N[:, order]
    mask = jnp.any(jnp.abs(N) > coefficient_tol, axis=1)
    return guard(DependentColumns(mask=mask, null_space=N, nullity=nullity))


def manipulability_gradient(
    robot: Robot,
    q: Any,
    measure: str = "yoshikawa",
    rows: Any = "all",
    frame: int | str | None = None,
    point: Any = None,
    reference: str = "world_aligned",
) -> jax.Array:
    """``d m / d q`` of ``m(q) = manipulability(geometric_jacobian(robot, q, frame, point,
    reference), measure, rows)``; shape (dof,). Exact (``jax.grad``), finite at singularities.

    For Yoshikawa's measure over all rows of a (6, dof >= 6) Jacobian, away from singularities,
    it equals ``dm/dq_k = m * vec(J H_k^T) . vec((J J^T)^-1)`` with ``H_k`` the kinematic Hessian
    slice ``jk.kinematic_hessian(...)[k]`` (Haviland & Corke 2022; the Robotics Toolbox's
    ``jacobm``); unlike that formula, the autodiff gradient stays finite at singularities.
    Non-finite ``q`` or ``point`` (module doc): raises eagerly; NaN under a trace.
    """
    fn = "jk.manipulability_gradient"
    refuse_multi_dof(robot, fn, "differentiates with respect to q in a vector space")
    check_reference(reference)
    _check_measure(measure, fn)
    q = check_q(robot, q, fn=fn)
    q = q.astype(result_dtype(robot, q))
    f = robot.frame_index(frame)
    pt = check_point(point, q.dtype, fn)
    # Validate rows eagerly (shape 6).
    idx = _row_indices(rows, 6, fn)
    guard = finite_guard(fn, q=q, point=pt)
    q, pt = guard.clean(q), None if pt is None else guard.clean(pt)
    return guard(_manipulability_gradient(robot, q, f, pt, measure, idx, reference))


def _manipulability_gradient_kernel(robot, q, frame, point, measure, idx, reference):
    def m(qq):
        J = _jacobian_matrix(robot, qq, frame=frame, point=point, reference=reference)
        return _manipulability(J if idx is None else _take_rows(J, idx), measure)

    return jax.grad(m)(q)


def _jacobian_matrix_impl(robot, q, frame, point, reference):
    return jacobian_pass(robot, q, frame, point, reference).matrix()


# The Jacobian of q as a nested jit (a concrete robot static, its constants folded as when traced
# inline): JAX traces it, and differentiates and batches its jaxpr, once per robot, frame,
# reference and shapes, shared by every manipulability gradient of one computation (one per
# measure and rows) instead of once per call (a third of the trace time of nine gradients of
# the UR5). The compiled program holds the same operations: the same values, bit for bit.
_jacobian_matrix = robot_jit(_jacobian_matrix_impl, ("frame", "reference"))


# Eagerly one compiled program per robot and options (op by op, the gradient dispatched and
# compiled hundreds of primitives); traced inline under the caller's jit/vmap/grad.
_manipulability_gradient = eager(
    _manipulability_gradient_kernel, ("frame", "measure", "idx", "reference")
)


# ----------------------------------------------------------------------------- ellipsoids
class Ellipsoid(NamedTuple):
    """A task-space ellipsoid ``{x : x^T (axes diag(radii)^-2 axes^T) x <= 1}``.

    ``axes`` (m, m): unit principal directions as columns (the left singular vectors of the
    selected rows of J), in the Jacobian's basis; ``radii`` (m,): the semi-axis lengths, in the
    order of ``axes``' columns.
    """

    axes: jax.Array
    radii: jax.Array


def _ellipsoid(J: Any, rows: Any, fn: str):
    Jr, guard = _guarded(J, rows, fn)
    U, _, _ = jnp.linalg.svd(jax.lax.stop_gradient(Jr), full_matrices=True)
    return U, _task_singular_values(Jr), guard


def velocity_ellipsoid(J: Any, rows: Any = "translation") -> Ellipsoid:
    """The velocity ellipsoid ``{J qd : |qd| <= 1}`` of the selected rows of ``J``.

    Radii are the task-space singular values ``sigma_i`` (0 along directions the robot cannot
    move in: at a singularity, or for m > dof); axes the left singular vectors. The default rows
    are the translational ones (``"translation"``, m/s per unit joint speed), since an ellipsoid
    mixing metres and radians has no geometric meaning. Radii are differentiable everywhere;
    axes carry no derivative (``stop_gradient``: principal directions are not differentiable where
    radii coincide). Non-finite ``J`` (module doc): raises eagerly; NaN under a trace.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))
    >>> E = jk.velocity_ellipsoid(J, rows=[0, 1])  # the tip's (v_x, v_y) for |qd| <= 1
    >>> E.radii.round(6).tolist()
    [1.618034, 0.618034]
    """
    U, s, guard = _ellipsoid(J, rows, "jk.velocity_ellipsoid")
    return guard(Ellipsoid(axes=U, radii=s))


def force_ellipsoid(J: Any, rows: Any = "translation") -> Ellipsoid:
    """The force ellipsoid ``{F : |J^T F| <= 1}`` (wrenches balanced by unit joint torques).

    Same axes as :func:`velocity_ellipsoid`, radii ``1 / sigma_i``: ``inf`` along a singular
    direction (the structure then holds any force along it with no joint torque). The gradient of
    an infinite radius is 0 (double-where), never NaN. Non-finite ``J`` (module doc): raises
    eagerly; NaN (not ``inf``) under a trace.
    """
    U, s, guard = _ellipsoid(J, rows, "jk.force_ellipsoid")
    ok = s > 0
    inv = jnp.where(ok, 1.0 / jnp.where(ok, s, 1.0), jnp.inf)
    return guard(Ellipsoid(axes=U, radii=inv))


# ----------------------------------------------------------------------------- statics
def joint_torques(J: Any, wrench: Any) -> jax.Array:
    """Statics: the joint torques/forces ``tau = J^T F`` (dof,) that balance a wrench.

    ``wrench`` (m,) is ordered like the rows of ``J``: ``[f; n]`` (force in N, moment in N m)
    for a (6, dof) geometric Jacobian, with the moment taken about the Jacobian's point and both
    in its basis (``world_aligned``: about the frame origin, world axes; ``world``: about the
    world origin). ``tau`` is what the joints must exert for the end effector to apply ``F`` to
    the environment (equivalently, what an external wrench ``-F`` loads them with); power:
    ``F . (J qd) == tau . qd``. Non-finite ``J`` or ``wrench`` (module doc): raises eagerly; NaN
    under a trace.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))  # tip at (1, 1)
    >>> F = jnp.array([0.0, -1.0, 0.0, 0.0, 0.0, 0.0])  # 1 N downwards at the tip
    >>> jk.joint_torques(J, F).round(6).tolist()  # the torques that hold it
    [-1.0, 0.0]
    """
    fn = "jk.joint_torques"
    J = check_J(J, fn, f"jax.vmap({fn}, in_axes=(0, None))(Js, wrench)")
    F = jnp.asarray(wrench)
    if F.shape != (J.shape[0],):
        raise ShapeError(
            f"{fn}: wrench must have shape ({J.shape[0]},) to match J's rows "
            f"([f; n] for a 6-row Jacobian), got {F.shape}. Batch with jax.vmap."
        )
    guard = finite_guard(fn, J=J, wrench=F)
    J, F = guard.clean(J), guard.clean(F)
    return guard(J.T @ F.astype(J.dtype))


# ----------------------------------------------------------------------------- spherical wrist
class WristDecoupling(NamedTuple):
    """The arm/wrist decoupling of a 6-dof Jacobian at the wrist centre.

    With ``J_c`` the (6, 6) world-aligned Jacobian of the wrist centre ``c`` (the point where the
    three wrist axes meet), ``J_c = [[J11, J12], [J21, J22]]`` with ``J12 = 0``, so
    ``det J = det J11 * det J22`` (``det J`` does not depend on the reference point).

    Fields (scalars unless noted): ``det_J`` (of the tip Jacobian), ``det_arm`` (``det J11``: the
    wrist centre's linear velocity from the three arm joints), ``det_wrist`` (``det J22``: the
    angular velocity from the three wrist joints), ``sigma_min_arm``, ``sigma_min_wrist``
    (their smallest singular values), ``arm_singular``, ``wrist_singular`` (bool: below the
    threshold), ``wrist_centre`` (3,) in world coordinates, ``coupling`` (``max |J12|``; 0 for a
    spherical wrist up to rounding), ``axis_distance`` (largest distance of a wrist axis from
    ``wrist_centre``; 0 for a spherical wrist).
    """

    det_J: jax.Array
    det_arm: jax.Array
    det_wrist: jax.Array
    sigma_min_arm: jax.Array
    sigma_min_wrist: jax.Array
    arm_singular: jax.Array
    wrist_singular: jax.Array
    wrist_centre: jax.Array
    coupling: jax.Array
    axis_distance: jax.Array


def _wrist_joint_indices(robot: Robot, wrist_joints, fn: str) -> tuple[tuple[int, ...], tuple]:
    refuse_multi_dof(robot, fn, "needs 6 revolute or prismatic joints")
    if robot.dof != 6:
        raise JaxkinError(
            f"{fn}: the arm/wrist decoupling needs a 6-dof robot (3 arm joints, 3 wrist joints); "
            f"robot {robot.name!r} has {robot.dof}."
        )
    if wrist_joints is None:
        wrist = (3, 4, 5)
    else:
        wrist = []
        for w in wrist_joints:
            if isinstance(w, str):
                if w not in robot.joint_names:
                    raise JaxkinError(
                        f"{fn}: unknown joint {w!r}; joints are {list(robot.joint_names)}."
                    )
                wrist.append(robot.joint_names.index(w))
            elif isinstance(w, (int, np.integer)) and not isinstance(w, bool) and 0 <= w < 6:
                wrist.append(int(w))
            else:
                raise JaxkinError(f"{fn}: wrist joint {w!r} is not a joint name or index 0..5.")
        wrist = tuple(wrist)
        if len(set(wrist)) != 3:
            raise JaxkinError(f"{fn}: wrist_joints must name 3 distinct joints, got {wrist}.")
    kinds = robot.joint_kinds
    if any(kinds[i] != "revolute" for i in wrist):
        raise JaxkinError(
            f"{fn}: wrist joints {wrist} must be revolute (a spherical wrist), got "
            f"{[kinds[i] for i in wrist]}."
        )
    arm = tuple(i for i in range(6) if i not in wrist)
    # model joint (possibly several per q entry: use the first) driving each wrist q entry
    joint_of = {}
    for j, qi in enumerate(robot.q_index):
        if qi >= 0 and qi not in joint_of:
            joint_of[qi] = j
    return arm, wrist, tuple(joint_of[i] for i in wrist)


def wrist_centre(robot: Robot, q: Any, wrist_joints: Sequence[int | str] | None = None):
    """The point (3,) closest, in least squares, to the three wrist joint axes (world
    coordinates), and its largest distance from those axes (0 for a spherical wrist).

    ``wrist_joints`` names or indexes the wrist joints (default: the last three). The three axes
    of a spherical wrist meet in one point; two of them are always perpendicular, so the
    least-squares problem is well posed even at a wrist singularity. Non-finite ``q`` (module
    doc): raises eagerly; NaN under a trace.
    """
    fn = "jk.wrist_centre"
    _, _, wrist_model = _wrist_joint_indices(robot, wrist_joints, fn)
    q = check_q(robot, q, fn=fn)
    guard = finite_guard(fn, q=q)
    q = guard.clean(q)
    return guard(_wrist_centre_eager(robot, q, wrist_model))


def _wrist_centre(fp, wrist_model):
    """Least-squares intersection of the wrist axes of forward pass ``fp``, and the largest
    distance of an axis from it."""
    dtype = fp.p.dtype
    eye = jnp.eye(3, dtype=dtype)
    A = jnp.zeros((3, 3), dtype=dtype)
    b = jnp.zeros(3, dtype=dtype)
    Ps = []
    for j in wrist_model:
        z, o = fp.z[j], fp.o[j]
        P = eye - jnp.outer(z, z)
        Ps.append((P, o))
        A = A + P
        b = b + P @ o
    c = jnp.linalg.solve(A, b)
    d2 = jnp.max(jnp.stack([jnp.sum((P @ (c - o)) ** 2) for P, o in Ps]))
    return c, safe_sqrt(d2)  # finite gradient where the axes meet


def wrist_decoupling(
    robot: Robot,
    q: Any,
    threshold: float,
    *,
    frame: int | str | None = None,
    wrist_joints: Sequence[int | str] | None = None,
    check: bool = True,
) -> WristDecoupling:
    """Arm versus wrist singularities of a 6-dof robot with a spherical wrist.

    Builds the world-aligned Jacobian of ``frame`` (default: the tip) and moves its point to the
    wrist centre ``c`` (``v_c = v_tip + omega x (c - p_tip)``), which makes the upper-right block
    zero: ``det J = det J11 * det J22``. ``J11`` (3x3: linear rows, arm joints) is singular at the
    arm's singularities (elbow stretched, wrist centre on the shoulder axis), ``J22`` (3x3:
    angular rows, wrist joints) at the wrist's (two wrist axes aligned). Flags use
    ``sigma_min < threshold`` (m/s per rad/s for the arm, rad/s per rad/s for the wrist); the
    threshold has no default.

    Args:
      robot: a 6-dof robot; ``wrist_joints`` (default the last three) must be revolute.
      q: joint values (6,).
      threshold: singular-value threshold of the flags.
      frame: the frame whose Jacobian is decoupled (default: the tip).
      wrist_joints: names or indices of the three wrist joints.
      check: when called eagerly, raise :class:`~jaxkin.JaxkinError` if the wrist axes do not
        meet in one point (``axis_distance > 1e-9 * max(1, |c|)``): the robot has no spherical
        wrist and the decoupling does not hold. Under ``jit``/``vmap`` inspect
        ``axis_distance`` and ``coupling`` yourself.

    Non-finite ``q`` or ``threshold`` (module doc): raises eagerly; under a trace the numbers are
    NaN and both flags True ("possibly singular").
    """
    fn = "jk.wrist_decoupling"
    arm, wrist, wrist_model = _wrist_joint_indices(robot, wrist_joints, fn)
    q = check_q(robot, q, fn=fn, batch_hint=f"jax.vmap(lambda q: {fn}(robot, q, threshold))(qs)")
    guard = finite_guard(fn, q=q, threshold=threshold)
    q = guard.clean(q)
    f = robot.frame_index(frame)
    out = guard(_decoupling(robot, q, f, threshold, arm, wrist, wrist_model))
    if check and not is_traced(robot, q):
        d = float(out.axis_distance)
        scale = max(1.0, float(jnp.linalg.norm(out.wrist_centre)))
        if not d <= 1e-9 * scale:
            raise JaxkinError(
                f"{fn}: the wrist axes of robot {robot.name!r} (joints "
                f"{[robot.joint_names[i] for i in wrist]}) do not meet in one point (largest "
                f"distance from their least-squares intersection: {d:.3g} m), so the robot has no "
                "spherical wrist and det J != det J11 det J22. Pass the right wrist_joints, or "
                "analyse singular_values / dependent_columns of the full Jacobian instead."
            )
    return out


def _decoupling_kernel(robot, q, frame, threshold, arm, wrist, wrist_model) -> WristDecoupling:
    """The unguarded :class:`WristDecoupling` of checked arguments."""
    g = jacobian_pass(robot, q, frame, None, "world_aligned")
    J, p = g.matrix(), g.pose()[:3, 3]  # the frame's origin from the Jacobian's own pass
    c, dist = _wrist_centre(forward_pass(robot, q), wrist_model)  # joint axes and origins
    r = c - p
    Jv_c = J[:3] + jnp.cross(J[3:].T, r).T  # omega x r per column
    J11 = Jv_c[:, jnp.array(arm)]
    J12 = Jv_c[:, jnp.array(wrist)]
    J22 = J[3:, jnp.array(wrist)]
    s11 = jnp.linalg.svd(J11, compute_uv=False)
    s22 = jnp.linalg.svd(J22, compute_uv=False)
    return WristDecoupling(
        det_J=jnp.linalg.det(J),
        det_arm=jnp.linalg.det(J11),
        det_wrist=jnp.linalg.det(J22),
        sigma_min_arm=s11[-1],
        sigma_min_wrist=s22[-1],
        arm_singular=s11[-1] < threshold,
        wrist_singular=s22[-1] < threshold,
        wrist_centre=c,
        coupling=jnp.max(jnp.abs(J12)),
        axis_distance=dist,
    )


def _wrist_centre_kernel(robot, q, wrist_model):
    return _wrist_centre(forward_pass(robot, q), wrist_model)


# Eagerly one compiled program per robot and joints (op by op, each call dispatched the forward
# pass's primitives); traced inline under the caller's jit/vmap/grad.
_wrist_centre_eager = eager(_wrist_centre_kernel, ("wrist_model",))
_decoupling = eager(_decoupling_kernel, ("frame", "arm", "wrist", "wrist_model"))
