"""The robot model: a JAX pytree with static topology and float parameter leaves.

A :class:`Robot` is a tree of frames connected by joints. Frame 0 is the base; joint ``j`` moves
frame ``j + 1`` relative to its parent frame ``parents[j]``; an optional tool frame comes last.
Each joint's motion is

    T_parent_child(q) = B_j @ Motion(axis_j, multiplier_j * q[q_index_j] + offset_j) @ A_j

for a revolute or prismatic joint (a fixed joint has no motion), where ``B_j`` and ``A_j`` are
constant placements built from the joint's parameters. Which of them
is used is fixed by the model's parameterisation (static):

* ``"dh_standard"`` (Spong): ``A_j = Rz(theta) Tz(d) Tx(a) Rx(alpha)``, ``B_j = I``, axis = z;
* ``"dh_modified"`` (Craig): ``B_j = Rx(alpha) Tx(a) Rz(theta) Tz(d)``, ``A_j = I``, axis = z;
* ``"placement"`` (URDF-like): ``B_j = Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)``, ``A_j = I``.

Free, ball and planar joints (placement robots only) take several entries of ``q`` and of the
velocity ``v``: ``Motion`` is then the rigid motion their coordinates give (see
:mod:`jaxkin.configuration`), and ``robot.nq`` (the length of ``q``) exceeds ``robot.nv`` (the
length of ``v``, the number of Jacobian columns). For every other robot ``nq == nv == dof``.

Topology (joint kinds, parent indices, names, which q entry drives which joint) is static and
hashable; every number (DH parameters or placements, axes, offsets, multipliers, limits, base and
tool transforms) is a float array leaf. Hence ``jit`` over ``(robot, q)``, ``vmap`` over ``q`` or
over a stack of robots of one topology, and ``grad`` with respect to the parameters all work, and
new parameter values never retrace.
"""

from __future__ import annotations

import dataclasses
import hashlib
import warnings
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._traces import inside_trace, is_traced
from .errors import JaxkinPrecisionWarning, ModelError, NoDefaultFrameError, ShapeError

__all__ = [
    "COORDINATES",
    "JOINT_KINDS",
    "JOINT_SIZES",
    "PARAMETERISATIONS",
    "NoDefaultFrameError",
    "Params",
    "Robot",
    "resolve_dtype",
]

JOINT_KINDS = ("revolute", "prismatic", "fixed", "free", "ball", "planar")

JOINT_SIZES = {
    "revolute": (1, 1),
    "prismatic": (1, 1),
    "fixed": (0, 0),
    "free": (7, 6),
    "ball": (4, 3),
    "planar": (4, 3),
}
"""``(nq, nv)`` of each joint kind: how many entries of the configuration ``q`` and of the
velocity ``v`` it takes (see :mod:`jaxkin.configuration` for the coordinates)."""

COORDINATES = {
    "free": (("x", "y", "z", "qw", "qx", "qy", "qz"), ("vx", "vy", "vz", "wx", "wy", "wz")),
    "ball": (("qw", "qx", "qy", "qz"), ("wx", "wy", "wz")),
    "planar": (("x", "y", "cos", "sin"), ("vx", "vy", "wz")),
}
"""Names of the ``q`` and ``v`` entries of each multi-coordinate joint kind: the entries of joint
``j`` are named ``f"{j}.{coordinate}"`` in ``joint_names`` and ``velocity_names``."""
PARAMETERISATIONS = ("dh_standard", "dh_modified", "placement")


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


_LEAF = {"leaf": True}  # field metadata: a float-array pytree leaf
_STRUCTURE = {"leaf": False}  # field metadata: a hashable Python value, part of the structure


def _as_leaf(x: Any) -> Any:
    """Arrays handed to a robot become immutable JAX arrays (an independent copy for numpy)."""
    if isinstance(x, np.ndarray):
        return _from_host(x)
    return jnp.array(x) if isinstance(x, (list, tuple, float, int)) else x


