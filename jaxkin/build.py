"""Building robots: every description (DH tables, joint lists, URDF, ...) becomes a
:class:`~jaxkin.Robot` through one validated path.

Parsers emit joint specs (mappings, see :func:`from_joints`), keep the part the user asked for
with :func:`select` (the subtree below ``base`` or the chain to ``tip``, mimic leaders outside
it, the default frame: one function for every file loader) and call :func:`from_joints`; DH
tables go through :func:`from_dh`. Validation happens here, on the host, once, before any
tracing; mimic joints are resolved here, once (:func:`resolve_mimics`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import jax.numpy as jnp
import numpy as np

from .errors import ModelError
from .model import COORDINATES, JOINT_KINDS, JOINT_SIZES, Robot, resolve_dtype
from .spatial import matrix_to_rpy_np, quaternion_to_matrix_np, rotation_about_axis_np

__all__ = [
    "TOOL_FLANGE",
    "MimicError",
    "Selection",
    "SelectionError",
    "end_frames",
    "from_dh",
    "from_joints",
    "resolve_mimics",
    "select",
]

_DH_CONVENTIONS = {"standard": "dh_standard", "modified": "dh_modified"}


def from_dh(
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

    >>> import jaxkin as jk
    >>> robot = jk.Robot.from_dh(
    ...     [
    ...         dict(a=1.0, alpha=0.0, d=0.0, theta=0.0, joint="revolute"),
    ...         dict(a=0.0, alpha=0.0, d=0.0, theta=0.0, joint="prismatic", lower=0.0, upper=1.0),
    ...     ],
    ...     convention="standard",
    ...     name="rp",
    ... )
    >>> robot.dof, robot.joint_kinds, robot.frame_names
    (2, ('revolute', 'prismatic'), ('base', 'link1', 'link2'))
    >>> T = jk.fk(robot, [0.0, 0.5])  # one unit along x, then 0.5 up the prismatic joint
    >>> float(T[0, 3]), float(T[2, 3])
    (1.0, 0.5)
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
        _check_keys(
            row,
            where,
            allowed,
            ("a", "alpha", "d", "theta", "joint"),
            "every row needs a, alpha, d, theta and joint ('revolute' or 'prismatic')",
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
    return _build(
        name=name or "dh_robot",
        parameterisation=_DH_CONVENTIONS[convention],
        params=params,
        axis=np.tile([0.0, 0.0, 1.0], (n, 1)),
        kinds=kinds,
        parents=list(range(n)),
        q_index=list(range(n)),
        v_index=list(range(n)),
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


def from_joints(
    joints: Sequence[Mapping[str, Any]],
    root: str = "base",
    base: Any = None,
    tool: Any = None,
    name: str | None = None,
    dtype: Any = None,
    leaders: Sequence[Mapping[str, Any]] = (),
    default_frames: Sequence[str] = (),
    root_inertial: Mapping[str, Any] | None = None,
) -> Robot:
    """A robot from URDF-style joint placements (chain or tree).

    Args:
      joints: one mapping per joint, parents before children, with keys ``name``, ``type``
        (``"revolute"``, ``"prismatic"``, ``"fixed"``, or the multi-coordinate ``"free"`` (also
        spelt ``"floating"``), ``"ball"`` and ``"planar"``: see below), ``child`` (the name of
        the frame the joint moves), optional ``parent`` (a frame name; default: the previous joint's
        child),
        ``xyz`` and ``rpy`` (the joint origin in the parent frame, URDF fixed-axis roll-pitch-
        yaw ``R = Rz(y) Ry(p) Rx(r)``; default zeros), ``axis`` (in the joint frame, normalised;
        default (1, 0, 0) as in URDF), ``lower``, ``upper``, ``mimic``. Instead of ``rpy`` the
        origin's rotation may be ``quat``, a quaternion ``(w, x, y, z)`` (scalar first, MuJoCo's
        order; normalised), and instead of ``xyz`` and ``rpy`` the whole origin may be
        ``transform``, a 4x4 homogeneous ``T_parent_joint``: exactly one form per joint. Both are
        stored as ``xyz``/``rpy`` (:func:`jaxkin.spatial.matrix_to_rpy_np`: exact to rounding,
        gimbal lock too).
        An empty ``joints`` gives a robot whose only frame is ``root`` (dof 0).
      root: the name of the base frame.
      base, tool, name, dtype: as in :meth:`from_dh`.

    ``T_parent_child(q) = Trans(xyz) Rot(rpy) Motion(axis, value)``, as in URDF, where
    ``value = q[i]`` for an independent joint.

    Free, ball and planar joints take several entries of ``q`` and of the velocity ``v`` (see
    :mod:`jaxkin.configuration` for their coordinates and :data:`jaxkin.model.JOINT_SIZES`):
    free ``q = (x, y, z, qw, qx, qy, qz)``, ball ``(qw, qx, qy, qz)``, planar ``(x, y, cos,
    sin)`` (motion in the joint frame's xy plane; ``axis``, if given, must be ``(0, 0, 1)``).
    Their ``q`` entries are named ``"<name>.x"``, ``"<name>.qw"`` ... in ``joint_names``; their
    limits are fixed (translations unbounded, quaternion and cos/sin entries in [-1, 1]), so they
    take no ``lower``/``upper``; they cannot mimic nor be mimicked. A free joint's ``axis`` is
    ignored.

    Mimic joints (URDF ``<mimic>``): ``mimic={"joint": leader, "multiplier": m, "offset": o}``
    (multiplier default 1, offset default 0) makes a revolute or prismatic joint follow the
    moving joint named ``leader`` (listed anywhere in ``joints``):
    ``value = m * value_leader + o``. A mimic joint is not an entry of ``q`` (it is not in
    ``joint_names`` and its ``lower``/``upper`` are checked but not kept: the leader's limits
    bound ``q``); its Jacobian column folds into the leader's, scaled by ``m``. A leader may
    itself mimic another joint: the chain is resolved to the independent joint at its end
    (multipliers multiply, offsets compose); a chain that loops back is an error.

    ``leaders``: joints that are not part of the robot's structure but drive some of its mimic
    joints (a chain cut out of a larger file whose gripper fingers follow a joint outside it);
    mappings with ``name``, ``type``, ``lower``, ``upper`` and optional ``mimic``. A leader at the
    end of a mimic chain becomes an entry of ``q`` named after it, placed where its first
    follower is, with its limits.

    ``default_frames``: which frame ``frame=None`` means (:attr:`jaxkin.Robot.tip_frame`):
    ``()`` (default) the last frame; one frame name, that frame; several names, none (the
    robot branches: asking for the default raises, listing these candidates).
    :func:`select` gives it (and ``leaders``) for a part of a larger description.

    Masses (for :func:`jaxkin.center_of_mass`): a joint's ``inertial`` is the mass of the frame
    it moves (its child), ``root_inertial`` that of the root frame; a mapping with ``mass`` (kg,
    finite, >= 0), optional ``xyz`` (the centre of mass in the frame; default zeros), ``rpy`` or
    ``quat`` (the orientation of the inertia's axes in the frame; default identity) and
    ``inertia`` (about the centre of mass in those axes: URDF's six numbers ``(ixx, ixy, ixz,
    iyy, iyz, izz)`` or a symmetric 3x3 matrix; default zeros), as URDF's ``<inertial>``. Stored
    per frame in the frame's own axes (``robot.frame_mass``, ``frame_com``, ``frame_inertia``);
    a frame without one has mass 0. The robot's ``has_inertia`` is True when any is given.
    Moments must be finite and the matrix symmetric; positive semi-definiteness and the
    triangle inequality are not enforced (files in use miss them by rounding, e.g. moments of
    -5e-20, as urdfdom and Pinocchio accept; the centre of mass does not depend on the inertia).

    >>> import jaxkin as jk
    >>> robot = jk.Robot.from_joints(
    ...     [
    ...         dict(name="shoulder", type="revolute", child="upper_arm", axis=[0, 0, 1]),
    ...         dict(name="elbow", type="revolute", child="forearm", xyz=[1, 0, 0], axis=[0, 0, 1]),
    ...         dict(name="flange", type="fixed", child="hand", xyz=[1, 0, 0]),
    ...     ],
    ...     name="planar2",
    ... )
    >>> robot.joint_names, robot.frame_names
    (('shoulder', 'elbow'), ('base', 'upper_arm', 'forearm', 'hand'))
    >>> float(jk.fk(robot, [0.0, 0.0])[0, 3])  # stretched along x: the hand at x = 2
    2.0
    """
    if isinstance(joints, Mapping) or not isinstance(joints, Sequence):
        raise ModelError("joints must be a sequence of mappings, one per joint.")
    dt = resolve_dtype(dtype)
    frame_names = [str(root)]
    frame_of = {str(root): 0}  # name -> frame index (O(1) lookups for long chains)
    specs = [_joint_spec(spec, j, frame_names, frame_of) for j, spec in enumerate(joints)]
    root_mass = None if root_inertial is None else _inertial(root_inertial, "root_inertial")
    all_names = [s.name for s in specs]
    _check_unique(all_names, "joint name")
    kinds = [s.kind for s in specs]
    xyz = [s.xyz for s in specs]
    rpy = [s.rpy for s in specs]
    axes = [s.axis for s in specs]
    parents = [s.parent for s in specs]
    q_index, v_index, multiplier, offset, joint_names, lowers, uppers = _drive(specs, leaders)
    params = {  # reshape: a robot with no joint at all (only its root frame) has (0, 3) leaves
        "xyz": jnp.asarray(np.array(xyz, dtype=float).reshape(-1, 3), dtype=dt),
        "rpy": jnp.asarray(np.array(rpy, dtype=float).reshape(-1, 3), dtype=dt),
    }
    return _build(
        name=name or "robot",
        parameterisation="placement",
        params=params,
        axis=np.array(axes, dtype=float).reshape(-1, 3),
        kinds=kinds,
        parents=parents,
        q_index=q_index,
        v_index=v_index,
        offset=offset,
        multiplier=multiplier,
        lower=lowers,
        upper=uppers,
        joint_names=joint_names,
        frame_names=frame_names,
        base=base,
        tool=tool,
        dtype=dt,
        default_frames=default_frames,
        inertials=[root_mass, *(s.inertial for s in specs)],
    )


_JOINT_KEYS = {
    "name",
    "type",
    "child",
    "parent",
    "xyz",
    "rpy",
    "quat",
    "transform",
    "axis",
    "lower",
    "upper",
    "mimic",
    "inertial",
}


class _Joint(NamedTuple):
    """One validated joint spec of :func:`from_joints`."""

    name: str
    kind: str
    parent: int  # frame index
    xyz: np.ndarray
    rpy: np.ndarray
    axis: np.ndarray
    limits: tuple[float, float] | None  # None for fixed, free, ball and planar joints
    mimic: tuple[str, float, float] | None
    inertial: tuple[float, np.ndarray, np.ndarray] | None  # the child's (mass, com, inertia)


def _joint_spec(spec: Any, j: int, frame_names: list, frame_of: dict) -> _Joint:
    """Validate joint ``j``'s spec and register the frame it moves (appended to the lists)."""
    _check_keys(
        spec,
        f"joint {j}",
        _JOINT_KEYS,
        ("name", "type", "child"),
        "every joint needs name, type, child",
    )
    jname = str(spec["name"])
    where = f"joint {jname!r}"
    kind = spec["type"]
    if kind == "floating":
        kind = "free"
    if kind not in JOINT_KINDS:
        raise ModelError(
            f"{where} has unknown type {kind!r}; use 'revolute', 'prismatic', 'fixed', 'free' "
            "(or 'floating'), 'ball' or 'planar'."
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
    frame_of[child] = len(frame_names)
    frame_names.append(child)
    mimic, limits = spec.get("mimic"), None
    if mimic is not None:
        if kind == "fixed":
            raise ModelError(
                f"{where} is fixed but has a mimic; only revolute and prismatic joints "
                "can mimic another joint."
            )
        if kind in COORDINATES:
            raise ModelError(
                f"{where} is {kind} but has a mimic; only revolute and prismatic joints can "
                "mimic another joint."
            )
        mimic = _mimic_spec(mimic, where)
    if kind in COORDINATES:
        given = sorted(k for k in ("lower", "upper") if spec.get(k) is not None)
        if given:
            raise ModelError(
                f"{where} is {kind} and takes no {'/'.join(given)}: its limits are fixed "
                "(translations unbounded, quaternion and cos/sin entries in [-1, 1])."
            )
        if kind == "planar" and "axis" in spec:
            ax = _unit_axis(spec["axis"], kind, where)
            if np.max(np.abs(ax - (0.0, 0.0, 1.0))) > 1e-12:
                raise ModelError(
                    f"{where} is planar with axis {ax.tolist()}; a planar joint moves in its "
                    "joint frame's xy plane (normal (0, 0, 1), as Pinocchio's JointModelPlanar). "
                    "Rotate the joint frame with rpy/quat so that the plane's normal is its z "
                    "axis."
                )
    elif kind != "fixed":
        limits = _limits(spec, where)
    xyz, rpy = _placement(spec, where)
    return _Joint(
        name=jname,
        kind=kind,
        parent=frame_of[parent_name],
        xyz=xyz,
        rpy=rpy,
        axis=_unit_axis(
            spec.get("axis", (1.0, 0.0, 0.0)) if kind not in COORDINATES else (0.0, 0.0, 1.0),
            kind,
            where,
        ),
        limits=limits,
        mimic=mimic,
        inertial=None if spec.get("inertial") is None else _inertial(spec["inertial"], where),
    )


_INERTIAL_KEYS = {"mass", "xyz", "rpy", "quat", "inertia"}


def _inertial(value: Any, where: str) -> tuple[float, np.ndarray, np.ndarray]:
    """Validate an ``inertial`` mapping of :func:`from_joints`: ``(mass, com (3,), inertia (3,
    3))``, the inertia about the centre of mass in the frame's axes (exactly symmetric)."""
    where = f"{where}, key 'inertial'" if where != "root_inertial" else where
    _check_keys(
        value,
        where,
        _INERTIAL_KEYS,
        ("mass",),
        "an inertial needs mass (kg); optional xyz, rpy or quat, inertia",
    )
    mass = _finite_float(value["mass"], f"{where}, 'mass'")
    if mass < 0.0:
        raise ModelError(f"{where}: mass must be >= 0 kg, got {mass!r}.")
    if "rpy" in value and "quat" in value:
        raise ModelError(f"{where} gives both rpy and quat; give one orientation.")
    com = _vector3(value.get("xyz", (0.0, 0.0, 0.0)), f"{where}, 'xyz'")
    if "quat" in value:
        R = _quat_matrix(value["quat"], f"{where}, 'quat'")
    else:
        roll, pitch, yaw = _vector3(value.get("rpy", (0.0, 0.0, 0.0)), f"{where}, 'rpy'")
        R = (
            rotation_about_axis_np((0.0, 0.0, 1.0), yaw)
            @ rotation_about_axis_np((0.0, 1.0, 0.0), pitch)
            @ rotation_about_axis_np((1.0, 0.0, 0.0), roll)
        )
    inertia = _inertia_matrix(value.get("inertia", np.zeros((3, 3))), f"{where}, 'inertia'")
    inertia = R @ inertia @ R.T
    return mass, com, (inertia + inertia.T) / 2.0


def _inertia_matrix(value: Any, where: str) -> np.ndarray:
    """A rotational inertia from URDF's six numbers ``(ixx, ixy, ixz, iyy, iyz, izz)`` or a
    symmetric 3x3 matrix: finite and symmetric (to rounding)."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        arr = None
    if arr is not None and arr.shape == (6,):
        xx, xy, xz, yy, yz, zz = arr
        arr = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    if arr is None or arr.shape != (3, 3):
        raise ModelError(
            f"{where} must be six numbers (ixx, ixy, ixz, iyy, iyz, izz) or a symmetric 3x3 "
            f"matrix, got {value!r:.80}."
        )
    if not np.all(np.isfinite(arr)):
        raise ModelError(f"{where} must be finite, got {arr.tolist()}.")
    scale = float(np.max(np.abs(arr)))
    if np.max(np.abs(arr - arr.T)) > 1e-9 * scale:
        raise ModelError(
            f"{where} must be symmetric (a rotational inertia is), got {arr.tolist()}; give "
            "the six numbers (ixx, ixy, ixz, iyy, iyz, izz)."
        )
    return arr


def _placement(spec: Mapping[str, Any], where: str) -> tuple[np.ndarray, np.ndarray]:
    """A joint's origin as stored: ``(xyz, rpy)``, from ``xyz``/``rpy``, ``xyz``/``quat`` or
    ``transform`` (exactly one orientation form)."""
    forms = [k for k in ("rpy", "quat", "transform") if k in spec]
    if len(forms) > 1 or ("transform" in spec and "xyz" in spec):
        given = sorted(k for k in ("xyz", "rpy", "quat", "transform") if k in spec)
        raise ModelError(
            f"{where} gives its placement twice ({given}); give exactly one form: xyz and rpy, "
            "xyz and quat (w, x, y, z), or transform (4x4)."
        )
    if "transform" in spec:
        T = _transform(spec["transform"], f"{where}, key 'transform'")
        return T[:3, 3].copy(), matrix_to_rpy_np(T[:3, :3])
    xyz = _vector3(spec.get("xyz", (0.0, 0.0, 0.0)), f"{where}, key 'xyz'")
    if "quat" in spec:
        return xyz, matrix_to_rpy_np(_quat_matrix(spec["quat"], f"{where}, key 'quat'"))
    return xyz, _vector3(spec.get("rpy", (0.0, 0.0, 0.0)), f"{where}, key 'rpy'")


def _quat_matrix(value: Any, where: str) -> np.ndarray:
    """The rotation matrix of a quaternion ``(w, x, y, z)`` (scalar first, MuJoCo's order),
    normalised in float64 first (as MuJoCo's compiler does)."""
    try:
        q = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(f"{where} must be 4 numbers (w, x, y, z), got {value!r}.") from None
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise ModelError(f"{where} must be 4 finite numbers (w, x, y, z), got {value!r}.")
    norm = math.hypot(*(float(x) for x in q))
    if norm == 0.0:
        raise ModelError(f"{where} is the zero quaternion; give a rotation, e.g. (1, 0, 0, 0).")
    return quaternion_to_matrix_np(q)


def _unit_axis(value: Any, kind: str, where: str) -> np.ndarray:
    ax = _vector3(value, f"{where}, key 'axis'")
    # Overflow- and underflow-safe norm (math.hypot scales internally).
    norm = math.hypot(*(float(x) for x in ax))
    if kind != "fixed" and norm == 0.0:
        raise ModelError(f"{where} has a zero axis; give a non-zero direction.")
    if norm == 0.0:
        return np.array([1.0, 0.0, 0.0])
    if abs(norm - 1.0) > 4 * np.finfo(np.float64).eps:
        return ax / norm  # a unit axis (to rounding) is kept bit for bit: idempotent
    return ax


def _limits(spec: Mapping[str, Any], where: str) -> tuple[float, float]:
    lo = _limit(spec.get("lower", -math.inf), f"{where}, key 'lower'")
    hi = _limit(spec.get("upper", math.inf), f"{where}, key 'upper'")
    if lo > hi:
        raise ModelError(f"{where}: lower limit {lo} is above upper limit {hi}.")
    return lo, hi


def _drive(joints: list[_Joint], leaders: Sequence[Mapping[str, Any]]):
    """Which entries of ``q`` and ``v`` drive each joint, and how: ``(q_index, v_index,
    multiplier, offset, joint_names, lower, upper)``. Independent joints get entries in order
    (a free, ball or planar joint several, see :data:`jaxkin.model.JOINT_SIZES`); mimic joints
    are resolved once (:func:`resolve_mimics`); a leader outside the structure (``leaders``) that
    ends a mimic chain gets the entry where its first follower is."""
    kind_of = {j.name: j.kind for j in joints}
    limits = {j.name: j.limits for j in joints}
    mimics = {j.name: j.mimic for j in joints if j.mimic is not None}
    for spec in leaders:  # outside the structure: kinds, limits and mimics only
        lname, lkind = str(spec["name"]), spec["type"]
        if lname in kind_of or lkind not in ("revolute", "prismatic"):
            raise ModelError(f"leader joint {lname!r} must be a new revolute or prismatic joint.")
        kind_of[lname] = lkind
        limits[lname] = _limits(spec, f"leader joint {lname!r}")
        if spec.get("mimic") is not None:
            mimics[lname] = _mimic_spec(spec["mimic"], f"leader joint {lname!r}")
    try:
        resolved = resolve_mimics(mimics, kind_of)
    except MimicError as e:
        raise ModelError(str(e)) from None
    inside = {j.name for j in joints}
    q_of: dict[str, tuple[int, int]] = {}  # independent joint name -> start in q and in v
    nq = nv = 0
    for j in joints:
        driver = resolved[j.name][0] if j.name in resolved else j.name
        if j.kind != "fixed" and driver not in q_of and (driver == j.name or driver not in inside):
            q_of[driver] = (nq, nv)
            sq, sv = JOINT_SIZES[kind_of[driver]]
            nq, nv = nq + sq, nv + sv
    n = len(joints)
    multiplier, offset, q_index, v_index = [1.0] * n, [0.0] * n, [-1] * n, [-1] * n
    for i, j in enumerate(joints):
        if j.kind != "fixed":
            driver, multiplier[i], offset[i] = resolved.get(j.name, (j.name, 1.0, 0.0))
            q_index[i], v_index[i] = q_of[driver]
    names, lower, upper = [], [], []  # empty for a robot with no moving joint (dof 0)
    for k in q_of:
        kind = kind_of[k]
        if kind in COORDINATES:
            coords = COORDINATES[kind][0]
            names += [f"{k}.{c}" for c in coords]
            for c in coords:
                bound = math.inf if c in ("x", "y", "z") else 1.0
                lower.append(-bound)
                upper.append(bound)
        else:
            names.append(k)
            lower.append(limits[k][0])
            upper.append(limits[k][1])
    return q_index, v_index, multiplier, offset, names, lower, upper


def _build(
    *,
    base,
    tool,
    dtype,
    frame_names,
    offset,
    multiplier,
    lower,
    upper,
    axis,
    default_frames=(),
    inertials=None,
    **static,
) -> Robot:
    has_tool = tool is not None
    base_T = _transform(base, "base")
    tool_T = _transform(tool, "tool")
    frame_names = list(frame_names)
    if has_tool:
        frame_names.append("tool")
    _check_unique(frame_names, "frame name")
    default_frames = _default_frames(default_frames, frame_names)
    leaves = dict(
        axis=jnp.asarray(axis, dtype=dtype),
        offset=jnp.asarray(np.array(offset, dtype=float), dtype=dtype),
        multiplier=jnp.asarray(np.array(multiplier, dtype=float), dtype=dtype),
        lower=jnp.asarray(np.array(lower, dtype=float), dtype=dtype),
        upper=jnp.asarray(np.array(upper, dtype=float), dtype=dtype),
        base=jnp.asarray(base_T, dtype=dtype),
        tool=jnp.asarray(tool_T, dtype=dtype),
    )
    has_inertia = inertials is not None and any(x is not None for x in inertials)
    if has_inertia:
        leaves.update(_inertial_leaves([*inertials, *([None] if has_tool else [])], dtype))
    return Robot(
        params=static.pop("params"),
        **leaves,
        name=str(static.pop("name")),
        parameterisation=static.pop("parameterisation"),
        kinds=tuple(static.pop("kinds")),
        parents=tuple(int(p) for p in static.pop("parents")),
        q_index=tuple(int(i) for i in static.pop("q_index")),
        v_index=tuple(int(i) for i in static.pop("v_index")),
        joint_names=tuple(static.pop("joint_names")),
        frame_names=tuple(frame_names),
        has_tool=has_tool,
        default_frames=default_frames,
        has_inertia=has_inertia,
    )


def _inertial_leaves(inertials: list, dtype) -> dict[str, Any]:
    """``frame_mass``, ``frame_com``, ``frame_inertia`` from per-frame ``(mass, com, inertia)``
    (None: a massless frame)."""
    none = (0.0, np.zeros(3), np.zeros((3, 3)))
    mass, com, inertia = zip(*(none if x is None else x for x in inertials), strict=True)
    return dict(
        frame_mass=jnp.asarray(np.array(mass, dtype=float), dtype=dtype),
        frame_com=jnp.asarray(np.array(com, dtype=float).reshape(-1, 3), dtype=dtype),
        frame_inertia=jnp.asarray(np.array(inertia, dtype=float).reshape(-1, 3, 3), dtype=dtype),
    )


def _default_frames(value: Any, frame_names: Sequence[str]) -> tuple[str, ...]:
    """Validate ``default_frames``; the last frame as the only one is stored as ``()`` (the same
    default), so that robots built with and without it compare equal."""
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise ModelError(
            f"default_frames must be a sequence of frame names, got {value!r}; pass "
            "('name',) for one default frame."
        )
    names = tuple(value)
    known = set(frame_names)
    for n in names:
        if not isinstance(n, str) or n not in known:
            raise ModelError(f"default_frames: {n!r} is not a frame of the robot.")
    _check_unique(names, "default frame")
    return () if names == (frame_names[-1],) else names


# ---------------------------------------------------------------------- host-side validation
def _check_keys(spec: Any, where: str, allowed: set, required: tuple, needs: str) -> None:
    """``spec`` is a mapping with every ``required`` key and no key outside ``allowed``."""
    if not isinstance(spec, Mapping):
        raise ModelError(f"{where} must be a mapping, got {type(spec).__name__}.")
    unknown = set(spec) - allowed
    if unknown:
        raise ModelError(
            f"{where} has unknown key(s) {sorted(unknown)}; allowed keys are {sorted(allowed)}."
        )
    for key in required:
        if key not in spec:
            raise ModelError(f"{where} is missing key {key!r}; {needs}.")


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


class MimicError(ModelError):
    """A mimic joint that cannot be resolved: ``problem`` is "missing", "not_moving" or "cycle";
    ``joint`` the follower whose leader is at fault, ``leader`` that leader, ``cycle`` the
    joint names around a cycle."""

    def __init__(self, message: str, problem: str, joint: str, leader: str, cycle=()):
        super().__init__(message)
        self.problem, self.joint, self.leader, self.cycle = problem, joint, leader, tuple(cycle)

    def __reduce__(self):
        return (type(self), (str(self), self.problem, self.joint, self.leader, self.cycle))


def resolve_mimics(
    mimics: Mapping[str, tuple[str, float, float]], kinds: Mapping[str, str]
) -> dict[str, tuple[str, float, float]]:
    """Resolve every mimic joint to the independent joint at the end of its mimic chain.

    ``mimics`` maps a follower to ``(leader, m, o)`` (``value = m * value_leader + o``);
    ``kinds`` gives every known joint's kind. Returns ``{follower: (driver, M, O)}`` with
    ``value = M * value_driver + O`` and ``driver`` independent. Following ``j -> k -> ... -> i``
    composes multipliers and offsets. Iterative and linear (memoised). Raises
    :class:`MimicError` for a missing or fixed leader or a cycle.
    """
    resolved: dict[str, tuple[str, float, float]] = {}
    for start in mimics:
        path: list[str] = []
        on_path: dict[str, int] = {}
        k = start
        while k in mimics and k not in resolved:
            on_path[k] = len(path)
            path.append(k)
            leader = mimics[k][0]
            if leader not in kinds:
                raise MimicError(
                    f"joint {k!r} mimics joint {leader!r}, which is not a joint of this robot; "
                    "name an existing revolute or prismatic joint.",
                    "missing",
                    k,
                    leader,
                )
            if kinds[leader] not in ("revolute", "prismatic"):
                raise MimicError(
                    f"joint {k!r} mimics joint {leader!r}, which is {kinds[leader]}; a mimic "
                    "joint must follow a revolute or prismatic joint.",
                    "not_moving",
                    k,
                    leader,
                )
            if leader in on_path:
                cycle = [*path[on_path[leader] :], leader]
                raise MimicError(
                    f"mimic joints form a cycle ({' -> '.join(cycle)}): no joint in it is "
                    "independent. Make one of them an independent joint (remove its mimic).",
                    "cycle",
                    k,
                    leader,
                    cycle,
                )
            k = leader
        # k is independent or already resolved: value_k = M * q[driver] + O.
        driver, M, O = resolved.get(k, (k, 1.0, 0.0))
        for i in reversed(path):
            _, m, o = mimics[i]
            M, O = m * M, m * O + o  # value_i = m * value_next + o
            resolved[i] = (driver, M, O)
    return resolved


TOOL_FLANGE = "tool0"
"""The name of ROS-Industrial's tool flange frame, as REP 199 defines it.

``tool0`` is the robot's mounting flange with no tool attached. Where the fixed frames hanging
off the last moving link branch, the default frame follows the branch to a link of this name
(see :func:`end_frames`)."""


def end_frames(root: str, joints: Sequence[tuple[str, str, bool]]) -> tuple[str, ...]:
    """The end frame of each branch of the moving joints of a tree: the default frame rule of
    the file loaders (``jk.load_urdf``, ``jk.load_mjcf``).

    ``joints`` are ``(parent, child, moves)`` triples, parents before children, below ``root``.
    For each moving joint with no moving joint below it (the end of a branch), fixed joints are
    followed down from its child link while the link has exactly one child joint; where the
    fixed frames branch and one of the children is :data:`TOOL_FLANGE` (``"tool0"``), the walk
    goes on into it. The link where the walk stops is the branch's end frame. One end frame:
    the robot's default frame; several: no default (the candidates); none (no moving joint):
    ``()``. Iterative and linear.
    """
    children: dict[str, list[str]] = {root: []}
    for parent, child, _ in joints:
        children.setdefault(parent, []).append(child)
        children.setdefault(child, [])
    moving_below = dict.fromkeys(children, False)  # a moving joint in the link's subtree
    for parent, child, moves in reversed(joints):  # children before parents
        if moves or moving_below[child]:
            moving_below[parent] = True

    def end_frame(link: str) -> str:
        while True:  # fixed joints only: no moving joint is below
            below = children[link]
            if len(below) == 1:
                link = below[0]
            elif TOOL_FLANGE in below:
                link = TOOL_FLANGE
            else:
                return link

    ends = [child for _, child, moves in joints if moves and not moving_below[child]]
    return tuple(end_frame(child) for child in ends)


class SelectionError(ModelError):
    """A ``base``/``tip`` that :func:`select` cannot honour: ``problem`` is ``"base"`` or
    ``"tip"`` (``name`` is not a frame of the description) or ``"not_below"`` (the tip ``name``
    is not below the base). The loaders reword it with their file's context."""

    def __init__(self, message: str, problem: str, name: Any) -> None:
        super().__init__(message)
        self.problem, self.name = problem, name

    def __reduce__(self):
        return (type(self), (str(self), self.problem, self.name))


class Selection(NamedTuple):
    """What :func:`select` keeps: the arguments of :func:`from_joints` (``joints``, ``root``,
    ``leaders``, ``default_frames``, ``root_inertial``) and ``index``, the positions of the kept
    joints in the description (parents first; the joint ``above`` is not one of them)."""

    root: str
    joints: list[dict[str, Any]]
    leaders: list[dict[str, Any]]
    default_frames: tuple[str, ...]
    index: tuple[int, ...]
    root_inertial: Mapping[str, Any] | None = None


def select(
    joints: Sequence[Mapping[str, Any]],
    root: str,
    base: str | None = None,
    tip: str | None = None,
    *,
    mimics: Callable[[set[str]], Mapping[str, Mapping[str, Any]]] | None = None,
    above: Mapping[str, Any] | None = None,
    root_inertial: Mapping[str, Any] | None = None,
) -> Selection:
    """The part of a description that a loader builds: the one selection of every file loader
    (``jk.load_urdf``, xacro included, and ``jk.load_mjcf``), for :func:`from_joints`.

    ``joints`` are the :func:`from_joints` specs of the whole description (each with its
    ``parent``), a tree below the frame ``root``. Kept: the subtree below ``base`` (default
    ``root``), depth-first with siblings in the given order, or with ``tip`` the chain from
    ``base`` to ``tip``. ``above``: a joint spec put above the kept part (its ``child`` is set
    to the part's root; its ``parent`` becomes the root of the result), e.g. a free joint.

    Mimic joints: ``mimics(names)`` gives the ``mimic`` mapping of each of the joints ``names``
    that follows another (default: their specs' own ``mimic``); it is asked for the kept moving
    joints, then again with each revolute or prismatic joint outside the part that drives one
    of them (followed to the end of its chain). Those become ``leaders`` (sorted by name), and
    the kept specs (copies) get their ``mimic`` from it. ``default_frames`` is
    :func:`end_frames` of the result.

    Masses: each spec's ``inertial`` (that of its child frame) is kept with it;
    ``root_inertial`` is the mass of ``root``. The kept part's root frame keeps its own (the
    ``inertial`` of the joint above it, which is not kept, or ``root_inertial``): it becomes the
    ``inertial`` of ``above`` when given, else the result's ``root_inertial``.

    Raises :class:`SelectionError` naming the ``base`` or ``tip`` that is not a frame, or a tip
    that is not below the base; the loaders add their file's context.

    >>> import jaxkin as jk
    >>> from jaxkin.build import select
    >>> joints = [
    ...     dict(name="j1", type="revolute", parent="base", child="a"),
    ...     dict(name="j2", type="revolute", parent="a", child="b", xyz=[1, 0, 0]),
    ...     dict(name="finger", type="revolute", parent="a", child="f", mimic={"joint": "j1"}),
    ... ]
    >>> part = select(joints, "base", base="a", tip="f")  # the finger, driven by j1 outside
    >>> part.root, [s["name"] for s in part.joints], [s["name"] for s in part.leaders]
    ('a', ['finger'], ['j1'])
    >>> robot = jk.Robot.from_joints(
    ...     part.joints, root=part.root, leaders=part.leaders, default_frames=part.default_frames
    ... )
    >>> robot.joint_names, robot.frame_names, robot.frame_names[robot.tip_frame]
    (('j1',), ('a', 'f'), 'f')
    """
    frames = {root, *(s["child"] for s in joints)}
    for what, name in (("base", base), ("tip", tip)):
        if name is not None and (not isinstance(name, str) or name not in frames):
            raise SelectionError(f"{what}={name!r} is not a frame of the description.", what, name)
    start = root if base is None else base
    index = _subtree(joints, start) if tip is None else _chain(joints, start, tip)
    kept = [dict(joints[i]) for i in index]
    if start == root:
        mass = root_inertial
    else:
        mass = next(s.get("inertial") for s in joints if s["child"] == start)
    if above is not None:
        top = {**above, "child": start}
        if mass is not None:
            top["inertial"] = mass
        kept.insert(0, top)
        start, mass = above["parent"], None
    mimic, leaders = _leaders(joints, kept, mimics)
    for s in kept:
        if s["name"] in mimic:
            s["mimic"] = mimic[s["name"]]
    ends = end_frames(start, [(s["parent"], s["child"], s["type"] != "fixed") for s in kept])
    return Selection(start, kept, leaders, ends, tuple(index), mass)


def _subtree(joints: Sequence[Mapping[str, Any]], start: str) -> list[int]:
    """The positions of the joints below ``start``, depth-first (siblings in order)."""
    children: dict[str, list[int]] = {}
    for i, s in enumerate(joints):
        children.setdefault(s["parent"], []).append(i)
    out, stack = [], list(reversed(children.get(start, [])))
    while stack:
        i = stack.pop()
        out.append(i)
        stack.extend(reversed(children.get(joints[i]["child"], [])))
    return out


def _chain(joints: Sequence[Mapping[str, Any]], start: str, tip: str) -> list[int]:
    """The positions of the joints from ``start`` down to ``tip``, parents first."""
    parent_joint = {s["child"]: i for i, s in enumerate(joints)}
    path, frame = [], tip
    while frame != start:
        if frame not in parent_joint:
            raise SelectionError(f"tip {tip!r} is not below base {start!r}.", "not_below", tip)
        path.append(parent_joint[frame])
        frame = joints[path[-1]]["parent"]
    return path[::-1]


def _leaders(joints, kept, mimics) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The mimics of the kept joints and of the joints outside that drive them, and those
    leaders as :func:`from_joints` takes them (see :func:`select`)."""
    if mimics is None:
        own = {s["name"]: s["mimic"] for s in joints if s.get("mimic") is not None}

        def mimics(names: set[str]) -> dict[str, Any]:
            return {n: own[n] for n in names if n in own}

    moving = {s["name"]: s for s in joints if s["type"] in ("revolute", "prismatic")}
    selected = {s["name"] for s in kept if s["type"] != "fixed"}
    coupled = set(selected)
    mimic = mimics(coupled)
    while True:  # a leader outside may itself follow a joint outside (or inside)
        outside = ({m["joint"] for m in mimic.values()} - coupled) & set(moving)
        if not outside:
            break
        coupled |= outside
        mimic = mimics(coupled)
    leaders = []
    for name in sorted(coupled - selected):
        spec = moving[name]
        leader = {k: spec[k] for k in ("name", "type", "lower", "upper") if k in spec}
        if name in mimic:
            leader["mimic"] = mimic[name]
        leaders.append(leader)
    return dict(mimic), leaders


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
