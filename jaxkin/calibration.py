"""Kinematic calibration: fit a robot's parameters to measured poses with optax.

Given configurations ``qs`` (M, dof) and the poses ``Ts_measured`` (M, 4, 4) an external sensor
(laser tracker, camera) measured for ``frame`` at them, :func:`calibrate` adjusts chosen
parameters of the model so that ``fk(robot, q_k, frame)`` matches ``Ts_measured[k]``. It
differentiates through the model: the parameters are leaves of the :class:`~jaxkin.Robot`
pytree, so ``jax.grad`` of the loss with respect to them is exact.

Loss (weighted least squares, the maximum-likelihood fit for Gaussian sensor noise)::

    L = 1/M sum_k ( |p_k - p(q_k)|^2 / sigma_p^2 + |log(R_k R(q_k)^T)|^2 / sigma_o^2 )

with ``sigma_p = position_sigma`` (m) and ``sigma_o = orientation_sigma`` (rad), minimised with
an optax optimiser (default: ``optax.lbfgs`` with a backtracking line search, which compiles
about twice as fast as its default zoom line search) in a jitted ``lax.while_loop``.

Which parameters (``params=``): leaf names of the robot's ``params`` dict (``"a"``, ``"alpha"``,
``"d"``, ``"theta"`` for DH robots, ``"xyz"``, ``"rpy"`` for joint placements), ``"offset"``
(joint zero offsets), ``"base"`` and ``"tool"`` (6-vector corrections ``[dp; dw]`` in the
transform's own axes: ``T' = T Trans(dp) exp(skew(dw))``), each either all of its entries (a name)
or some (a mapping name -> boolean mask of the leaf's shape, True = free). Not every set can be
recovered from end-effector poses: before fitting, :func:`identifiability` checks the
regressor's rank and names the parameter combinations the data cannot tell apart.

Data are refused eagerly (:class:`~jaxkin.JaxkinError` naming the argument) when ``qs`` or
``Ts_measured`` hold NaN or inf, when a measured pose is not a rigid transform (e.g. transposed),
or when there are no measurements. Under ``jit``/``vmap`` (traced data) the non-finite policy of
:mod:`jaxkin.analysis` applies: the fitted values are NaN and ``converged`` is False.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import spatial
from ._checks import check_poses, finite_guard, is_traced, refuse_multi_dof
from ._forward import forward_pass, frame_pose
from ._jit import robot_jit
from .errors import JaxkinError, ShapeError
from .model import Robot
from .optimizers import default_optimizer
from .pose_errors import pose_residual

__all__ = ["CalibrationResult", "Identifiability", "calibrate", "identifiability"]

_TRANSFORMS = ("base", "tool")


class CalibrationResult(NamedTuple):
    """Output of :func:`calibrate`.

    ``robot``: the calibrated robot (same topology, fitted leaves replaced); ``params``: dict of
    the fitted values of each selected leaf (for ``"base"``/``"tool"``: the fitted (4, 4)
    transform); ``std``: dict of predicted standard deviations of the free entries (same shapes,
    0 for fixed entries; for base/tool the 6-vector ``[dp; dw]``), from the Gauss-Newton
    covariance ``s^2 (A^T A)^-1`` of the weighted residuals at the solution; ``loss_history``
    (max_steps,) with NaN after the last step; ``steps``; ``rms_position_before``/``_after`` (m)
    and ``rms_orientation_before``/``_after`` (rad): root mean square pose errors over the
    measurements, with the initial and the fitted model.

    Status: ``converged`` (bool scalar) is True only when the loss stopped changing (relative
    ``tol``) while the loss and the fitted parameters were finite; it is False when the loss
    became NaN or inf, when ``max_steps`` ran out first, and under a trace for non-finite data.
    ``identifiable`` (bool scalar) is True when :func:`identifiability` found every free
    parameter determined by the data; False when it did not (``check_identifiable=False`` fits
    anyway: the fit then wanders along the undetermined directions, whatever ``converged`` says)
    and under a trace, where that host-side check cannot run (check once outside). Trust the fit
    when both are True.
    """

    robot: Robot
    params: dict[str, jax.Array]
    std: dict[str, jax.Array]
    loss_history: jax.Array
    steps: jax.Array
    converged: jax.Array
    rms_position_before: jax.Array
    rms_position_after: jax.Array
    rms_orientation_before: jax.Array
    rms_orientation_after: jax.Array
    identifiable: jax.Array


class Identifiability(NamedTuple):
    """Rank of the calibration regressor (see :func:`identifiability`).

    ``singular_values`` (P,) of the scaled regressor (each free parameter's column normalised to
    unit length); ``rank``; ``names`` (P,): the free parameters, e.g. ``"xyz[2, 0]"``;
    ``unidentifiable``: the parameters whose effect on the measured poses is a combination of
    the effects of the parameters listed before them (taken in order): fix them (mask them out)
    and the rest are identifiable.
    """

    singular_values: np.ndarray
    rank: int
    names: list[str]
    unidentifiable: list[str]


# ----------------------------------------------------------------------------- parameter sets
def _leaf(robot: Robot, name: str):
    if name == "offset":
        return robot.offset
    if name in robot.params:
        return robot.params[name]
    raise JaxkinError(
        f"robot {robot.name!r} has no calibratable parameter {name!r}; choose from "
        f"{_allowed(robot)}."
    )


def _allowed(robot: Robot) -> list[str]:
    return [*robot.params, "offset", *_TRANSFORMS]


def _masks(robot: Robot, params: Any) -> dict[str, np.ndarray]:
    """name -> boolean mask of free entries (host side, validated)."""
    if isinstance(params, str):
        params = (params,)
    if isinstance(params, Mapping):
        items = list(params.items())
    elif isinstance(params, Sequence) and len(params) > 0:
        items = [(name, None) for name in params]
    else:
        raise JaxkinError(
            f"params must be a non-empty sequence of names or a mapping name -> mask; choose "
            f"names from {_allowed(robot)}."
        )
    masks = {}
    for name, mask in items:
        if not isinstance(name, str):
            raise JaxkinError(f"parameter names must be strings, got {name!r}.")
        shape = (6,) if name in _TRANSFORMS else tuple(np.shape(_leaf(robot, name)))
        if name == "tool" and not robot.has_tool:
            raise JaxkinError(f"robot {robot.name!r} has no tool transform to calibrate.")
        if mask is None:
            m = np.ones(shape, dtype=bool)
        else:
            m = np.asarray(mask)
            if m.shape != shape or m.dtype != bool:
                raise ShapeError(
                    f"mask of {name!r} must be a boolean array of shape {shape}, got "
                    f"{m.dtype} {m.shape}."
                )
        if not m.any():
            continue
        masks[name] = m
    if not masks:
        raise JaxkinError("no free parameter selected (every mask is all False).")
    return masks


def _names(masks: dict[str, np.ndarray]) -> list[str]:
    out = []
    for name, m in masks.items():
        for idx in zip(*np.nonzero(m), strict=True):
            out.append(f"{name}[{', '.join(str(int(i)) for i in idx)}]")
    return out


def _apply(robot: Robot, masks: dict[str, np.ndarray], theta: jax.Array) -> Robot:
    """The robot with the free entries moved by ``theta`` (P,) (a correction, 0 = nominal)."""
    params = dict(robot.params)
    changes: dict[str, Any] = {}
    k = 0
    for name, m in masks.items():
        n = int(m.sum())
        delta = theta[k : k + n]
        k += n
        idx = np.nonzero(m)
        if name in _TRANSFORMS:
            d = jnp.zeros(6, theta.dtype).at[idx].set(delta)
            T = getattr(robot, name).astype(theta.dtype)
            R = T[:3, :3] @ spatial.exp_so3(d[3:])
            p = T[:3, 3] + T[:3, :3] @ d[:3]
            changes[name] = spatial.make_transform(R, p)
        elif name == "offset":
            changes["offset"] = robot.offset.astype(theta.dtype).at[idx].add(delta)
        else:
            params[name] = params[name].astype(theta.dtype).at[idx].add(delta)
    return robot.replace(params=params, **changes)


def _pose_residuals(robot: Robot, qs, Ts, f: int, wp, wo) -> jax.Array:
    """Weighted residuals (M, 6): ``[dp / sigma_p; log(R_m R^T) / sigma_o]``."""

    def one(q, T):
        # The full forward pass, not frame_pose: calibrate's compiled loop (line search included)
        # fuses differently around the path-only pass, moving fits by ~1e-13 (not bit-identical).
        fp = forward_pass(robot, q)
        e = pose_residual(spatial.make_transform(fp.R[f], fp.p[f]), T)
        return jnp.concatenate([e[:3] * wp, e[3:] * wo])

    return jax.vmap(one)(qs, Ts)


def _check_qs(robot: Robot, qs: Any, fn: str):
    """Configurations (M, dof), M >= 1, as the robot's dtype, and their non-finite guard."""
    refuse_multi_dof(robot, fn, "fits joint offsets and parameters of 1-dof joints only")
    qs = jnp.asarray(qs)
    if qs.ndim != 2 or qs.shape[1] != robot.dof:
        raise ShapeError(f"{fn}: qs must have shape (M, {robot.dof}), got {qs.shape}.")
    if qs.shape[0] == 0:
        raise JaxkinError(
            f"{fn}: no measurements (qs has 0 rows): give at least one configuration and its "
            "measured pose (enough of them to determine the free parameters)."
        )
    guard = finite_guard(fn, qs=qs)
    return qs.astype(robot.dtype), guard