def _from_host(a: np.ndarray) -> Any:
    """``jnp.array(a)`` (a copy; the same dtype, canonicalised by JAX's x64 setting, and
    placement): outside a trace by ``jax.device_put`` of a copy, since ``jnp.array`` of a numpy
    array there runs a ``stage`` primitive that JAX compiles once per shape and dtype (a robot
    of a new size would compile one program per leaf); inside a trace ``jnp.array`` itself (a
    constant of the traced program)."""
    if inside_trace():
        return jnp.array(a)
    return jax.device_put(np.array(a))


def _cast(x: Any, dtype: Any) -> Any:
    """``jnp.asarray(x, dtype)``, bit for bit. A concrete float JAX array outside a trace is cast
    on the host, as XLA's CPU convert does it (round to nearest even, subnormal inputs and results
    flushed to signed zero): ``jnp.asarray`` would compile a convert per leaf shape."""
    dt = np.dtype(dtype)
    if (
        not isinstance(x, jax.Array)
        or is_traced(x)
        or inside_trace()
        or x.dtype == dt
        or np.dtype(x.dtype).kind != "f"
        or dt.kind != "f"
    ):
        return jnp.asarray(x, dtype=dt)
    with np.errstate(over="ignore"):  # overflow to inf, as XLA
        cast = _flush_subnormal(_flush_subnormal(np.asarray(x)).astype(dt))
    return jax.device_put(cast)


def _flush_subnormal(a: np.ndarray) -> np.ndarray:
    """``a`` with subnormal values replaced by zeros of their sign (XLA's CPU flush to zero)."""
    return np.where(np.abs(a) < np.finfo(a.dtype).tiny, np.copysign(0, a), a).astype(a.dtype)


def _host(x: Any) -> Any:
    """A JAX array as numpy (for pickling); other values unchanged."""
    return np.asarray(x) if isinstance(x, jax.Array) else x


