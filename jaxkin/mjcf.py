"""MJCF (MuJoCo) files -> :class:`~jaxkin.Robot`, through MuJoCo's own compiler.

``jk.load_mjcf(source, tip=None, base=None)`` needs the ``mjcf`` extra
(``pip install 'jaxkin[mjcf]'``, i.e. the ``mujoco`` package). MuJoCo parses and compiles the
file (includes, defaults and classes, ``childclass``, ``angle="degree"``, every orientation form:
``quat``, ``euler`` with ``eulerseq``, ``axisangle``, ``xyaxes``, ``zaxis``; ``<frame>``); jaxkin
reads the *compiled* model (``body_pos``/``body_quat``, ``jnt_pos``/``jnt_axis``, ``qpos0``,
``jnt_range``, ``site_pos``/``site_quat``) and emits joint specs into
:func:`jaxkin.build.from_joints`, so a pose computed by jaxkin is the one MuJoCo's
``mj_kinematics`` computes for the same ``qpos``.

Mesh, height-field, skin and texture files are never read: geoms that use them become small
spheres and the assets are dropped before compiling (they do not move any frame). A file named
by ``<include>`` must exist; MuJoCo's message, naming the missing file and the element, is passed
on in a :class:`MJCFError`.

Before MuJoCo reads anything, jaxkin reads the file and every file it names that MuJoCo would
read while parsing (``<include file=...>`` and ``<asset><model file=...>``, recursively), each
resolved as MuJoCo resolves it: relative to the top file's directory (the current directory
for XML given as a string), then to the including file's directory (``<compiler meshdir>`` and
``assetdir`` do not apply to these). Refused by name, with an :class:`MJCFError`
(:func:`check_files`):

* a named file that is not a regular file (a FIFO, a device, a directory), which would make
  MuJoCo block or read without end; paths that leave the model's directory (``../``) are
  allowed, as MuJoCo allows them and models use them;
* more than :data:`MAX_BYTES` (16 MiB) read in all (the largest models of the MJCF zoo are
  under 200 kB);
* more than ``max_bodies`` bodies (default :data:`MAX_BODIES`, 5,000): MuJoCo's parser takes a
  time quadratic in the number of bodies (measured with MuJoCo 4.0 on a 2-core machine: 2.6 s
  to parse and 1.1 s to compile 5,000 bodies, 10 s and 4.5 s at 10,000; 59 s to parse 32,000,
  then MuJoCo runs out of memory). The count includes the
  bodies of included files, ``<replicate count=n>`` multiplies those inside it, a
  ``<composite>`` or ``<flexcomp>`` counts as the product of its ``count``, and each
  ``<attach model=...>`` adds the bodies of that model. Pass ``max_bodies=`` to load a larger
  model.

What becomes what
-----------------
* Every body is a frame named after it (an unnamed body ``body<id>``); the world body is the
  root frame ``world`` (or the body given as ``base=``). A body without joints is welded to its
  parent (a fixed joint); mocap bodies are fixed at their model pose.
* ``hinge`` -> revolute, ``slide`` -> prismatic, with MuJoCo's axis and limits (``range`` where
  ``limited``; unbounded otherwise). ``free`` -> free and ``ball`` -> ball joints
  (:mod:`jaxkin.configuration`): ``q`` holds their ``qpos`` as MuJoCo does (free: the body's
  position in the world, then its unit quaternion ``(qw, qx, qy, qz)``; ball: the quaternion of
  the rotation about the joint's anchor); a ball joint's ``range`` (a cone) is not kept. A
  joint whose anchor (``pos``) is not the body origin, and every joint but the last of a body with
  several joints, gets a frame of its own at its anchor,
  named after the joint (``joint:<name>`` when a body already has that name): MuJoCo applies a
  body's joints one after the other in the body's (moving) frame, and so does the chain of
  frames, ending at the body's frame.
* Every site is a frame fixed to its body, named after it (``site:<name>`` when a body already
  has that name; an unnamed site ``site<id>``).
* Masses: each body's frame gets MuJoCo's compiled ``body_mass``, ``body_ipos``,
  ``body_iquat`` and ``body_inertia`` (from ``<inertial>``, or inferred from its geoms as the
  compiler does), for :func:`jaxkin.center_of_mass`; joint anchor and site frames are
  massless. Where MuJoCo would infer a body's mass from a mesh, height field or SDF geom,
  which jaxkin does not read, the model has no inertial data (``robot.has_inertia`` is False;
  give such bodies an ``<inertial>``).
* ``<equality joint1 joint2 polycoef>`` with a linear polynomial (``a2 = a3 = a4 = 0``), active
  at start, makes ``joint1`` a mimic joint of ``joint2``: MuJoCo's ``y - y0 = a0 + a1 (x - x0)``
  (``y0``, ``x0`` from ``qpos0``). It is not an entry of ``q``; its Jacobian column folds into
  ``joint2``'s.
* ``connect``, ``weld`` and other equality constraints between bodies are not kinematic
  couplings of the tree: like ``mj_kinematics``, jaxkin computes the open tree and ignores them.
  Tendons used by actuators and sensors are ignored too.
* Refused by name, with a :class:`MJCFError` (a :class:`jaxkin.ModelError`): ``joint``
  equalities with a non-linear polynomial, without ``joint2`` or a second equality on the
  same joint, and tendon equalities coupling joints of the loaded part.

``q`` and ``qpos``
------------------
``q`` is MuJoCo's ``qpos`` of the loaded joints, in MuJoCo's order, without the mimic (coupled)
joints: the same numbers, including MuJoCo's ``ref`` convention (a joint at ``qpos = ref`` is at
the pose the file draws; jaxkin folds ``-ref`` into the joint's placement, so ``q = qpos``
exactly, and ``robot.lower``/``robot.upper`` are ``jnt_range``).

Velocities differ for free joints only: jaxkin's velocity ``v`` (and the Jacobian's columns)
follows Pinocchio, the free joint's linear velocity in the body's own axes, where MuJoCo's
``qvel`` gives it in the world's: ``v[:3] = R.T @ qvel[:3]`` with ``R`` the body's orientation
(``v[3:6] = qvel[3:6]``, the angular velocity in body axes for both; ball joints agree too). So
``mj_jac``'s three linear columns of a free joint equal jaxkin's times ``R.T``.

The default frame of an MJCF model
----------------------------------
As for URDF (see :mod:`jaxkin.urdf`, "The default frame"): ``tip=`` (a body or site) when given;
otherwise the end of the chain of moving joints, following fixed frames (welded bodies, sites)
down while there is exactly one, or into the one named ``tool0`` where they branch (the same
rule, :func:`jaxkin.build.end_frames`); none when the moving joints branch (then functions
need ``frame=`` and list the candidates).
"""