def _check_data(robot: Robot, qs: Any, Ts: Any, fn: str):
    """Checked ``qs`` (M, dof) and ``Ts`` (M, 4, 4) (finite and rigid when concrete), and the
    non-finite guard of ``qs``."""
    qs, _ = _check_qs(robot, qs, fn)
    shape = tuple(Ts.shape) if hasattr(Ts, "shape") else np.shape(Ts)
    if len(shape) == 3 and shape[1:] == (4, 4) and shape[0] != qs.shape[0]:
        raise ShapeError(
            f"{fn}: Ts_measured must have shape ({qs.shape[0]}, 4, 4) (one pose per row of qs), "
            f"got {shape}."
        )
    Ts, _ = check_poses(Ts, fn, "Ts_measured", robot.dtype, batch="required")
    return qs, Ts, finite_guard(fn, qs=qs, Ts_measured=Ts)


# ----------------------------------------------------------------------------- identifiability
def _regressor_impl(robot, qs, theta0, wp, wo, *, masks_key, f):
    """d pose / d theta (6M, P) at ``theta0``, rows ``[dp * wp; dw * wo]`` (``dw`` the angular
    velocity of the frame per unit parameter): minus the residuals' derivative near a fit."""
    masks = {k: np.asarray(v) for k, v in masks_key}

    def poses(theta):
        r = _apply(robot, masks, theta)

        def one(q):
            R, p = frame_pose(r, q, f)
            return p, R

        p, R = jax.vmap(one)(qs)
        return (p, R), R

    # The rotations at theta0 come out of the same forward-mode pass (its primal).
    (dP, dRt), R0 = jax.jacfwd(poses, has_aux=True)(theta0)  # (M, 3, P), (M, 3, 3, P)
    dw = jax.vmap(
        lambda dRk, R: jax.vmap(lambda d: spatial.vee(d @ R.T), in_axes=2, out_axes=1)(dRk)
    )(dRt, R0)  # (M, 3, P)
    return jnp.concatenate([dP * wp, dw * wo], axis=1).reshape(-1, theta0.shape[0])


