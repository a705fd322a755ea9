"""Private: every input check, written once (the one notion of "traced", :func:`is_traced`,
lives in :mod:`jaxkin._traces`, below the model, and is re-exported here).

Public functions check their arguments here at entry, once; kernels take checked arrays and do
not check again. Checks run in Python before tracing and raise :class:`~jaxkin.ShapeError` or
:class:`~jaxkin.JaxkinError` naming what was expected, what was given and the fix.

Value checks (non-finite input, singular configurations) follow one policy, :func:`error_if`:
called eagerly they raise; under a trace (``jit``/``vmap``/``grad``), where values cannot raise,
the result is replaced by NaN.

Non-finite input follows the policy documented once in :mod:`jaxkin.analysis` ("Non-finite
input"): :func:`finite_guard` implements it (eagerly raise naming the argument; under a trace
poison the result: NaN values, True flags, -1 counts).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._traces import is_traced, is_tracer
from .errors import JaxkinError, ModelError, ShapeError
from .model import Robot

REFERENCES = ("world_aligned", "local", "world")
_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))


def error_if(bad: Any, error: Callable[[], Exception], value: Any, *trees: Any) -> Any:
    """The non-finite/singular policy: raise ``error()`` eagerly when ``bad`` holds, otherwise
    return ``value``; when ``trees`` (or ``bad``) are traced, return ``value`` with NaN wherever
    ``bad`` holds (``bad`` broadcasts against each leaf of ``value``)."""
    if not is_traced(bad, *trees):
        if bool(np.any(np.asarray(bad))):
            raise error()
        return value
    return FiniteGuard(jnp.asarray(bad))(value)


class FiniteGuard:
    """The non-finite policy of one call (module doc), from :func:`finite_guard`.

    ``bad``: False (eager: the inputs were checked), or a traced bool scalar, True where some
    input holds NaN or inf. Calling the guard on a result poisons it where ``bad`` holds: float
    leaves NaN, bool leaves True, integer leaves -1; eagerly it returns the result unchanged.
    Finite results are unchanged bit for bit (a multiplication by 1.0, whose derivative is 1.0).
    """

    def __init__(self, bad: Any):
        self.bad = bad

    def clean(self, x: Any) -> Any:
        """``x`` with its non-finite entries replaced by 0 when traced (eagerly ``x`` itself), for
        kernels that must not see them: LAPACK's SVD can loop forever on inf. The result computed
        from it is then poisoned by calling the guard."""
        if self.bad is False:
            return x
        return jnp.where(jnp.isfinite(x), x, jnp.zeros_like(x))

    def __call__(self, value: Any) -> Any:
        bad = self.bad
        if bad is False:
            return value

        def poison(v):
            v = jnp.asarray(v)
            if jnp.issubdtype(v.dtype, jnp.inexact):
                return v * jnp.where(bad, jnp.nan, 1.0).astype(v.dtype)
            if v.dtype == jnp.bool_:
                return v | bad
            return jnp.where(bad, jnp.asarray(-1, v.dtype), v)

        return jax.tree_util.tree_map(poison, value)


def finite_guard(fn: str, **inputs: Any) -> FiniteGuard:
    """The entry check of the non-finite policy (module doc) for public function ``fn``.

    ``inputs`` are the argument names and values whose entries must be finite (None skipped).
    Eagerly (no tracer among them) raises :class:`~jaxkin.JaxkinError` naming the first one that
    holds NaN or inf; otherwise returns the :class:`FiniteGuard` that poisons the result.
    """
    inputs = {k: v for k, v in inputs.items() if v is not None}
    if not is_traced(*inputs.values()):
        for name, x in inputs.items():
            a = np.asarray(x)
            if a.dtype.kind in "fc" and not np.all(np.isfinite(a)):
                raise JaxkinError(
                    f"{fn}: {name} contains NaN or inf, so no meaningful result exists (see "
                    "'Non-finite input' in jaxkin.analysis). Find where it came from, e.g. with "
                    "jax.config.update('jax_debug_nans', True)."
                )
        return FiniteGuard(False)
    arrays = [jnp.asarray(x) for x in inputs.values()]
    ok = [jnp.all(jnp.isfinite(x)) for x in arrays if jnp.issubdtype(x.dtype, jnp.inexact)]
    return FiniteGuard(~jnp.all(jnp.stack(ok)) if ok else False)


def refuse_nonfinite(x: Any, what: str, fn: str) -> None:
    """Eagerly: raise :class:`~jaxkin.JaxkinError` when ``x`` holds NaN or inf, for inputs that
    must be finite whose traced values a kernel handles itself (IK's ``nonfinite`` result code).
    A traced ``x`` is not checked."""
    if not is_traced(x) and not np.all(np.isfinite(np.asarray(x, dtype=np.float64))):
        raise JaxkinError(f"{fn}: {what} contains NaN or inf.")


def host_side(fn: str, **inputs: Any) -> None:
    """The non-finite policy (module doc) for a host-side result (a Python string, say): it
    cannot be poisoned, so a traced input raises too, and a concrete non-finite one raises as
    :func:`finite_guard` does."""
    if is_traced(*inputs.values()):
        raise JaxkinError(
            f"{fn} returns a Python string, so it works on concrete values only: call it outside "
            "jit/vmap/grad (e.g. on jax.device_get of the traced result)."
        )
    finite_guard(fn, **inputs)


# ----------------------------------------------------------------------------- dtypes and math
def result_dtype(robot: Robot, *arrays: Any) -> np.dtype:
    """The float dtype of a computation on ``robot`` and float ``arrays``: float32 only if all
    are (numpy's promotion, which equals JAX's for float32/float64 and is much cheaper)."""
    dtype = robot.base.dtype
    if all(a.dtype == dtype for a in arrays):  # the common case, without numpy's promotion
        return np.dtype(dtype)
    return np.result_type(dtype, *(a.dtype for a in arrays))


# ----------------------------------------------------------------------------- arrays
def _as_array(x: Any, what: str, fn: str, expected: str) -> Any:
    """``x`` as something with ``shape`` and ``dtype`` (lists become numpy), or a ShapeError."""
    if hasattr(x, "shape") and hasattr(x, "dtype"):
        return x
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        if isinstance(x, (list, tuple)):
            expected = "a sequence of numbers"
        raise ShapeError(f"{fn}: {what} must be {expected}, got {x!r:.80}.") from None


def _numeric(x: Any, what: str, fn: str) -> None:
    kind = np.dtype(x.dtype).kind
    if kind == "c":
        raise ShapeError(f"{fn}: {what} must be real, got complex dtype {x.dtype}.")
    if kind not in "fiub":
        raise ShapeError(f"{fn}: {what} must be an array of numbers, got dtype {x.dtype}.")


def _batch_hint(what: str, code: str) -> str:
    """The sentence suggesting ``code`` (which must run when pasted) for a batch of ``what``."""
    how = "use jax.vmap, e.g." if code.startswith("jax.vmap") else "use, e.g."
    return f" For a batch of {what} {how} {code}."


def host_float_array(x: Any, dtype: Any) -> np.ndarray:
    """Host data ``x`` as the numpy array ``jnp.asarray`` would make of it (float64 becomes
    float32 while x64 is off; integer and boolean input becomes ``dtype``), without the device
    round trip."""
    x = np.asarray(x)
    if x.dtype.kind != "f":
        x = x.astype(dtype)
    return x.astype(jax.dtypes.canonicalize_dtype(x.dtype), copy=False)


def _float_input(x: Any, dtype: Any, host: bool) -> Any:
    """Checked input as a float array: host data stays numpy with ``host`` (see ``check_q``)."""
    if host and not isinstance(x, jax.Array):
        return host_float_array(x, dtype)
    return _float_array(x, dtype)


def _float_array(x: Any, dtype: Any) -> jax.Array:
    """``x`` as a JAX array; integer and boolean input becomes ``dtype``."""
    x = jnp.asarray(x)
    return x if jnp.issubdtype(x.dtype, jnp.floating) else x.astype(dtype)


def check_robot(robot: Any, fn: str) -> Robot:
    if not isinstance(robot, Robot):
        raise ShapeError(
            f"{fn} expects a jaxkin Robot as first argument, got {type(robot).__name__}."
        )
    return robot


def check_q(
    robot: Robot,
    q: Any,
    what: str = "q",
    fn: str = "this function",
    batch_hint=None,
    host: bool = False,
):
    """A configuration of shape (nq,) as a float JAX array (integers take the robot's dtype).

    For a robot with free or ball joints, a concrete ``q`` whose quaternion is zero or not
    finite raises (no rotation exists; under a trace the result is NaN instead). ``batch_hint``
    is the code to suggest for a batch (default: ``jax.vmap(lambda q: fn(robot, q))(qs)``); it
    must run when pasted. ``host=True`` (entry points that hand ``q`` to
    :func:`jaxkin._jit.eager`): host data (numpy, lists) stays a numpy array of the dtype JAX
    would give it, since a compiled executable takes numpy input directly and converting to a
    JAX array first costs about 60 us per call.
    """
    check_robot(robot, fn)
    nq = robot.nq
    if isinstance(q, jax.Array) and not is_tracer(q) and q.shape == (nq,) and q.dtype in _FLOATS:
        if robot.nq != robot.nv:
            check_rotations(robot, q, what, fn)
        return q  # the common case, fast: eager calls must not cost milliseconds
    q = _as_array(q, what, fn, "an array of numbers")
    _numeric(q, what, fn)
    shape = tuple(q.shape)
    if shape != (nq,):
        hint = ""
        if len(shape) >= 2 and shape[-1] == nq:
            hint = _batch_hint(
                "configurations", batch_hint or f"jax.vmap(lambda q: {fn}(robot, q))(qs)"
            )
        elif len(shape) == 1:
            hint = f" Give one value per joint coordinate {list(robot.joint_names)}."
        joints = f"{nq} joints" if nq == robot.nv else f"nq = {nq} coordinates, nv = {robot.nv}"
        raise ShapeError(
            f"{fn}: {what} must have shape ({nq},) for robot {robot.name!r} "
            f"({joints}), got shape {shape}.{hint}"
        )
    q = _float_input(q, robot.dtype, host)
    if robot.nq != robot.nv:
        check_rotations(robot, q, what, fn)
    return q


def check_rotations(robot: Robot, q: Any, what: str, fn: str) -> None:
    """Eagerly: raise when a free or ball joint's quaternion (or a planar joint's (cos, sin)) in
    the configuration ``q`` is zero or not finite, or so small that all its entries are below
    the computation dtype's smallest normal number (the kernels flush such subnormals to zero).
    Any other size is normalised exactly by the kernels. A traced ``q`` is not checked (the
    kernels give NaN there)."""
    if is_traced(q):
        return
    tiny = np.finfo(result_dtype(robot, q)).tiny
    a = np.asarray(q, dtype=np.float64)
    for j in robot.multi_dof_joints:
        kind, qi = robot.kinds[j], robot.q_index[j]
        part = {"free": (3, 7), "ball": (0, 4), "planar": (2, 4)}[kind]
        r = a[qi + part[0] : qi + part[1]]
        if not np.all(np.isfinite(r)) or not np.any(np.abs(r) >= tiny):
            name = robot.joint_names[qi].rsplit(".", 1)[0]
            entries = list(robot.joint_names[qi + part[0] : qi + part[1]])
            what_r = "(cos, sin) pair" if kind == "planar" else "quaternion (qw, qx, qy, qz)"
            if not np.all(np.isfinite(r)):
                why = "not finite"
            elif np.any(r != 0.0):
                why = f"too small to normalise (every entry below {tiny:.3g})"
            else:
                why = "zero"
            raise JaxkinError(
                f"{fn}: the {what_r} of {kind} joint {name!r} in {what} ({entries} = "
                f"{r.tolist()}) is {why}, so it "
                "is no rotation. Use a unit one (the identity is "
                f"{'(1, 0)' if kind == 'planar' else '(1, 0, 0, 0)'}; jk.neutral(robot) gives a "
                "valid configuration)."
            )


def check_v(
    robot: Robot,
    v: Any,
    what: str = "qd",
    fn: str = "this function",
    batch_hint=None,
    host: bool = False,
):
    """A velocity (tangent vector) of shape (nv,) as a float JAX array; for robots without free,
    ball or planar joints this is :func:`check_q` (nv == nq). ``host``: as in :func:`check_q`."""
    if robot.nq == robot.nv:
        return check_q(robot, v, what, fn, batch_hint, host)
    check_robot(robot, fn)
    nv = robot.nv
    v = _as_array(v, what, fn, "an array of numbers")
    _numeric(v, what, fn)
    shape = tuple(v.shape)
    if shape != (nv,):
        hint = ""
        if len(shape) >= 2 and shape[-1] == nv:
            hint = _batch_hint("velocities", batch_hint or "jax.vmap")
        raise ShapeError(
            f"{fn}: {what} must have shape ({nv},) for robot {robot.name!r} (a velocity: nv = "
            f"{nv} entries {list(robot.velocity_names)}; q has nq = {robot.nq}), got shape "
            f"{shape}.{hint}"
        )
    return _float_input(v, robot.dtype, host)


def refuse_multi_dof(robot: Robot, fn: str, why: str = "") -> None:
    """Raise :class:`~jaxkin.JaxkinError` when ``robot`` has a free, ball or planar joint, for a
    function ``fn`` that treats ``q`` as a vector space."""
    check_robot(robot, fn)
    joints = robot.multi_dof_joints
    if not joints:
        return
    names = []
    for j in joints:
        qi = robot.q_index[j]
        label = robot.joint_names[qi].rsplit(".", 1)[0] if qi >= 0 else robot.frame_names[j + 1]
        names.append(f"{label!r} ({robot.kinds[j]})")
    raise JaxkinError(
        f"{fn} does not support robot {robot.name!r}: it has free, ball or planar joints "
        f"({', '.join(names)}), whose configuration (unit quaternions, (cos, sin) pairs) is not a "
        f"vector space, and {fn} {why or 'treats q as one'}. Use it on a fixed-base robot (e.g. "
        "load the chain without floating_base, or with base=<a link> below the joint)."
    )


def check_vector(x: Any, n: int, what: str, fn: str, meaning: str, hint: str = "") -> Any:
    """A real vector of shape (n,) (still host data or a JAX array, as given)."""
    x = _as_array(x, what, fn, f"{n} numbers ({meaning})")
    _numeric(x, what, fn)
    if tuple(x.shape) != (n,):
        raise ShapeError(
            f"{fn}: {what} must have shape ({n},) ({meaning}), got {tuple(x.shape)}.{hint}"
        )
    return x


def check_scalar(x: Any, what: str, fn: str, meaning: str, hint: str = "") -> Any:
    """A real number of shape () (still host data or a JAX array, as given)."""
    x = _as_array(x, what, fn, f"one number ({meaning})")
    _numeric(x, what, fn)
    if tuple(x.shape) != ():
        raise ShapeError(
            f"{fn}: {what} must be one number, shape () ({meaning}), got shape "
            f"{tuple(x.shape)}.{hint}"
        )
    return x


def check_point(point: Any, dtype: Any, fn: str = "this function") -> jax.Array | None:
    """An offset (3,) in a frame's own axes, or None."""
    if point is None:
        return None
    point = check_vector(point, 3, "point", fn, "an offset in the frame's own axes")
    return jnp.asarray(point, dtype=dtype)


def check_frames(robot: Robot, frame: Any, fn: str) -> tuple[int, ...] | None:
    """Several frames, asked for as a list or tuple of names and indices (mixed, in any order,
    duplicates allowed) or a 1-D numpy array of indices, as a tuple of frame indices in that
    order; None when ``frame`` is one frame (a name, an index or None, for
    ``robot.frame_index``). An empty list raises; an unknown name or an index out of range
    raises as it does for one frame."""
    if isinstance(frame, np.ndarray) and frame.ndim == 1:
        frame = frame.tolist()
    if not isinstance(frame, (list, tuple)):
        return None
    if len(frame) == 0:
        raise JaxkinError(
            f"{fn}: frame must be a frame name or index, or a non-empty list of them, got an "
            f"empty {type(frame).__name__}. Pass frame=None for the default frame, or e.g. "
            f"frame={list(robot.frame_names[-2:])!r}."
        )
    return tuple(robot.frame_index(f) for f in frame)


def check_points(point: Any, k: int, dtype: Any, fn: str = "this function") -> jax.Array | None:
    """Offsets for k frames, each in its frame's own axes: None, one offset (3,) for every frame,
    or one per frame (k, 3); returned as None or (k, 3)."""
    if point is None:
        return None
    x = _as_array(point, "point", fn, "offsets in the frames' own axes")
    _numeric(x, "point", fn)
    if tuple(x.shape) == (3,):
        return jnp.broadcast_to(jnp.asarray(x, dtype=dtype), (k, 3))
    if tuple(x.shape) != (k, 3):
        raise ShapeError(
            f"{fn}: point must have shape (3,) (one offset for every frame) or ({k}, 3) (one per "
            f"frame, in the frames' own axes) for {k} frames, got {tuple(x.shape)}."
        )
    return jnp.asarray(x, dtype=dtype)


def check_reference(reference: Any) -> str:
    if reference not in REFERENCES:
        raise JaxkinError(
            f"reference must be one of {REFERENCES}, got {reference!r}. 'world_aligned' is the "
            "textbook's geometric Jacobian (frame origin, world axes)."
        )
    return reference


def check_J(J: Any, fn: str, batch_hint: str | None = None, zero_dof: bool = False) -> jax.Array:
    """A Jacobian of shape (m, dof), m and dof >= 1 (dof == 0 too with ``zero_dof``: a robot
    with no moving joint), as a float JAX array. ``batch_hint``: the code suggested for a batch
    of Jacobians ``Js`` (default ``jax.vmap(fn)(Js)``); it must run when pasted, with the
    function's other arguments under their parameter names."""
    J = _as_array(J, "J", fn, "an array of numbers")
    _numeric(J, "J", fn)
    shape = tuple(J.shape)
    if len(shape) != 2 or shape[0] == 0 or (shape[1] == 0 and not zero_dof):
        hint = ""
        if len(shape) == 3:
            hint = _batch_hint("Jacobians", batch_hint or f"jax.vmap({fn})(Js)")
        raise ShapeError(
            f"{fn}: J must have shape (m, dof) (e.g. (6, dof) from jk.geometric_jacobian), got "
            f"shape {shape}.{hint}"
        )
    return _float_array(J, jnp.result_type(float))


def check_J_and_vector(
    J: Any, v: Any, fn: str, what: str = "v", batch_hint: str | None = None
) -> tuple[jax.Array, jax.Array]:
    """A Jacobian (m, dof) and a vector (m,) (e.g. a twist), cast to one float dtype."""
    J = check_J(J, fn, batch_hint or f"jax.vmap({fn})(Js, {what}s)")
    m = J.shape[0]
    meaning = f"to match J's {m} rows: a twist [v; omega] for a geometric Jacobian"
    v = jnp.asarray(check_vector(v, m, what, fn, meaning, " Batch with jax.vmap."))
    dtype = jnp.result_type(J.dtype, v.dtype if jnp.issubdtype(v.dtype, jnp.floating) else J.dtype)
    return J.astype(dtype), v.astype(dtype)


def check_twist(V: Any, fn: str = "this function") -> jax.Array:
    return jnp.asarray(check_vector(V, 6, "a twist", fn, "[v; omega]"))


def rigid_transform_errors(Ts: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Indices of the (N, 4, 4) float64 transforms that are not rigid: rotation block not
    orthonormal with det +1 (to ``tol``), or last row not [0, 0, 0, 1]."""
    R = Ts[:, :3, :3]
    bad_R = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2)) > tol
    bad_row = np.abs(Ts[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > 1e-12
    return np.flatnonzero(bad_R | bad_row | (np.linalg.det(R) < 0))


def check_poses(T: Any, fn: str, what: str, dtype: Any, batch: str = "optional"):
    """Pose(s) ``T_world_frame``: (4, 4), or (N, 4, 4) when ``batch`` is "optional" or
    "required". Concrete poses must be finite and rigid. Returns ``(T as dtype, batched)``."""
    T = _as_array(T, what, fn, "a (4, 4) transform")
    _numeric(T, what, fn)
    shape = tuple(T.shape)
    batched = len(shape) == 3 and shape[1:] == (4, 4)
    if (shape != (4, 4) or batch == "required") and not (batched and batch != "never"):
        allowed = {
            "optional": "(4, 4) (one pose, T_world_frame) or (N, 4, 4) (a batch)",
            "required": "(N, 4, 4) (one pose per measurement)",
            "never": "(4, 4) (T_world_frame)",
        }[batch]
        raise ShapeError(f"{fn}: {what} must have shape {allowed}, got {shape}.")
    if not is_traced(T):
        Tn = np.asarray(T, dtype=np.float64).reshape(-1, 4, 4)
        refuse_nonfinite(Tn, what, fn)
        bad = rigid_transform_errors(Tn)
        if bad.size:
            raise JaxkinError(
                f"{fn}: {what}{f'[{int(bad[0])}]' if batched else ''} is not a rigid transform "
                "(its rotation block must be orthonormal with det +1 to 1e-6 and its last row "
                "[0, 0, 0, 1]). Build it with jk.fk or jk.spatial.make_transform."
            )
    return jnp.asarray(T, dtype=dtype), batched


def check_path(Ts: Any, what: str, fn: str) -> Any:
    """A path of N >= 2 poses: ``Ts`` (an array) itself when its shape is (N, 4, 4), else a
    :class:`~jaxkin.ShapeError`."""
    if Ts.ndim != 3 or Ts.shape[1:] != (4, 4) or Ts.shape[0] < 2:
        raise ShapeError(f"{fn}: {what} must have shape (N, 4, 4) with N >= 2, got {Ts.shape}.")
    return Ts


def check_inertia(robot: Robot, fn: str) -> None:
    """Raise :class:`~jaxkin.ModelError` unless ``robot`` has inertial data and (when its leaves
    are concrete) a positive total mass: the check of every entry point that uses the centre of
    mass, done once, eagerly."""
    if not robot.has_inertia:
        raise no_inertia_error(robot, fn)
    if not is_traced(robot.frame_mass) and robot.frame_mass.ndim == 1:
        total = float(np.sum(np.asarray(robot.frame_mass, dtype=np.float64)))
        if not total > 0.0:
            raise ModelError(
                f"{fn}: robot {robot.name!r} has total mass {total!r} kg (robot.mass), so its "
                "centre of mass is undefined. Give its links positive masses (URDF "
                '<inertial><mass value="..."/>, MJCF <inertial mass=...> or geoms, '
                "from_joints inertial=dict(mass=...)), or robot.replace(frame_mass=...)."
            )


def no_inertia_error(robot: Robot, fn: str) -> ModelError:
    """The error for a robot without inertial data, saying why it has none and the fix."""
    if robot.parameterisation != "placement":
        why = "a Denavit-Hartenberg table has no masses"
    else:
        why = (
            "its description gave none (a URDF whose links have no <inertial>, joint specs "
            "without inertial=, or an MJCF model whose masses MuJoCo infers from mesh geoms, "
            "which jaxkin does not read)"
        )
    return ModelError(
        f"{fn}: robot {robot.name!r} has no inertial data (masses), so it has no centre of "
        f"mass: {why}. Load a description with masses (a URDF with <inertial> in its links, an "
        "MJCF model with <inertial> or primitive geoms; from_joints specs with inertial=...), "
        "or give them: robot.replace(frame_mass=..., frame_com=..., frame_inertia=..., "
        "has_inertia=True) (shapes (n_frames,), (n_frames, 3), (n_frames, 3, 3))."
    )