from __future__ import annotations

import math
import os
import stat
import xml.parsers.expat
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .build import SelectionError, select
from .errors import JaxkinError, ModelError
from .model import Robot
from .spatial import make_transform_np, quaternion_to_matrix_np, rotation_about_axis_np

__all__ = [
    "MAX_BODIES",
    "MAX_BYTES",
    "MJCFDependencyError",
    "MJCFError",
    "check_files",
    "load_mjcf",
]

_EXTRA = "pip install 'jaxkin[mjcf]' (or pip install mujoco)"

MAX_BODIES = 5_000
"""The default cap on the number of bodies of an MJCF model (``max_bodies=``; module doc)."""
MAX_BYTES = 16 * 2**20
"""The cap on the bytes of an MJCF file and all the files it includes (module doc)."""


class MJCFError(ModelError):
    """An MJCF file that MuJoCo rejects, or that jaxkin cannot represent. ``file`` is the path
    or ``"<string>"``; ``element`` names the offending element (e.g. ``"<joint name='j1'>"``)
    when one is known."""

    def __init__(self, message: str, file: str = "", element: str | None = None) -> None:
        super().__init__(message)
        self.file, self.element = file, element

    def __reduce__(self):
        return (type(self), (str(self), self.file, self.element))


class MJCFDependencyError(JaxkinError, ImportError):
    """MuJoCo (the ``mjcf`` extra) is not installed."""


def _mujoco():
    try:
        import mujoco
    except ImportError as exc:
        raise MJCFDependencyError(
            f"jk.load_mjcf needs MuJoCo (>= 3.1): {_EXTRA}. Import failed with: {exc}"
        ) from None
    return mujoco