_regressor = robot_jit(_regressor_impl, ("masks_key", "f"))


def _masks_key(masks: dict[str, np.ndarray]):
    return tuple((k, _HashableMask(v)) for k, v in masks.items())


def identifiability(
    robot: Robot,
    qs: Any,
    params: Any,
    frame: int | str | None = None,
    *,
    position_sigma: float = 1.0,
    orientation_sigma: float = 1.0,
    rtol: float = 1e-8,
) -> Identifiability:
    """Which of ``params`` the poses of ``frame`` at ``qs`` (M, dof) can determine.

    Builds the regressor ``A = d residuals / d theta`` (6M, P) at the nominal parameters
    (``jax.jacfwd``, residual rows weighted by ``1 / sigma``), scales each column to unit length
    and takes its singular values (``rank``: those above ``rtol * sigma_max``). Then, in the
    order of ``names``, a parameter is *unidentifiable* when its column lies (to ``rtol``) in the
    span of the columns before it: e.g. two offsets along one joint axis, a joint zero offset and
    a rotation about the same axis, or a parameter no measured pose depends on.
    Host-side helper (numpy arrays and Python lists): raises :class:`~jaxkin.JaxkinError` under a
    trace, for non-finite ``qs`` and for no ``qs`` at all.
    """
    masks = _masks(robot, params)
    f = robot.frame_index(frame)
    if is_traced(robot, qs):
        raise JaxkinError(
            "jk.identifiability works on concrete data (it returns Python lists): call it outside "
            "jit/vmap/grad. jk.calibrate calls it unless check_identifiable=False; inside a "
            "transformation pass check_identifiable=False and check once outside."
        )
    qs, _ = _check_qs(robot, qs, "jk.identifiability")
    names = _names(masks)
    A = _regressor(
        robot,
        qs,
        np.zeros(len(names), robot.dtype),
        jnp.asarray(1.0 / position_sigma, robot.dtype),
        jnp.asarray(1.0 / orientation_sigma, robot.dtype),
        masks_key=_masks_key(masks),
        f=f,
    )
    A = np.asarray(A, dtype=np.float64)
    norms = np.linalg.norm(A, axis=0)
    A = A / np.where(norms > 0, norms, 1.0)
    s = np.linalg.svd(A, compute_uv=False)
    rank = int(np.sum(s > rtol * (s[0] if s.size else 0.0)))
    # Greedy, in order: modified Gram-Schmidt with one reorthogonalisation.
    basis: list[np.ndarray] = []
    redundant = []
    for i, name in enumerate(names):
        v = A[:, i].copy() if norms[i] > 0 else np.zeros(A.shape[0])
        for _ in range(2):
            for b in basis:
                v -= (b @ v) * b
        r = np.linalg.norm(v)
        if r <= max(rtol, 1e-12) ** 0.5 * 1e-2 or norms[i] == 0:
            redundant.append(name)
        else:
            basis.append(v / r)
    return Identifiability(singular_values=s, rank=rank, names=names, unidentifiable=redundant)