@jax.tree_util.register_pytree_node_class
class Params(Mapping):
    """The per-joint parameter arrays of a robot, read-only (``robot.params["a"]``).

    A mapping from name to array (``a``, ``alpha``, ``d``, ``theta`` for DH robots; ``xyz``,
    ``rpy`` for placement robots). Items cannot be assigned: build a changed robot with
    ``robot.replace(params={**robot.params, "a": new_a})``.
    """

    __slots__ = ("_items",)

    def __init__(self, items: Mapping[str, Any]) -> None:
        object.__setattr__(self, "_items", {k: _as_leaf(items[k]) for k in sorted(items)})

    def __getitem__(self, key: str) -> Any:
        return self._items[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("robot parameters are read-only; use robot.replace(params=...).")

    def __repr__(self) -> str:
        return f"Params({self._items!r})"

    def __reduce__(self):
        """Pickle, copy and deepcopy by value (the arrays as numpy; a new read-only mapping)."""
        return (Params, ({k: np.asarray(v) for k, v in self._items.items()},))

    def tree_flatten(self):
        return tuple(self._items.values()), tuple(self._items)

    @classmethod
    def tree_unflatten(cls, keys, values):
        obj = object.__new__(cls)
        object.__setattr__(obj, "_items", dict(zip(keys, values, strict=True)))
        return obj


@jax.tree_util.register_pytree_node_class
@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class Robot:
    """A serial or tree-shaped robot manipulator: an immutable value and a JAX pytree.

    Build one with :meth:`Robot.from_dh`, :meth:`Robot.from_joints`, :func:`jaxkin.load_urdf` or
    :func:`jaxkin.robots.load`; do not call the constructor directly.

    Attributes (static): ``name``, ``parameterisation``, ``kinds`` (per joint), ``parents`` (per
    joint, index of the parent frame), ``q_index`` (per joint, start index into ``q`` or -1 for
    fixed), ``v_index`` (per joint, start index into the velocity ``v`` and the Jacobian's
    columns, or -1 for fixed; equal to ``q_index`` unless the robot has free, ball or planar
    joints), ``joint_names`` (one per entry of ``q``; the entries of a free, ball or planar
    joint ``j`` are ``"j.x"``, ``"j.qw"`` ..., see :data:`COORDINATES`), ``frame_names``
    (``fk_all``'s order, base first), ``has_tool``, ``configurations`` (named joint vectors),
    ``default_frames`` (which frame
    ``frame=None`` means: see :attr:`tip_frame`).

    Attributes (float leaves): ``params`` (read-only mapping of per-joint parameter arrays),
    ``axis`` (n, 3), ``offset`` (n,), ``multiplier`` (n,), ``lower``/``upper`` (nq,), ``base``
    (4, 4) = T_world_base, ``tool`` (4, 4) = T_flange_tool; the inertial data of each frame (a
    URDF link's ``<inertial>``, a MuJoCo body's compiled mass; zeros where a frame has none):
    ``frame_mass`` (n_frames,) in kg, ``frame_com`` (n_frames, 3) the centre of mass in the
    frame, ``frame_inertia`` (n_frames, 3, 3) the rotational inertia about the centre of mass in
    the frame's axes. ``has_inertia`` (static) says whether the description gave any inertial
    data (False for DH robots and for a URDF without ``<inertial>``); :attr:`mass` is the total.

    A robot is a value: its attributes cannot be assigned, :meth:`replace` returns an independent
    robot, and two robots with the same structure and the same numbers compare equal and hash
    alike (so compiled solvers are shared by equal robots and never reused for a changed one).
    """

    params: Params = dataclasses.field(metadata=_LEAF)
    axis: jax.Array = dataclasses.field(metadata=_LEAF)
    offset: jax.Array = dataclasses.field(metadata=_LEAF)
    multiplier: jax.Array = dataclasses.field(metadata=_LEAF)
    lower: jax.Array = dataclasses.field(metadata=_LEAF)
    upper: jax.Array = dataclasses.field(metadata=_LEAF)
    base: jax.Array = dataclasses.field(metadata=_LEAF)
    tool: jax.Array = dataclasses.field(metadata=_LEAF)
    frame_mass: jax.Array = dataclasses.field(default=None, metadata=_LEAF)
    frame_com: jax.Array = dataclasses.field(default=None, metadata=_LEAF)
    frame_inertia: jax.Array = dataclasses.field(default=None, metadata=_LEAF)
    name: str = dataclasses.field(default="robot", metadata=_STRUCTURE)
    parameterisation: str = dataclasses.field(default="dh_standard", metadata=_STRUCTURE)
    kinds: tuple[str, ...] = dataclasses.field(default=(), metadata=_STRUCTURE)
    parents: tuple[int, ...] = dataclasses.field(default=(), metadata=_STRUCTURE)
    q_index: tuple[int, ...] = dataclasses.field(default=(), metadata=_STRUCTURE)
    v_index: tuple[int, ...] = dataclasses.field(default=(), metadata=_STRUCTURE)
    joint_names: tuple[str, ...] = dataclasses.field(default=(), metadata=_STRUCTURE)
    frame_names: tuple[str, ...] = dataclasses.field(default=(), metadata=_STRUCTURE)
    has_tool: bool = dataclasses.field(default=False, metadata=_STRUCTURE)
    configurations_: tuple[tuple[str, tuple[float, ...]], ...] = dataclasses.field(
        default=(), metadata=_STRUCTURE
    )
    default_frames: tuple[str, ...] = dataclasses.field(default=(), metadata=_STRUCTURE)
    has_inertia: bool = dataclasses.field(default=False, metadata=_STRUCTURE)

    def __post_init__(self) -> None:
        if not self.v_index and all(JOINT_SIZES[k][0] <= 1 for k in self.kinds):
            object.__setattr__(self, "v_index", tuple(self.q_index))
        if not isinstance(self.params, Params):
            object.__setattr__(self, "params", Params(self.params))
        for f in _LEAVES:
            if f != "params":
                object.__setattr__(self, f, _as_leaf(getattr(self, f)))
        for f in _INERTIAL:  # no inertial data given: zeros of the frames' shapes
            if getattr(self, f) is None:
                shape = _leaf_shape(self, f)
                zeros = np.zeros(shape, dtype=jnp.asarray(self.base).dtype)
                object.__setattr__(self, f, _from_host(zeros))  # not jnp.zeros: no compile

    # ------------------------------------------------------------------ pytree
    def tree_flatten(self):
        return tuple(getattr(self, k) for k in _LEAVES), tuple(getattr(self, k) for k in _STATIC)

    @classmethod
    def tree_unflatten(cls, aux, children):
        obj = object.__new__(cls)
        for k, v in zip(_LEAVES, children, strict=True):
            object.__setattr__(obj, k, v)
        for k, v in zip(_STATIC, aux, strict=True):
            object.__setattr__(obj, k, v)
        return obj

    # ------------------------------------------------------------------ pickling
    def __reduce__(self):
        """Pickle, ``copy.copy`` and ``copy.deepcopy`` by value: the constructor with every
        attribute (arrays as numpy, so that a robot pickled next to a GPU loads anywhere). The
        copy is an equal, equally immutable robot; cached hashes are not carried (Python's
        string hashes differ between processes). A traced robot cannot be pickled."""
        if not self.is_concrete:
            raise TypeError("a traced robot (inside jit/vmap/grad) cannot be pickled or copied.")
        fields = [getattr(self, f.name) for f in dataclasses.fields(self)]
        return (Robot, tuple(x if isinstance(x, Params) else _host(x) for x in fields))

    # ------------------------------------------------------------------ value semantics
    def _value_key(self) -> tuple | None:
        """(structure, dtype and bytes of every leaf), or None while any leaf is traced."""
        key = self.__dict__.get("_key")
        if key is None:
            leaves, treedef = jax.tree_util.tree_flatten(self)
            if is_traced(leaves):
                return None
            digest = hashlib.blake2b(digest_size=16)
            for x in leaves:
                a = np.asarray(x)
                digest.update(f"{a.dtype}{a.shape}".encode())
                digest.update(np.ascontiguousarray(a).tobytes())
            key = (treedef, digest.digest())
            object.__setattr__(self, "_key", key)
        return key

    @property
    def is_concrete(self) -> bool:
        """True when no leaf is traced; cached, since a concrete robot stays concrete."""
        return self._value_key() is not None

    def __eq__(self, other: object) -> bool:
        if self is other:
            return True
        if not isinstance(other, Robot):
            return NotImplemented
        mine, theirs = self._value_key(), other._value_key()
        return mine is not None and mine == theirs

    def __hash__(self) -> int:
        h = self.__dict__.get("_hash")
        if h is None:  # hashing the key walks every name of the structure: once per robot
            key = self._value_key()
            if key is None:
                return id(self)
            h = hash(key)
            object.__setattr__(self, "_hash", h)
        return h

    # ------------------------------------------------------------------ info
    @property
    def dof(self) -> int:
        """The number of independent joint variables, i.e. degrees of freedom (:attr:`nv`, the
        Jacobian's columns); equal to :attr:`nq`, the length of ``q``, unless the robot has free,
        ball or planar joints."""
        return self.nv

    @property
    def nq(self) -> int:
        """Length of a configuration ``q`` (a unit quaternion counts 4, a planar angle 2)."""
        return len(self.joint_names)

    @property
    def nv(self) -> int:
        """Length of a velocity ``v``/``qd`` and number of Jacobian columns (a free joint counts
        6, a ball or planar joint 3)."""
        nv = self.__dict__.get("_nv")
        if nv is None:
            nv = max(
                (
                    i + JOINT_SIZES[k][1]
                    for k, i in zip(self.kinds, self.v_index, strict=True)
                    if i >= 0
                ),
                default=0,
            )
            object.__setattr__(self, "_nv", nv)
        return nv

    @property
    def multi_dof_joints(self) -> tuple[int, ...]:
        """Indices of the free, ball and planar joints (empty for most arms)."""
        return tuple(j for j, k in enumerate(self.kinds) if k in COORDINATES)

    @property
    def velocity_names(self) -> tuple[str, ...]:
        """One name per entry of the velocity ``v`` (the Jacobian's columns): ``joint_names`` for
        revolute and prismatic joints, ``"j.vx"`` ... ``"j.wz"`` for a free, ball or planar joint
        ``j`` (see :data:`COORDINATES`)."""
        if self.nq == self.nv:
            return self.joint_names
        out = [""] * self.nv
        for k, qi, vi in zip(self.kinds, self.q_index, self.v_index, strict=True):
            if qi < 0 or out[vi]:
                continue
            if k in COORDINATES:
                stem = self.joint_names[qi].rsplit(".", 1)[0]
                for i, c in enumerate(COORDINATES[k][1]):
                    out[vi + i] = f"{stem}.{c}"
            else:
                out[vi] = self.joint_names[qi]
        return tuple(out)

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
        """Index of the default frame, the one every function uses when ``frame=None``.

        ``default_frames`` decides it: ``()`` means the last frame (the tool when present: DH
        robots, chains); one name means that frame (a URDF chain's end, e.g. ``tool0``); several
        names mean the robot has no default frame, because its moving joints branch and no frame
        is moved by all of them; those names are the end frames of the branches, and asking for
        the default raises :class:`NoDefaultFrameError` listing them (also while tracing: it is
        static information).
        """
        d = self.default_frames
        if not d:
            return len(self.frame_names) - 1
        if len(d) == 1:
            return self.frame_names.index(d[0])
        raise self._no_default_frame()

    @property
    def has_default_frame(self) -> bool:
        """Whether ``frame=None`` means a frame (:attr:`tip_frame` does not raise)."""
        return len(self.default_frames) <= 1

    def _no_default_frame(self) -> NoDefaultFrameError:
        cands = list(self.default_frames)
        shown = cands if len(cands) <= 30 else [*cands[:30], "..."]
        index = {n: i for i, n in enumerate(self.frame_names)}
        # Where the branches meet: the deepest frame on every candidate's path from the base.
        paths = [self._frame_path(index[c]) for c in cands]
        meet = 0
        for fs in zip(*paths, strict=False):
            if any(f != fs[0] for f in fs):
                break
            meet = fs[0]
        moved = any(self.kinds[j] != "fixed" for j in self.ancestors(meet))
        above = (
            f" tip={self.frame_names[meet]!r}, where they branch, keeps the part above the "
            "branches."
            if moved
            else ""
        )
        first = cands[0]
        return NoDefaultFrameError(
            f"robot {self.name!r} has no default frame: its moving joints branch, so no frame is "
            "moved by all of them (a default frame must be, or its Jacobian would have columns "
            f"that are zero by construction). Candidate end frames ({len(cands)}): {shown}. "
            f"Choose one per call with frame=..., e.g. jk.fk(robot, q, frame={first!r}) "
            "(any name of robot.frame_names works), or load the chain to it, whose end is then "
            f"the default: jk.load_urdf(path, tip={first!r}) (jk.robots.load(name, tip=...) "
            f"for an example-robot-data robot).{above}",
            robot=self.name,
            candidates=cands,
        )

    def _frame_path(self, frame: int) -> list[int]:
        """Frames from the base (0) to ``frame``, both included."""
        path = [frame]
        n = self.n_joints
        while path[-1] > 0:
            f = path[-1]
            path.append(n if self.has_tool and f == n + 1 else self.parents[f - 1])
        return path[::-1]

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(self.base.dtype)

    @property
    def mass(self) -> jax.Array:
        """The total mass in kg, the sum of ``frame_mass`` over every frame (those fixed to the
        base included; 0 for a robot without inertial data, see ``has_inertia``).

        A JAX scalar (one per robot of a stack), traced inside ``jit``/``grad`` over the robot.
        """
        return jnp.sum(self.frame_mass, axis=-1)

    @property
    def joint_kinds(self) -> tuple[str, ...]:
        """Kind of the joint driven by each entry of ``q`` ("revolute", "prismatic", or "free",
        "ball", "planar" for each entry of such a joint)."""
        out = [""] * self.nq
        for j, i in enumerate(self.q_index):
            if i >= 0 and not out[i]:
                for k in range(JOINT_SIZES[self.kinds[j]][0]):
                    out[i + k] = self.kinds[j]
        return tuple(out)

    @property
    def configurations(self) -> dict[str, np.ndarray]:
        """Named joint configurations (e.g. ``"home"``), as numpy arrays of shape (nq,)."""
        return {k: np.asarray(v, dtype=self.dtype) for k, v in self.configurations_}

    def frame_index(self, frame: int | str | None) -> int:
        """Index into ``frame_names`` of a frame given by name, index or ``None`` (the default
        frame, :attr:`tip_frame`; raises :class:`NoDefaultFrameError` when the robot has none)."""
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
            f"Robot(name={self.name!r}, dof={self.dof}, "
            + (f"nq={self.nq}, " if self.nq != self.nv else "")
            + f"parameterisation={self.parameterisation!r},"
            f" joints={list(self.joint_names)}, dtype={self.dtype})"
        )

    # ------------------------------------------------------------------ changes
    def replace(self, **changes: Any) -> Robot:
        """An independent robot with some attributes replaced (e.g. perturbed parameters for
        calibration: ``robot.replace(params={**robot.params, "d": d_new})``); ``self`` is
        unchanged.

        Each replaced array must have the shape of the one it replaces (``axis`` (n, 3),
        ``offset``/``multiplier`` (n,), ``lower``/``upper`` (nq,), ``base``/``tool`` (4, 4),
        ``frame_mass`` (n_frames,), ``frame_com`` (n_frames, 3), ``frame_inertia`` (n_frames, 3,
        3), ``params`` the same names with their shapes; n joints, nq coordinates, after the change;
        a stack of robots keeps its leading axes); otherwise :class:`~jaxkin.ShapeError` names
        the attribute, the shape wanted and the shape given (every array is checked when a
        structural attribute such as ``kinds`` changes). Integer and boolean arrays take the
        robot's dtype. An unknown attribute is a :class:`~jaxkin.ModelError`.
        """
        unknown = sorted(set(changes) - set(_LEAVES) - set(_STATIC))
        if unknown:
            raise ModelError(
                f"robot.replace: Robot has no attribute {unknown[0]!r}; the attributes that can be "
                f"replaced are {[*_LEAVES, *_STATIC]}."
            )
        new = dataclasses.replace(self, **changes)
        batch = tuple(np.shape(self.base))[:-2]
        structure = any(k in _STATIC for k in changes)  # then every array must fit the new one
        for name in _LEAVES:
            if name == "params" and (structure or name in changes):
                _check_params(new, batch)
            elif structure or name in changes:
                value = _checked_leaf(name, getattr(new, name), _leaf_shape(new, name), batch, new)
                object.__setattr__(new, name, value)
        return new

    def astype(self, dtype: Any) -> Robot:
        """A copy with every float leaf cast to ``dtype`` (float32 or float64)."""
        dt = resolve_dtype(dtype)
        return jax.tree_util.tree_map(lambda x: _cast(x, dt), self)

    def with_configurations(self, **named: Sequence[float]) -> Robot:
        """A copy with extra named configurations, each of length ``nq``."""
        items = dict(self.configurations_)
        for k, v in named.items():
            arr = np.asarray(v, dtype=float).reshape(-1)
            if arr.shape != (self.nq,) or not np.all(np.isfinite(arr)):
                raise ModelError(
                    f"configuration {k!r} must be {self.nq} finite joint values, got {v!r}."
                )
            items[k] = tuple(float(x) for x in arr)
        return dataclasses.replace(self, configurations_=tuple(items.items()))

    # ------------------------------------------------------------------ builders
    # Thin aliases of jaxkin.build, which imports this module: build is imported when they are
    # called (the one import of build here), so loading model never loads build.
    @classmethod
    def from_dh(cls, rows: Sequence[Mapping[str, Any]], convention: str = "standard", **kwargs):
        """A serial robot from a Denavit-Hartenberg table: see :func:`jaxkin.build.from_dh`."""
        from .build import from_dh

        return from_dh(rows, convention, **kwargs)

    @classmethod
    def from_joints(cls, joints: Sequence[Mapping[str, Any]], root: str = "base", **kwargs):
        """A robot from URDF-style joint specs: see :func:`jaxkin.build.from_joints`."""
        from .build import from_joints

        return from_joints(joints, root, **kwargs)