# ----------------------------------------------------------------------------- pre-reading
_MULTIPLIERS = ("composite", "flexcomp")  # elements that make ``count`` bodies


def _count(value: str | None) -> int:
    """The product of a ``count`` attribute's integers (1 where it is not one: MuJoCo refuses)."""
    try:
        return math.prod(max(0, int(v)) for v in (value or "1").split())
    except ValueError:
        return 1


def _size() -> str:
    return f"{MAX_BYTES} bytes ({MAX_BYTES / 2**20:g} MiB)"


def _xml_text(source: Any) -> str | None:
    """``source`` as XML text when it is the XML itself (``str`` starting with ``<``, bytes)."""
    if isinstance(source, (bytes, bytearray)):
        try:
            source = bytes(source).decode("utf-8")
        except UnicodeDecodeError as e:
            raise MJCFError(
                f"<bytes>: the MJCF is not UTF-8 text ({e.reason} at byte {e.start}); pass the "
                "file's path, or its text decoded.",
                file="<bytes>",
            ) from None
    if isinstance(source, str) and source.lstrip("\ufeff \t\r\n").startswith("<"):
        return source
    return None


class _Scan:
    """One pre-read of a model (module doc): the files MuJoCo would read, their bytes, their
    bodies. ``tops``: the directories relative paths are resolved in before the including
    file's own."""

    def __init__(self, label: str, tops: list[Path], budget: list[int]) -> None:
        self.label, self.tops, self.budget = label, tops, budget
        self.bodies = 0
        self.models: dict[str, int] = {}
        self.attached: list[tuple[str, int]] = []
        self.seen: set[str] = set()

    def refuse(self, message: str, element: str | None = None) -> MJCFError:
        return MJCFError(f"{self.label}: {message}", file=self.label, element=element)

    def locate(self, tag: str, name: str, here: Path) -> Path | None:
        """The file MuJoCo opens for ``<tag file=name>`` found in a file of directory ``here``
        (None: none exists, MuJoCo says so); refuses a candidate that is not a regular file."""
        element = f"<{tag} file={name!r}>"
        first = None
        tried = [Path(name)] if os.path.isabs(name) else [d / name for d in (*self.tops, here)]
        for c in dict.fromkeys(tried):
            try:
                mode = os.stat(c).st_mode
            except (OSError, ValueError):
                continue
            if not stat.S_ISREG(mode):
                kind = "a directory" if stat.S_ISDIR(mode) else "a FIFO, device or socket"
                raise self.refuse(
                    f"{element} names {str(c)!r}, which is {kind}, not a regular file (MuJoCo "
                    "would block or read without end); point it at an .xml file.",
                    element,
                )
            first = first or c
        return first

    def read(self, path: Path, element: str) -> bytes:
        """The bytes of ``path`` (a regular file, checked again once open), within budget."""
        flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
        try:
            fd = os.open(path, flags)
        except OSError as e:
            raise self.refuse(f"{element}: cannot read {str(path)!r} ({e.strerror}).") from None
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise self.refuse(f"{element}: {str(path)!r} is not a regular file.", element)
            data = f.read(self.budget[0] + 1)
        self.budget[0] -= len(data)
        if self.budget[0] < 0:
            raise self.refuse(
                f"the model and the files it includes hold more than {_size()} (reached at "
                f"{str(path)!r}); jaxkin refuses MJCF input that large.",
                element,
            )
        return data

    def scan(self, data: bytes | str, here: Path, where: str, mult: int = 1) -> None:
        """Count the bodies of the XML ``data`` (of a file in directory ``here``), times
        ``mult``, following its includes and model assets."""
        stack = [mult]
        parser = xml.parsers.expat.ParserCreate()

        def start(tag: str, attrs: dict[str, str]) -> None:
            m = stack[-1]
            if tag == "replicate":
                m *= _count(attrs.get("count"))
            elif tag == "body":
                self.bodies += m
            elif tag in _MULTIPLIERS:
                self.bodies += m * _count(attrs.get("count"))
            elif tag == "attach" and "model" in attrs:
                self.attached.append((attrs["model"], m))
            elif tag in ("include", "model") and "file" in attrs:
                self.follow(tag, attrs, here, m)
            stack.append(m)

        parser.StartElementHandler = start
        parser.EndElementHandler = lambda tag: stack.pop()
        try:
            parser.Parse(data, True)
        except xml.parsers.expat.ExpatError as e:
            raise self.refuse(f"{where} is not well-formed XML ({e}).") from None

    def follow(self, tag: str, attrs: dict[str, str], here: Path, mult: int) -> None:
        element = f"<{tag} file={attrs['file']!r}>"
        path = self.locate(tag, attrs["file"], here)
        key = os.path.realpath(path) if path is not None else None
        if path is None or key in self.seen:
            return  # missing: MuJoCo names it; twice: MuJoCo refuses "already included"
        self.seen.add(key)
        data = self.read(path, element)
        if tag == "include":
            self.scan(data, path.parent, str(path), mult)
            return
        model = _Scan(self.label, [*self.tops, path.parent], self.budget)
        model.seen = self.seen
        model.scan(data, path.parent, str(path))
        self.models[attrs.get("name", "")] = model.total()

    def total(self) -> int:
        return self.bodies + sum(m * self.models.get(name, 0) for name, m in self.attached)