# ----------------------------------------------------------------------------- fit
def _fit_impl(robot, qs, Ts, wp, wo, tol, *, masks_key, f, optimizer, max_steps):
    import optax

    masks = {k: np.asarray(v) for k, v in masks_key}
    P = sum(int(m.sum()) for m in masks.values())
    dtype = qs.dtype
    M = qs.shape[0]

    def loss(theta):
        r = _pose_residuals(_apply(robot, masks, theta), qs, Ts, f, wp, wo)
        return jnp.sum(r * r) / M

    # Not optax.value_and_grad_from_state with the line search's store_grad=True: optax transposes
    # its linearisation with a Python-float cotangent (float64 under x64), which a float32 loss
    # rejects with a TypeError.
    vg = jax.value_and_grad(loss)
    theta0 = jnp.zeros(P, dtype)
    history0 = jnp.full((max_steps,), jnp.nan, dtype)

    def cond(c):
        _, _, k, _, _, met, finite = c
        return (k < max_steps) & ~met & finite

    def body(c):
        theta, state, k, hist, v_prev, _, _ = c
        v, g = vg(theta)
        hist = hist.at[jnp.maximum(k - 1, 0)].set(jnp.where(k > 0, v, hist[0]))
        updates, state = optimizer.update(g, state, theta, value=v, grad=g, value_fn=loss)
        theta = optax.apply_updates(theta, updates)
        # Converged: the loss stopped changing (relative tol). A NaN or inf loss stops the loop
        # without converging.
        met = jnp.abs(v_prev - v) <= tol * jnp.maximum(v, 1e-300)
        return theta, state, k + 1, hist, v, met, jnp.isfinite(v)

    init = (
        theta0,
        optimizer.init(theta0),
        jnp.zeros((), jnp.int32),
        history0,
        jnp.asarray(jnp.inf, dtype),
        jnp.asarray(False),
        jnp.asarray(True),
    )
    theta, _, k, hist, _, met, finite = jax.lax.while_loop(cond, body, init)
    converged = met & finite & jnp.all(jnp.isfinite(theta))
    return theta, hist, k, converged


_fit = robot_jit(_fit_impl, ("masks_key", "f", "optimizer", "max_steps"))