_PARAM_SHAPES = {
    "dh_standard": {"a": (), "alpha": (), "d": (), "theta": ()},
    "dh_modified": {"a": (), "alpha": (), "d": (), "theta": ()},
    "placement": {"xyz": (3,), "rpy": (3,)},
}
"""Per-joint shape of each parameter array of a parameterisation (after the joint axis)."""


def _leaf_shape(robot: Robot, name: str) -> tuple[int, ...]:
    """The shape of the array attribute ``name`` (not ``params``) of an unstacked ``robot``."""
    n = robot.n_joints
    return {
        "axis": (n, 3),
        "offset": (n,),
        "multiplier": (n,),
        "lower": (robot.nq,),
        "upper": (robot.nq,),
        "base": (4, 4),
        "tool": (4, 4),
        "frame_mass": (robot.n_frames,),
        "frame_com": (robot.n_frames, 3),
        "frame_inertia": (robot.n_frames, 3, 3),
    }[name]


def _checked_leaf(name: str, x: Any, shape: tuple, batch: tuple, robot: Robot) -> Any:
    """``x`` (already an array or tracer) if its shape is ``batch + shape`` and it holds real
    numbers (integer and boolean ones cast to the robot's dtype); a ShapeError otherwise."""
    got = tuple(np.shape(x)) if hasattr(x, "shape") else None
    kind = np.dtype(x.dtype).kind if hasattr(x, "dtype") else "O"
    wanted = batch + shape
    sizes = f"n = {robot.n_joints} joints, nq = {robot.nq} coordinates"
    if name in _INERTIAL:
        sizes += f", n_frames = {robot.n_frames} frames"
    stack = f" (a stack of {batch} robots)" if batch else ""
    if kind not in "fiub":
        raise ShapeError(
            f"robot.replace: {name} must be an array of real numbers of shape {wanted}{stack}, "
            f"got {x!r:.80}."
        )
    if got != wanted:
        raise ShapeError(
            f"robot.replace: {name} must have shape {wanted} for robot {robot.name!r}{stack} "
            f"({sizes}), got shape {got}."
        )
    return x if kind == "f" else jnp.asarray(x, robot.base.dtype)


def _check_params(robot: Robot, batch: tuple) -> None:
    """Check (and cast, as :func:`_checked_leaf`) the ``params`` of a replaced ``robot``."""
    shapes = _PARAM_SHAPES.get(robot.parameterisation)
    if shapes is None:
        return  # an unknown parameterisation is refused where it is used
    if set(robot.params) != set(shapes):
        raise ModelError(
            f"robot.replace: params of a {robot.parameterisation!r} robot must have the arrays "
            f"{sorted(shapes)}, got {sorted(robot.params)}. Change some with "
            'robot.replace(params={**robot.params, "name": new_array}).'
        )
    items = {
        k: _checked_leaf(f"params[{k!r}]", v, (robot.n_joints, *shapes[k]), batch, robot)
        for k, v in robot.params.items()
    }
    object.__setattr__(robot, "params", Params(items))


_LEAVES = tuple(f.name for f in dataclasses.fields(Robot) if f.metadata["leaf"])
_INERTIAL = ("frame_mass", "frame_com", "frame_inertia")
_STATIC = tuple(f.name for f in dataclasses.fields(Robot) if not f.metadata["leaf"])