def check_files(source: Any, *, max_bodies: int = MAX_BODIES) -> None:
    """Read the MJCF ``source`` (a path, or the XML as ``str``/``bytes``) and every file MuJoCo
    would read while parsing it, before MuJoCo does; refuse what would hang or exhaust it.

    Raises :class:`MJCFError`, naming the file and the element, for an ``<include>`` or
    ``<asset><model>`` file that is not a regular file (a FIFO, a device, a directory), for more
    than :data:`MAX_BYTES` bytes in all, and for more than ``max_bodies`` bodies (see the module
    doc for how they are counted and why). :func:`load_mjcf` calls it; so does the viewer.

    >>> import jaxkin.mjcf
    >>> jaxkin.mjcf.check_files('<mujoco><worldbody><body/><body/></worldbody></mujoco>',
    ...                         max_bodies=1)
    Traceback (most recent call last):
    ...
    jaxkin.mjcf.MJCFError: <string>: the model has 2 bodies, more than max_bodies=1; ...
    """
    if isinstance(max_bodies, bool) or not isinstance(max_bodies, int) or max_bodies < 1:
        raise JaxkinError(f"max_bodies must be a positive int, got {max_bodies!r}.")
    text = _xml_text(source)
    if text is not None:
        scan = _Scan("<string>", [Path()], [MAX_BYTES - len(text.encode("utf-8"))])
        if scan.budget[0] < 0:
            raise scan.refuse(f"the XML holds more than {_size()}; jaxkin refuses it.")
        scan.scan(text, Path(), "<string>")
    else:
        path = Path(source)
        scan = _Scan(str(source), [path.parent], [MAX_BYTES])
        scan.seen.add(os.path.realpath(path))
        scan.scan(scan.read(path, "the model file"), path.parent, str(source))
    n = scan.total()
    if n > max_bodies:
        raise scan.refuse(
            f"the model has {n} bodies, more than max_bodies={max_bodies}; MuJoCo's parser "
            f"takes a time quadratic in the number of bodies (about 4 s at {MAX_BODIES:,}, a "
            "minute at 32,000). To load it anyway, pass a larger max_bodies= "
            f"(jk.load_mjcf(..., max_bodies={n}))."
        )


# ------------------------------------------------------------------------------- compiling
def _spec(mujoco, source: Any, max_bodies: int):
    """MuJoCo's spec of ``source`` (pre-read by :func:`check_files`) and a label for messages."""
    text = _xml_text(source)
    if text is not None:
        label, load = "<string>", lambda: mujoco.MjSpec.from_string(text)
    elif isinstance(source, (str, os.PathLike)):
        path = Path(source)
        label = str(source)
        if not path.is_file():
            hint = "it is a directory" if path.is_dir() else "no such file"
            if path.exists() and not path.is_dir():
                hint = "it is not a regular file (a FIFO, a device or a socket)"
            raise MJCFError(
                f"cannot read the MJCF file {label}: {hint}. Pass the path of an .xml file, or "
                "the XML itself as a string (starting with '<').",
                file=label,
            )
        load = lambda: mujoco.MjSpec.from_file(str(path))  # noqa: E731
    else:
        raise ModelError(
            "source must be an MJCF path (str or os.PathLike), an XML string or bytes, got "
            f"{type(source).__name__}."
        )
    check_files(source, max_bodies=max_bodies)
    try:
        return load(), label
    except ValueError as e:
        raise _compiler_error(e, label, "MuJoCo could not parse the file") from None