def calibrate(
    robot: Robot,
    qs: Any,
    Ts_measured: Any,
    params: Any,
    frame: int | str | None = None,
    *,
    position_sigma: float = 1e-3,
    orientation_sigma: float = 1e-3,
    optimizer: Any = None,
    max_steps: int = 200,
    tol: float = 1e-12,
    check_identifiable: bool = True,
) -> CalibrationResult:
    """Fit ``params`` of ``robot`` to measured poses of ``frame`` (see the module doc).

    Args:
      robot: the nominal model (the starting point).
      qs: (M, dof) joint values at which the poses were measured.
      Ts_measured: (M, 4, 4) measured poses ``T_world_frame``.
      params: the parameters to fit: names or a mapping name -> boolean mask (module doc).
      frame: the measured frame (default: the tip).
      position_sigma, orientation_sigma: the measurement noise (m, rad) that weights the two
        parts of the residual.
      optimizer: an optax ``GradientTransformation`` (default: L-BFGS with a backtracking line
        search). Optimisers hash by identity: reuse one object to reuse the compiled fit.
      max_steps: optimiser steps at most.
      tol: stop when the loss changes by less than ``tol`` relative to its value.
      check_identifiable: first check (:func:`identifiability`) that the data determine every
        free parameter, and raise :class:`~jaxkin.JaxkinError` naming the combinations that
        they do not (a fit would wander along them). With False the fit runs anyway and the
        result's ``identifiable`` field reports the check (False under a trace: not checked).

    Returns a :class:`CalibrationResult`; check its ``converged`` and ``identifiable``.
    Non-finite, non-rigid or no measurements: see the module doc.
    """
    fn = "jk.calibrate"
    if not isinstance(robot, Robot):
        raise ShapeError(f"{fn} expects a jaxkin Robot, got {type(robot).__name__}.")
    masks = _masks(robot, params)
    f = robot.frame_index(frame)
    qs, Ts, guard = _check_data(robot, qs, Ts_measured, fn)
    qs, Ts = guard.clean(qs), guard.clean(Ts)
    _check_fit_settings(fn, position_sigma, orientation_sigma, tol, max_steps)
    identifiable = _check_identifiability(
        robot, qs, masks, f, fn, position_sigma, orientation_sigma, check_identifiable
    )
    if optimizer is None:
        optimizer = default_optimizer()
    dtype = robot.dtype
    wp = jnp.asarray(1.0 / position_sigma, dtype)
    wo = jnp.asarray(1.0 / orientation_sigma, dtype)
    masks_key = _masks_key(masks)
    theta, hist, k, converged = _fit(
        robot,
        qs,
        Ts,
        wp,
        wo,
        jnp.asarray(tol, dtype),
        masks_key=masks_key,
        f=f,
        optimizer=optimizer,
        max_steps=int(max_steps),
    )
    # Non-finite traced data (module doc): NaN parameters and history, not converged.
    theta, hist = guard((theta, hist))
    if guard.bad is not False:
        converged = converged & ~guard.bad
    # The regressor at the fit: the program identifiability compiled (theta is an argument).
    A = _regressor(robot, qs, theta, wp, wo, masks_key=masks_key, f=f)
    fitted, values, stds, before, after = _summary(
        robot, qs, Ts, theta, A, wp, wo, masks_key=masks_key, f=f
    )
    return CalibrationResult(
        robot=fitted,
        params=values,
        std=stds,
        loss_history=hist,
        steps=k,
        converged=converged,
        rms_position_before=before[0],
        rms_position_after=after[0],
        rms_orientation_before=before[1],
        rms_orientation_after=after[1],
        identifiable=jnp.asarray(identifiable),
    )


def _check_fit_settings(fn: str, position_sigma, orientation_sigma, tol, max_steps) -> None:
    """Refuse non-positive sigmas, a negative tol and a max_steps that is no integer >= 1."""
    if not (position_sigma > 0 and orientation_sigma > 0):
        raise JaxkinError(f"{fn}: position_sigma and orientation_sigma must be > 0.")
    if not tol >= 0:
        raise JaxkinError(f"{fn}: tol must be a number >= 0, got {tol!r}.")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise JaxkinError(f"{fn}: max_steps must be an integer >= 1, got {max_steps!r}.")


