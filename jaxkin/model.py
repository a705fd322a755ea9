"""The robot model: a JAX pytree with static topology and float parameter leaves.

A :class:`Robot` is a tree of frames connected by joints. Frame 0 is the base; joint ``j`` moves
frame ``j + 1`` relative to its parent frame ``parents[j]``; an optional tool frame comes last.
Each joint's motion is

    T_parent_child(q) = B_j @ Motion(axis_j, multiplier_j * q[q_index_j] + offset_j) @ A_j

where ``B_j`` and ``A_j`` are constant placements built from the joint's parameters. Which of them
is used is fixed by the model's parameterisation (static):

* ``"dh_standard"`` (Spong): ``A_j = Rz(theta) Tz(d) Tx(a) Rx(alpha)``, ``B_j = I``, axis = z;
* ``"dh_modified"`` (Craig): ``B_j = Rx(alpha) Tx(a) Rz(theta) Tz(d)``, ``A_j = I``, axis = z;
* ``"placement"`` (URDF-like): ``B_j = Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)``, ``A_j = I``.

Topology (joint kinds, parent indices, names, which q entry drives which joint) is static and
hashable; every number (DH parameters or placements, axes, offsets, multipliers, limits, base and
tool transforms) is a float array leaf. Hence ``jit`` over ``(robot, q)``, ``vmap`` over ``q`` or
over a stack of robots of one topology, and ``grad`` with respect to the parameters all work, and
new parameter values never retrace.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .errors import JaxkinPrecisionWarning, ModelError

__all__ = ["JOINT_KINDS", "PARAMETERISATIONS", "Robot", "resolve_dtype"]

JOINT_KINDS = ("revolute", "prismatic", "fixed")
PARAMETERISATIONS = ("dh_standard", "dh_modified", "placement")
_DH_CONVENTIONS = {"standard": "dh_standard", "modified": "dh_modified"}


def resolve_dtype(dtype: Any = None) -> np.dtype:
    """The float dtype to build with: ``dtype`` or JAX's default float.

    Asking for float64 while ``jax_enable_x64`` is off warns (:class:`JaxkinPrecisionWarning`) and
    returns float32; jaxkin never changes the global JAX configuration.
    """
    default = np.dtype(jnp.result_type(float))
    if dtype is None:
        return default
    dt = np.dtype(dtype)
    if not np.issubdtype(dt, np.floating) or dt.itemsize not in (4, 8):
        raise ModelError(f"dtype must be float32 or float64, got {dt}.")
    if dt == np.float64 and not jax.config.read("jax_enable_x64"):
        warnings.warn(
            "float64 was requested but jax_enable_x64 is off, so JAX computes in float32. "
            "Enable it at program start with jax.config.update('jax_enable_x64', True) "
            "(jaxkin never changes the global JAX configuration).",
            JaxkinPrecisionWarning,
            stacklevel=3,
        )
        return np.dtype(np.float32)
    return dt


@jax.tree_util.register_pytree_node_class
@dataclasses.dataclass(frozen=True, eq=False)
class Robot:
    """A serial or tree-shaped robot manipulator (a JAX pytree).

    Build one with :meth:`Robot.from_dh`, :meth:`Robot.from_joints`, :func:`jaxkin.load_urdf` or
    :func:`jaxkin.robots.load`; do not call the constructor directly.

    Attributes (static): ``name``, ``parameterisation``, ``kinds`` (per joint), ``parents`` (per
    joint, index of the parent frame), ``q_index`` (per joint, index into ``q`` or -1 for fixed),
    ``joint_names`` (one per entry of ``q``), ``frame_names`` (``fk_all``'s order, base first),
    ``has_tool``, ``configurations`` (named joint vectors).

    Attributes (float leaves): ``params`` (dict of per-joint parameter arrays), ``axis``
    (n, 3), ``offset`` (n,), ``multiplier`` (n,), ``lower``/``upper`` (dof,), ``base`` (4, 4) =
    T_world_base, ``tool`` (4, 4) = T_flange_tool.
    """

    params: dict[str, jax.Array]
    axis: jax.Array
    offset: jax.Array
    multiplier: jax.Array
    lower: jax.Array
    upper: jax.Array
    base: jax.Array
    tool: jax.Array
    # static
    name: str = "robot"
    parameterisation: str = "dh_standard"
    kinds: tuple[str, ...] = ()
    parents: tuple[int, ...] = ()
    q_index: tuple[int, ...] = ()
    joint_names: tuple[str, ...] = ()
    frame_names: tuple[str, ...] = ()
    has_tool: bool = False
    configurations_: tuple[tuple[str, tuple[float, ...]], ...] = ()

    # ------------------------------------------------------------------ pytree
    _LEAVES = ("params", "axis", "offset", "multiplier", "lower", "upper", "base", "tool")
    _STATIC = (
        "name",
        "parameterisation",
        "kinds",
        "parents",
        "q_index",
        "joint_names",
        "frame_names",
        "has_tool",
        "configurations_",
    )

    def tree_flatten(self):
        children = tuple(getattr(self, k) for k in self._LEAVES)
        aux = tuple(getattr(self, k) for k in self._STATIC)
        return children, aux

    @classmethod
    def tree_unflatten(cls, aux, children):
        obj = object.__new__(cls)
        for k, v in zip(cls._LEAVES, children, strict=True):
            object.__setattr__(obj, k, v)
        for k, v in zip(cls._STATIC, aux, strict=True):
            object.__setattr__(obj, k, v)
        return obj

    # ------------------------------------------------------------------ info
    @property
    def dof(self) -> int:
        """Number of independent joint variables (length of ``q``)."""
        return len(self.joint_names)

    @property
    def n_joints(self) -> int:
        """Number of joints, fixed ones included."""
        return len(self.kinds)

    @property
    def n_frames(self) -> int:
        """Number of frames returned by ``fk_all`` (base, one per joint, tool)."""
        return len(self.frame_names)

    @property
    def tip_frame(self) -> int:
        """Index of the default frame: the last one (the tool when present)."""
        return len(self.frame_names) - 1

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(self.base.dtype)

    @property
    def joint_kinds(self) -> tuple[str, ...]:
        """Kind of the joint driven by each entry of ``q`` ("revolute" or "prismatic")."""
        out = [""] * self.dof
        for j, i in enumerate(self.q_index):
            if i >= 0 and not out[i]:
                out[i] = self.kinds[j]
        return tuple(out)

    @property
    def configurations(self) -> dict[str, np.ndarray]:
        """Named joint configurations (e.g. ``"home"``), as numpy arrays of shape (dof,)."""
        return {k: np.asarray(v, dtype=self.dtype) for k, v in self.configurations_}

    def frame_index(self, frame: int | str | None) -> int:
        """Index into ``frame_names`` of a frame given by name, index or ``None`` (the tip)."""
        if frame is None:
            return self.tip_frame
        if isinstance(frame, str):
            try:
                return self.frame_names.index(frame)
            except ValueError:
                raise ModelError(
                    f"robot {self.name!r} has no frame {frame!r}; its frames are "
                    f"{list(self.frame_names)}."
                ) from None
        if isinstance(frame, (int, np.integer)) and not isinstance(frame, bool):
            n = self.n_frames
            if -n <= frame < n:
                return int(frame) % n
            raise ModelError(
                f"frame index {frame} is out of range for robot {self.name!r} with {n} frames."
            )
        raise ModelError(f"frame must be a frame name, an index or None, got {frame!r}.")

    def ancestors(self, frame: int) -> tuple[int, ...]:
        """Joints on the path from the base to ``frame`` (by frame index), base first."""
        path = []
        f = frame
        n = self.n_joints
        if self.has_tool and f == n + 1:
            f = n  # the tool hangs on the last joint's frame
        while f > 0:
            j = f - 1
            path.append(j)
            f = self.parents[j]
        return tuple(reversed(path))

    def __repr__(self) -> str:
        return (
            f"Robot(name={self.name!r}, dof={self.dof}, parameterisation={self.parameterisation!r},"
            f" joints={list(self.joint_names)}, dtype={self.dtype})"
        )

    # ------------------------------------------------------------------ changes
    def replace(self, **changes: Any) -> Robot:
        """A copy with some leaves replaced (e.g. perturbed parameters for calibration)."""
        return dataclasses.replace(self, **changes)

    def astype(self, dtype: Any) -> Robot:
        """A copy with every float leaf cast to ``dtype`` (float32 or float64)."""
        dt = resolve_dtype(dtype)
        return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=dt), self)

    def with_configurations(self, **named: Sequence[float]) -> Robot:
        """A copy with extra named configurations, each of length ``dof``."""
        items = dict(self.configurations_)
        for k, v in named.items():
            arr = np.asarray(v, dtype=float).reshape(-1)
            if arr.shape != (self.dof,) or not np.all(np.isfinite(arr)):
                raise ModelError(
                    f"configuration {k!r} must be {self.dof} finite joint values, got {v!r}."
                )
            items[k] = tuple(float(x) for x in arr)
        return dataclasses.replace(self, configurations_=tuple(items.items()))

    # ------------------------------------------------------------------ builders
    @classmethod
    def from_dh(
        cls,
        rows: Sequence[Mapping[str, Any]],
        convention: str = "standard",
        base: Any = None,
        tool: Any = None,
        name: str | None = None,
        dtype: Any = None,
    ) -> Robot:
        """A serial robot from a Denavit-Hartenberg table.

        Args:
          rows: one mapping per joint with keys ``a``, ``alpha``, ``d``, ``theta`` (metres,
            radians) and ``joint`` (``"revolute"`` or ``"prismatic"``); optional ``offset`` (added
            to the joint variable: to theta for a revolute joint, to d for a prismatic one),
            ``lower``, ``upper`` (joint limits; default unbounded), ``name``.
          convention: ``"standard"`` (Spong: ``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``) or
            ``"modified"`` (Craig: ``A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)``, the
            row's a and alpha being those of the previous link).
          base: optional (4, 4) ``T_world_base``; identity if None.
          tool: optional (4, 4) ``T_flange_tool``; adds a frame ``"tool"`` after the last link.
          name: the robot's name.
          dtype: float32 or float64 (default: JAX's default float).

        Frames are ``"base"``, ``"link1"`` ... ``"linkN"`` (frame i after joint i) and ``"tool"``.
        """
        if convention not in _DH_CONVENTIONS:
            raise ModelError(
                f"DH convention must be 'standard' or 'modified', got {convention!r}. "
                "Pass convention='standard' (Spong) or convention='modified' (Craig)."
            )
        if isinstance(rows, Mapping) or not isinstance(rows, Sequence) or len(rows) == 0:
            raise ModelError(
                "rows must be a non-empty sequence of mappings (one per joint) with keys "
                f"a, alpha, d, theta, joint; got {type(rows).__name__}."
            )
        dt = resolve_dtype(dtype)
        n = len(rows)
        cols: dict[str, list[float]] = {k: [] for k in ("a", "alpha", "d", "theta")}
        kinds, offsets, lowers, uppers, names = [], [], [], [], []
        allowed = {"a", "alpha", "d", "theta", "joint", "offset", "lower", "upper", "name"}
        for i, row in enumerate(rows):
            where = f"DH row {i}"
            if not isinstance(row, Mapping):
                raise ModelError(f"{where} must be a mapping, got {type(row).__name__}.")
            unknown = set(row) - allowed
            if unknown:
                raise ModelError(
                    f"{where} has unknown key(s) {sorted(unknown)}; allowed keys are "
                    f"{sorted(allowed)}."
                )
            for key in ("a", "alpha", "d", "theta", "joint"):
                if key not in row:
                    raise ModelError(
                        f"{where} is missing key {key!r}; every row needs a, alpha, d, theta "
                        "and joint ('revolute' or 'prismatic')."
                    )
            kind = row["joint"]
            if kind not in ("revolute", "prismatic"):
                raise ModelError(
                    f"{where} has unknown joint kind {kind!r}; use 'revolute' or 'prismatic'."
                )
            for key in ("a", "alpha", "d", "theta"):
                cols[key].append(_finite_float(row[key], f"{where}, key {key!r}"))
            offsets.append(_finite_float(row.get("offset", 0.0), f"{where}, key 'offset'"))
            lo = _limit(row.get("lower", -math.inf), f"{where}, key 'lower'")
            hi = _limit(row.get("upper", math.inf), f"{where}, key 'upper'")
            if lo > hi:
                raise ModelError(f"{where}: lower limit {lo} is above upper limit {hi}.")
            kinds.append(kind)
            lowers.append(lo)
            uppers.append(hi)
            names.append(str(row.get("name", f"joint{i + 1}")))
        _check_unique(names, "joint name")
        params = {k: jnp.asarray(np.array(v), dtype=dt) for k, v in cols.items()}
        frame_names = ["base"] + [f"link{i + 1}" for i in range(n)]
        return cls._build(
            name=name or "dh_robot",
            parameterisation=_DH_CONVENTIONS[convention],
            params=params,
            axis=np.tile([0.0, 0.0, 1.0], (n, 1)),
            kinds=kinds,
            parents=list(range(n)),
            q_index=list(range(n)),
            offset=offsets,
            multiplier=[1.0] * n,
            lower=lowers,
            upper=uppers,
            joint_names=names,
            frame_names=frame_names,
            base=base,
            tool=tool,
            dtype=dt,
        )

    @classmethod
    def from_joints(
        cls,
        joints: Sequence[Mapping[str, Any]],
        root: str = "base",
        base: Any = None,
        tool: Any = None,
        name: str | None = None,
        dtype: Any = None,
    ) -> Robot:
        """A robot from URDF-style joint placements (chain or tree).

        Args:
          joints: one mapping per joint, parents before children, with keys ``name``, ``type``
            (``"revolute"``, ``"prismatic"`` or ``"fixed"``), ``child`` (the name of the frame the
            joint moves), optional ``parent`` (a frame name; default: the previous joint's child),
            ``xyz`` and ``rpy`` (the joint origin in the parent frame, URDF fixed-axis roll-pitch-
            yaw ``R = Rz(y) Ry(p) Rx(r)``; default zeros), ``axis`` (in the joint frame, normalised;
            default (1, 0, 0) as in URDF), ``lower``, ``upper``, ``mimic``.
          root: the name of the base frame.
          base, tool, name, dtype: as in :meth:`from_dh`.

        ``T_parent_child(q) = Trans(xyz) Rot(rpy) Motion(axis, value)``, as in URDF, where
        ``value = q[i]`` for an independent joint.

        Mimic joints (URDF ``<mimic>``): ``mimic={"joint": leader, "multiplier": m, "offset": o}``
        (multiplier default 1, offset default 0) makes a revolute or prismatic joint follow the
        moving joint named ``leader`` (listed anywhere in ``joints``):
        ``value = m * value_leader + o``. A mimic joint is not an entry of ``q`` (it is not in
        ``joint_names`` and its ``lower``/``upper`` are checked but not kept: the leader's limits
        bound ``q``); its Jacobian column folds into the leader's, scaled by ``m``. A leader may
        itself mimic another joint: the chain is resolved to the independent joint at its end
        (multipliers multiply, offsets compose); a chain that loops back is an error.
        """
        if isinstance(joints, Mapping) or not isinstance(joints, Sequence) or len(joints) == 0:
            raise ModelError("joints must be a non-empty sequence of mappings, one per joint.")
        dt = resolve_dtype(dtype)
        frame_names = [str(root)]
        frame_of = {str(root): 0}  # name -> frame index (O(1) lookups for long chains)
        xyz, rpy, axes, kinds, parents, q_index = [], [], [], [], [], []
        lowers, uppers, joint_names, all_names = [], [], [], []
        mimics: dict[int, tuple[str, float, float]] = {}  # joint index -> (leader, mult, offset)
        allowed = {
            "name",
            "type",
            "child",
            "parent",
            "xyz",
            "rpy",
            "axis",
            "lower",
            "upper",
            "mimic",
        }
        for j, spec in enumerate(joints):
            where = f"joint {j}"
            if not isinstance(spec, Mapping):
                raise ModelError(f"{where} must be a mapping, got {type(spec).__name__}.")
            unknown = set(spec) - allowed
            if unknown:
                raise ModelError(
                    f"{where} has unknown key(s) {sorted(unknown)}; allowed: {sorted(allowed)}."
                )
            for key in ("name", "type", "child"):
                if key not in spec:
                    raise ModelError(f"{where} is missing key {key!r}.")
            jname = str(spec["name"])
            where = f"joint {jname!r}"
            kind = spec["type"]
            if kind not in JOINT_KINDS:
                raise ModelError(
                    f"{where} has unknown type {kind!r}; use 'revolute', 'prismatic' or 'fixed'."
                )
            parent_name = spec.get("parent", frame_names[-1])
            if not isinstance(parent_name, str) or parent_name not in frame_of:
                shown = frame_names if len(frame_names) <= 20 else [*frame_names[:20], "..."]
                raise ModelError(
                    f"{where}: parent frame {parent_name!r} is not defined by an earlier joint "
                    f"(known frames: {shown}). List parents before children."
                )
            child = str(spec["child"])
            if child in frame_of:
                raise ModelError(f"{where}: frame {child!r} already has a parent.")
            xyz.append(_vector3(spec.get("xyz", (0.0, 0.0, 0.0)), f"{where}, key 'xyz'"))
            rpy.append(_vector3(spec.get("rpy", (0.0, 0.0, 0.0)), f"{where}, key 'rpy'"))
            ax = _vector3(spec.get("axis", (1.0, 0.0, 0.0)), f"{where}, key 'axis'")
            # Overflow- and underflow-safe norm (math.hypot scales internally).
            norm = math.hypot(*(float(x) for x in ax))
            if kind != "fixed" and norm == 0.0:
                raise ModelError(f"{where} has a zero axis; give a non-zero direction.")
            if norm == 0.0:
                ax = np.array([1.0, 0.0, 0.0])
            elif abs(norm - 1.0) > 4 * np.finfo(np.float64).eps:
                ax = ax / norm  # a unit axis (to rounding) is kept bit for bit: idempotent
            axes.append(ax)
            kinds.append(kind)
            parents.append(frame_of[parent_name])
            frame_of[child] = len(frame_names)
            frame_names.append(child)
            all_names.append(jname)
            mimic = spec.get("mimic")
            if mimic is not None:
                if kind == "fixed":
                    raise ModelError(
                        f"{where} is fixed but has a mimic; only revolute and prismatic joints "
                        "can mimic another joint."
                    )
                mimics[j] = _mimic_spec(mimic, where)
            if kind != "fixed":
                lo = _limit(spec.get("lower", -math.inf), f"{where}, key 'lower'")
                hi = _limit(spec.get("upper", math.inf), f"{where}, key 'upper'")
                if lo > hi:
                    raise ModelError(f"{where}: lower limit {lo} is above upper limit {hi}.")
            if kind == "fixed":
                q_index.append(-1)
            elif j in mimics:
                q_index.append(-2)  # resolved below, once every joint is known
            else:
                q_index.append(len(joint_names))
                joint_names.append(jname)
                lowers.append(lo)
                uppers.append(hi)
        _check_unique(all_names, "joint name")
        n = len(kinds)
        multiplier, offset = [1.0] * n, [0.0] * n
        if mimics:
            _resolve_mimics(mimics, all_names, kinds, q_index, multiplier, offset)
        if not joint_names:
            raise ModelError("the robot has no moving joint (all joints are fixed).")
        params = {
            "xyz": jnp.asarray(np.array(xyz), dtype=dt),
            "rpy": jnp.asarray(np.array(rpy), dtype=dt),
        }
        return cls._build(
            name=name or "robot",
            parameterisation="placement",
            params=params,
            axis=np.array(axes),
            kinds=kinds,
            parents=parents,
            q_index=q_index,
            offset=offset,
            multiplier=multiplier,
            lower=lowers,
            upper=uppers,
            joint_names=joint_names,
            frame_names=frame_names,
            base=base,
            tool=tool,
            dtype=dt,
        )

    @classmethod
    def _build(
        cls, *, base, tool, dtype, frame_names, offset, multiplier, lower, upper, axis, **static
    ) -> Robot:
        has_tool = tool is not None
        base_T = _transform(base, "base")
        tool_T = _transform(tool, "tool")
        frame_names = list(frame_names)
        if has_tool:
            frame_names.append("tool")
        _check_unique(frame_names, "frame name")
        leaves = dict(
            axis=jnp.asarray(axis, dtype=dtype),
            offset=jnp.asarray(np.array(offset, dtype=float), dtype=dtype),
            multiplier=jnp.asarray(np.array(multiplier, dtype=float), dtype=dtype),
            lower=jnp.asarray(np.array(lower, dtype=float), dtype=dtype),
            upper=jnp.asarray(np.array(upper, dtype=float), dtype=dtype),
            base=jnp.asarray(base_T, dtype=dtype),
            tool=jnp.asarray(tool_T, dtype=dtype),
        )
        return cls(
            params=static.pop("params"),
            **leaves,
            name=str(static.pop("name")),
            parameterisation=static.pop("parameterisation"),
            kinds=tuple(static.pop("kinds")),
            parents=tuple(int(p) for p in static.pop("parents")),
            q_index=tuple(int(i) for i in static.pop("q_index")),
            joint_names=tuple(static.pop("joint_names")),
            frame_names=tuple(frame_names),
            has_tool=has_tool,
        )


# ---------------------------------------------------------------------- host-side validation
def _finite_float(value: Any, where: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ModelError(f"{where} must be a number, got {value!r}.") from None
    if not math.isfinite(x):
        raise ModelError(f"{where} must be finite, got {value!r}.")
    return x


def _mimic_spec(value: Any, where: str) -> tuple[str, float, float]:
    """Validate a ``mimic`` mapping of :meth:`Robot.from_joints`: (leader, multiplier, offset)."""
    if not isinstance(value, Mapping):
        raise ModelError(
            f"{where}, key 'mimic' must be a mapping {{'joint': name, 'multiplier': m, "
            f"'offset': o}}, got {value!r}."
        )
    unknown = set(value) - {"joint", "multiplier", "offset"}
    if unknown:
        raise ModelError(
            f"{where}, key 'mimic' has unknown key(s) {sorted(unknown)}; allowed: "
            "['joint', 'multiplier', 'offset']."
        )
    leader = value.get("joint")
    if not isinstance(leader, str) or not leader:
        raise ModelError(
            f"{where}, key 'mimic' needs 'joint': the name of the joint it follows, got {leader!r}."
        )
    mult = _finite_float(value.get("multiplier", 1.0), f"{where}, mimic 'multiplier'")
    off = _finite_float(value.get("offset", 0.0), f"{where}, mimic 'offset'")
    return leader, mult, off


def _resolve_mimics(
    mimics: dict[int, tuple[str, float, float]],
    names: list[str],
    kinds: list[str],
    q_index: list[int],
    multiplier: list[float],
    offset: list[float],
) -> None:
    """Point every mimic joint at the independent joint at the end of its mimic chain, in place.

    ``value_j = m_j * value_leader + o_j``; following a chain ``j -> k -> ... -> i`` (i
    independent) composes to ``value_j = M * q[i] + O``. Iterative and linear (memoised).
    """
    index = {name: j for j, name in enumerate(names)}
    done: set[int] = set()
    for j in mimics:
        path: list[int] = []
        on_path: dict[int, int] = {}
        k = j
        while k in mimics and k not in done:
            on_path[k] = len(path)
            path.append(k)
            leader = mimics[k][0]
            where = f"joint {names[k]!r}"
            if leader not in index:
                raise ModelError(
                    f"{where} mimics joint {leader!r}, which is not a joint of this robot; "
                    "name an existing revolute or prismatic joint."
                )
            nxt = index[leader]
            if kinds[nxt] == "fixed":
                raise ModelError(
                    f"{where} mimics joint {leader!r}, which is fixed; a mimic joint must follow "
                    "a revolute or prismatic joint."
                )
            if nxt in on_path:
                cycle = " -> ".join(names[i] for i in [*path[on_path[nxt] :], nxt])
                raise ModelError(
                    f"mimic joints form a cycle ({cycle}): no joint in it is independent. "
                    "Make one of them an independent joint (remove its mimic)."
                )
            k = nxt
        # k is independent or already resolved: value_k = M * q[q_index[k]] + O.
        M, O = (multiplier[k], offset[k]) if k in done else (1.0, 0.0)
        for i in reversed(path):
            _, m, o = mimics[i]
            M, O = m * M, m * O + o  # value_i = m * value_next + o
            q_index[i], multiplier[i], offset[i] = q_index[k], M, O
            done.add(i)


def _limit(value: Any, where: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ModelError(f"{where} must be a number, got {value!r}.") from None
    if math.isnan(x):
        raise ModelError(f"{where} is NaN; give a number (or omit it for no limit).")
    return x


def _vector3(value: Any, where: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(f"{where} must be 3 numbers, got {value!r}.") from None
    if arr.shape != (3,):
        raise ModelError(f"{where} must be 3 numbers, got shape {arr.shape}.")
    if not np.all(np.isfinite(arr)):
        raise ModelError(f"{where} must be finite, got {arr.tolist()}.")
    return arr


def _transform(value: Any, what: str) -> np.ndarray:
    if value is None:
        return np.eye(4)
    try:
        T = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(f"{what} must be a 4x4 homogeneous transform, got {value!r}.") from None
    if T.shape != (4, 4):
        raise ModelError(f"{what} must be a 4x4 homogeneous transform, got shape {T.shape}.")
    if not np.all(np.isfinite(T)):
        raise ModelError(f"{what} transform must be finite.")
    R = T[:3, :3]
    if not np.allclose(T[3], [0, 0, 0, 1]) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
        raise ModelError(
            f"{what} must be a homogeneous transform: orthonormal rotation block and last row "
            "[0, 0, 0, 1]."
        )
    if np.linalg.det(R) < 0:
        raise ModelError(f"{what} rotation block has determinant -1 (a reflection).")
    return T


def _check_unique(names: Sequence[str], what: str) -> None:
    seen = set()
    for n in names:
        if n in seen:
            raise ModelError(f"duplicate {what} {n!r}; names must be unique.")
        seen.add(n)