def _compiler_error(e: Exception, label: str, what: str) -> MJCFError:
    text = " ".join(str(e).split())
    return MJCFError(
        f'{label}: {what}: {text}. Fix the element MuJoCo names (python -c "import mujoco; '
        f"mujoco.MjModel.from_xml_path('...')\" shows the same message).",
        file=label,
    )


def _strip_assets(mujoco, spec) -> set[str]:
    """Drop every file-backed asset (meshes, height fields, skins, textures): geoms that use
    them become small spheres (no frame depends on a geom's shape). Returns the names of the
    bodies whose mass MuJoCo would infer from such a geom (:func:`_weighs`): their compiled
    masses are those of the spheres, not the file's."""
    file_shapes = {mujoco.mjtGeom.mjGEOM_MESH, mujoco.mjtGeom.mjGEOM_HFIELD}
    sdf = getattr(mujoco.mjtGeom, "mjGEOM_SDF", None)
    if sdf is not None:
        file_shapes.add(sdf)
    unknown: set[str] = set()
    for g in spec.geoms:
        if g.type in file_shapes:
            if _weighs(mujoco, spec, g):
                unknown.add(g.parent.name)
            g.type = mujoco.mjtGeom.mjGEOM_SPHERE
            g.meshname = ""
            g.hfieldname = ""
            g.size = [0.01, 0.0, 0.0]
    for mat in spec.materials:
        mat.textures = [""] * len(mat.textures)
    for group in (spec.skins, spec.meshes, spec.hfields, spec.textures):
        for item in list(group):
            spec.delete(item)
    return unknown


def _weighs(mujoco, spec, g) -> bool:
    """Whether geom ``g`` adds to its body's compiled mass and inertia (MuJoCo's rules: the
    compiler's ``inertiafromgeom``, ``inertiagrouprange``, the body's explicit ``<inertial>``,
    the geom's ``mass`` or ``density``)."""
    rule = spec.compiler.inertiafromgeom
    modes = mujoco.mjtInertiaFromGeom
    if rule == modes.mjINERTIAFROMGEOM_FALSE:
        return False
    if rule == modes.mjINERTIAFROMGEOM_AUTO and g.parent.explicitinertial:
        return False
    lo, hi = (int(x) for x in spec.compiler.inertiagrouprange)
    if not lo <= int(g.group) <= hi:
        return False
    mass = float(g.mass)
    return mass > 0.0 if math.isfinite(mass) else float(g.density) > 0.0


def _compile(source: Any, max_bodies: int):
    mujoco = _mujoco()
    spec, label = _spec(mujoco, source, max_bodies)
    unknown = _strip_assets(mujoco, spec)
    spec.compiler.fusestatic = False  # every body stays a frame
    try:
        return mujoco, spec.compile(), label, spec.modelname, unknown
    except ValueError as e:
        raise _compiler_error(e, label, "MuJoCo could not compile the model") from None


# ------------------------------------------------------------------------------ converting
def _names(mujoco, m) -> tuple[list[str], list[str], list[str]]:
    """Body, joint and site names (generated for unnamed elements)."""

    def name(kind, i, fallback):
        return mujoco.mj_id2name(m, kind, i) or fallback

    bodies = [name(mujoco.mjtObj.mjOBJ_BODY, b, f"body{b}") for b in range(m.nbody)]
    bodies[0] = "world"
    joints = [name(mujoco.mjtObj.mjOBJ_JOINT, j, f"joint{j}") for j in range(m.njnt)]
    sites = [name(mujoco.mjtObj.mjOBJ_SITE, s, f"site{s}") for s in range(m.nsite)]
    return bodies, joints, sites