def _check_identifiability(
    robot: Robot,
    qs,
    masks: dict[str, np.ndarray],
    f: int,
    fn: str,
    position_sigma: float,
    orientation_sigma: float,
    check_identifiable: bool,
) -> bool:
    """The result's ``identifiable`` flag (False under a trace: not checked); raises
    :class:`~jaxkin.JaxkinError` when ``check_identifiable`` and some parameter is not."""
    identifiable = False  # under a trace: not checked
    if check_identifiable or not is_traced(robot, qs):
        ident = identifiability(
            robot,
            qs,
            masks,
            f,
            position_sigma=position_sigma,
            orientation_sigma=orientation_sigma,
        )
        identifiable = not ident.unidentifiable
        if check_identifiable and ident.unidentifiable:
            raise JaxkinError(
                f"{fn}: the measurements cannot determine all of the {len(ident.names)} free "
                f"parameters (regressor rank {ident.rank}): {ident.unidentifiable} only move the "
                "measured poses in ways the parameters listed before them already do. Fix them "
                "(mask them out), or add measurements that excite them; check_identifiable=False "
                "fits anyway (the fit then wanders along the unidentifiable directions)."
            )
    return identifiable


def _summary_impl(robot, qs, Ts, theta, A, wp, wo, *, masks_key, f):
    """The report of a fit, one program per robot, masks, frame and shapes (as the fit itself):
    the fitted robot, the result's ``params`` and ``std`` dicts, and the RMS position and
    orientation errors ``(before, after)`` with the nominal parameters and with the correction
    ``theta``. ``A`` is the weighted regressor at ``theta`` (:func:`_regressor`)."""
    masks = {k: np.asarray(v) for k, v in masks_key}
    one = jnp.ones((), qs.dtype)
    # The nominal robot itself, not moved by a zero correction: its constants fold.
    r0 = _pose_residuals(robot, qs, Ts, f, one, one)
    fitted = _apply(robot, masks, theta)
    r = _pose_residuals(fitted, qs, Ts, f, one, one)
    weights = jnp.concatenate([jnp.broadcast_to(wp, (3,)), jnp.broadcast_to(wo, (3,))])
    std = _fit_std((r * weights[None, :]).reshape(-1), A)
    values, stds = _values_and_stds(fitted, masks, std, qs.dtype)
    return fitted, values, stds, _rms_errors(r0), _rms_errors(r)


_summary = robot_jit(_summary_impl, ("masks_key", "f"))


def _rms_errors(r) -> tuple[jax.Array, jax.Array]:
    """The RMS position and orientation errors of unweighted residuals ``r`` (M, 6)."""
    return (
        jnp.sqrt(jnp.mean(jnp.sum(r[:, :3] ** 2, axis=1))),
        jnp.sqrt(jnp.mean(jnp.sum(r[:, 3:] ** 2, axis=1))),
    )


def _fit_std(r, A) -> jax.Array:
    """Predicted standard deviations (P,) of the free parameters from the weighted residuals
    ``r`` (6M,) and regressor ``A`` (6M, P) at the fit: the square roots of the diagonal of
    ``s^2 (A^T A)^-1``."""
    s2 = jnp.sum(r * r) / max(r.shape[0] - A.shape[1], 1)
    cov = s2 * jnp.linalg.pinv(A.T @ A, hermitian=True)
    return jnp.sqrt(jnp.maximum(jnp.diagonal(cov), 0.0))


def _values_and_stds(fitted: Robot, masks: dict[str, np.ndarray], std, dtype):
    """The result's ``params`` and ``std`` dicts: each selected leaf of the fitted robot (the
    (4, 4) transform for base/tool) and ``std`` (P,) spread over its free entries."""
    values: dict[str, jax.Array] = {}
    stds: dict[str, jax.Array] = {}
    kk = 0
    for name, m in masks.items():
        n = int(m.sum())
        if name in _TRANSFORMS:
            values[name] = getattr(fitted, name)
            stds[name] = jnp.zeros(6, dtype).at[np.nonzero(m)].set(std[kk : kk + n])
        else:
            values[name] = _leaf(fitted, name)
            stds[name] = jnp.zeros(m.shape, dtype).at[np.nonzero(m)].set(std[kk : kk + n])
        kk += n
    return values, stds


class _HashableMask:
    """A boolean mask usable as a static jit argument (hash and equality by value)."""

    def __init__(self, m: np.ndarray):
        self.m = np.asarray(m, dtype=bool)
        self._key = (self.m.shape, self.m.tobytes())

    def __array__(self, dtype=None, copy=None):
        return self.m if dtype is None else self.m.astype(dtype)

    def __hash__(self):
        return hash(self._key)

    def __eq__(self, other):
        return isinstance(other, _HashableMask) and self._key == other._key