def _fixed(name: str, parent: str, child: str, T: np.ndarray) -> dict[str, Any]:
    return dict(name=name, type="fixed", parent=parent, child=child, transform=T)


_JOINT_TYPES = {0: "free", 1: "ball", 2: "slide", 3: "hinge"}


def _body_specs(m, b: int, names, label: str) -> list[dict[str, Any]]:
    """Joint specs that place body ``b`` (and its joints' anchor frames) in its parent."""
    bodies, joints, frame_name = names
    parent = bodies[int(m.body_parentid[b])]
    T = make_transform_np(quaternion_to_matrix_np(m.body_quat[b]), m.body_pos[b])
    adr, num = int(m.body_jntadr[b]), int(m.body_jntnum[b])
    if num == 0:
        return [_fixed(f"weld:{bodies[b]}", parent, bodies[b], T)]
    specs: list[dict[str, Any]] = []
    for k, j in enumerate(range(adr, adr + num)):
        jtype = _JOINT_TYPES[int(m.jnt_type[j])]
        spec: dict[str, Any] = dict(name=joints[j], parent=parent)
        axis = np.array(m.jnt_axis[j], dtype=float)
        anchor = np.array(m.jnt_pos[j], dtype=float) if jtype in ("hinge", "ball") else np.zeros(3)
        if jtype == "free":  # qpos is the body's pose in its parent (the world): body_pos unused
            T = np.eye(4)
        elif jtype == "ball":  # qpos is the rotation about the anchor (MuJoCo ignores ref)
            T = T @ make_transform_np(None, anchor)
        elif jtype == "hinge":  # Rot(axis, qpos - ref) = Rot(axis, -ref) Rot(axis, qpos)
            ref = float(m.qpos0[m.jnt_qposadr[j]])
            T = T @ make_transform_np(rotation_about_axis_np(axis, -ref), anchor)
        else:  # Trans(axis (qpos - ref)) = Trans(-ref axis) Trans(axis qpos)
            ref = float(m.qpos0[m.jnt_qposadr[j]])
            T = T @ make_transform_np(None, -ref * axis)
        # Its own frame at the anchor, unless it is the body's last joint and sits at its origin.
        last, at_origin = k == num - 1, not np.any(anchor != 0.0)
        child = bodies[b] if last and at_origin else frame_name(joints[j])
        if jtype in ("free", "ball"):
            spec.update(type=jtype, child=child, transform=T)
        else:
            lo, hi = (-math.inf, math.inf)
            if m.jnt_limited[j]:
                lo, hi = (float(v) for v in m.jnt_range[j])
            spec.update(
                type="revolute" if jtype == "hinge" else "prismatic",
                child=child,
                transform=T,
                axis=axis,
                lower=lo,
                upper=hi,
            )
        specs.append(spec)
        parent = child
        T = make_transform_np(None, -anchor)
    if specs[-1]["child"] != bodies[b]:
        specs.append(_fixed(f"weld:{bodies[b]}", parent, bodies[b], T))
    return specs


def _all_specs(mujoco, m, label: str) -> tuple[list[dict[str, Any]], dict[str, str]]:
    """Specs of every body, joint anchor and site (parents first), and frame -> body name."""
    bodies, joints, sites = _names(mujoco, m)
    taken = set(bodies)

    def frame_name(n: str, prefix: str = "joint") -> str:
        return n if n not in taken else f"{prefix}:{n}"

    specs: list[dict[str, Any]] = []
    for b in range(1, m.nbody):
        specs += _body_specs(m, b, (bodies, joints, frame_name), label)
    taken |= {s["child"] for s in specs}
    for s in range(m.nsite):
        b = int(m.site_bodyid[s])
        T = make_transform_np(quaternion_to_matrix_np(m.site_quat[s]), m.site_pos[s])
        child = frame_name(sites[s], "site")
        taken.add(child)
        specs.append(_fixed(f"site:{sites[s]}", bodies[b], child, T))
    return specs, {s["child"]: s["parent"] for s in specs}


def _inertial(m, b: int) -> dict[str, Any]:
    """Body ``b``'s compiled mass, centre of mass and principal inertia (``body_mass``,
    ``body_ipos``, ``body_iquat``, ``body_inertia``) as a :func:`jaxkin.build.from_joints`
    ``inertial``."""
    ix, iy, iz = (float(x) for x in m.body_inertia[b])
    return {
        "mass": float(m.body_mass[b]),
        "xyz": np.array(m.body_ipos[b], dtype=float),
        "quat": np.array(m.body_iquat[b], dtype=float),
        "inertia": (ix, 0.0, 0.0, iy, 0.0, iz),
    }


def _add_masses(m, specs: list[dict[str, Any]], bodies: list[str]) -> dict[str, Any]:
    """Give each body's spec (the one whose child is the body) its :func:`_inertial`; returns
    the world body's."""
    index = {name: b for b, name in enumerate(bodies)}
    for spec in specs:
        b = index.get(spec["child"])
        if b is not None and b > 0:
            spec["inertial"] = _inertial(m, b)
    return _inertial(m, 0)


def _selection_error(label: str, e: SelectionError, root: str, known: Sequence[str]):
    """:func:`jaxkin.build.select`'s refusal (or a ``base`` that is not a body: ``known`` are
    the bodies), with the file's label."""
    if e.problem == "not_below":
        return MJCFError(
            f"{label}: tip {e.name!r} is not below base {root!r}; choose a base that is an "
            "ancestor of the tip (or leave base=None).",
            file=label,
        )
    shown = list(known[:8])
    return MJCFError(
        f"{label}: {e.problem}={e.name!r} is not a "
        f"{'body' if e.problem == 'base' else 'body or site'}"
        f" of the model (frames: {shown}{' ...' if len(known) > 8 else ''}).",
        file=label,
    )


def _couplings(mujoco, m, label: str, selected: set[str], joint_names: list[str]):
    """Mimic specs ``{follower: mimic}`` from active joint equalities; refusals by name."""
    mimic: dict[str, dict[str, float | str]] = {}
    tendon_joints = _tendon_joints(mujoco, m, joint_names)
    for e in range(m.neq):
        if not m.eq_active0[e]:
            continue
        etype = int(m.eq_type[e])
        ename = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_EQUALITY, e) or f"equality {e}"
        where = f"<equality name={ename!r}>"
        if etype == int(mujoco.mjtEq.mjEQ_TENDON):
            t1, t2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
            coupled = set(tendon_joints[t1]) | (set(tendon_joints[t2]) if t2 >= 0 else set())
            if coupled & selected:
                raise MJCFError(
                    f"{label}: tendon equality {ename!r} couples joints "
                    f"{sorted(coupled & selected)} through tendons; jaxkin represents linear "
                    "joint couplings (<equality joint1 joint2 polycoef>) only. Load a part "
                    "without these joints (tip=/base=), or write the coupling as a joint "
                    "equality.",
                    file=label,
                    element=where,
                )
            continue
        if etype != int(mujoco.mjtEq.mjEQ_JOINT):
            continue  # connect, weld, ...: not couplings of the tree (mj_kinematics ignores them)
        y, x = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
        follower = joint_names[y]
        if follower not in selected:
            continue
        a = [float(v) for v in m.eq_data[e][:5]]
        problem = None
        if x < 0:
            problem = "has no joint2 (it holds joint1 at a constant)"
        elif any(c != 0.0 for c in a[2:]):
            problem = f"has a non-linear polycoef {a} (a2, a3, a4 must be 0)"
        elif follower in mimic:
            problem = f"is a second equality on joint {follower!r}"
        if problem is not None:
            raise MJCFError(
                f"{label}: joint equality {ename!r} on joint {follower!r} {problem}; jaxkin "
                "represents y - y0 = a0 + a1 (x - x0) between two hinge or slide joints only. "
                "Remove it, make it linear, or load a part without that joint (tip=/base=).",
                file=label,
                element=where,
            )
        y0, x0 = float(m.qpos0[m.jnt_qposadr[y]]), float(m.qpos0[m.jnt_qposadr[x]])
        mimic[follower] = {
            "joint": joint_names[x],
            "multiplier": a[1],
            "offset": y0 + a[0] - a[1] * x0,
        }
    return mimic


def _tendon_joints(mujoco, m, joint_names: list[str]) -> list[list[str]]:
    out = []
    for t in range(m.ntendon):
        adr, num = int(m.tendon_adr[t]), int(m.tendon_num[t])
        out.append(
            [
                joint_names[int(m.wrap_objid[w])]
                for w in range(adr, adr + num)
                if int(m.wrap_type[w]) == int(mujoco.mjtWrap.mjWRAP_JOINT)
            ]
        )
    return out


def load_mjcf(
    source: Any,
    tip: str | None = None,
    base: str | None = None,
    *,
    dtype: Any = None,
    name: str | None = None,
    max_bodies: int = MAX_BODIES,
) -> Robot:
    """Load an MJCF (MuJoCo) model as a :class:`~jaxkin.Robot` (see the module doc).

    Args:
      source: a path (``str`` or ``os.PathLike``) or the XML as ``str`` or ``bytes``.
      tip: optional body or site name: keep only the chain from ``base`` to it (then the
        default frame of ``fk``/``geometric_jacobian``).
      base: optional body name: the root of the result (default: the world body, ``"world"``);
        its frame is the world frame of the result.
      dtype: float32 or float64 (default: JAX's default float).
      name: the robot's name (default: ``<mujoco model=...>``).
      max_bodies: refuse a model with more bodies than this (default :data:`MAX_BODIES`,
        5,000: MuJoCo's parser is quadratic in the number of bodies; module doc).

    Returns:
      A placement robot whose ``q`` is MuJoCo's ``qpos`` of its joints (coupled joints left
      out; see "``q`` and ``qpos``" for the velocity of free joints) and whose frames are the
      bodies, joint anchors and sites; poses and Jacobians in the world frame of MuJoCo
      (``T_world_frame``; rows ``[v; omega]``).

    Raises:
      MJCFError: MuJoCo rejects the file, or it holds what jaxkin cannot represent
        (non-linear couplings, ...), named; or :func:`check_files` refuses it (an included
        file that is not a regular file, more than 16 MiB, more than ``max_bodies`` bodies).
      MJCFDependencyError: MuJoCo is not installed (``pip install 'jaxkin[mjcf]'``).

    >>> import jaxkin as jk
    >>> robot = jk.load_mjcf(
    ...     '''<mujoco model="arm"><worldbody><body name="upper">
    ...       <joint name="shoulder" axis="0 0 1"/><geom size=".05"/>
    ...       <body name="fore" pos="1 0 0"><joint name="elbow" axis="0 0 1" range="-90 90"/>
    ...         <geom size=".05"/><site name="hand" pos="1 0 0"/></body></body>
    ...     </worldbody></mujoco>'''
    ... )
    >>> robot.joint_names, robot.frame_names[-1], robot.frame_names[robot.tip_frame]
    (('shoulder', 'elbow'), 'hand', 'hand')
    >>> round(float(robot.upper[1]), 6)  # degrees in the file (MuJoCo's default), radians here
    1.570796
    >>> [round(float(x), 6) for x in jk.fk(robot, [0.0, 1.5707963267948966])[:3, 3]]
    [1.0, 1.0, 0.0]
    """
    mujoco, m, label, model_name, unknown = _compile(source, max_bodies)
    specs, parent_of = _all_specs(mujoco, m, label)
    root = "world" if base is None else base
    body_names, joint_names, _ = _names(mujoco, m)
    world_mass = None if unknown else _add_masses(m, specs, body_names)
    if base is not None and base not in body_names:
        problem = SelectionError("", "base", base)
        raise _selection_error(label, problem, root, body_names)
    try:
        sel = select(
            specs,
            "world",
            base,
            tip,
            mimics=lambda names: _couplings(mujoco, m, label, names, joint_names),
            root_inertial=world_mass,
        )
    except SelectionError as e:
        raise _selection_error(label, e, root, ["world", *parent_of]) from None
    try:
        return Robot.from_joints(
            sel.joints,
            root=sel.root,
            name=name or model_name or "mjcf",
            dtype=dtype,
            leaders=sel.leaders,
            default_frames=sel.default_frames,
            root_inertial=sel.root_inertial,
        )
    except MJCFError:
        raise
    except ModelError as e:
        raise MJCFError(f"{label}: {e}", file=label) from None
