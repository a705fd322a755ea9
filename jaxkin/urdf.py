"""URDF files -> :class:`~jaxkin.Robot`: safe, strict, iterative.

``jk.load_urdf(source, tip=None, base=None)`` reads a URDF (a path, an XML string or bytes) and
builds a placement robot (``Robot.from_joints``) holding the whole kinematic tree, or the chain
``base -> tip``, or the subtree below ``base``. :func:`parse_urdf` returns the validated
description itself (:class:`URDFModel`: every link and joint with its line number, fixed and
mimic joints included), for tools that need more than the kinematic model.

What is read, and how
---------------------
* Joint types ``revolute`` (one DOF, limited), ``continuous`` (one DOF, unbounded: ``q`` is the
  angle itself, not Pinocchio's (cos, sin) pair), ``prismatic`` and ``fixed``. A fixed joint's
  placement is kept as a frame named after its child link. ``floating`` joints become free joints
  (``q`` entries ``x, y, z, qw, qx, qy, qz``, 6 velocity entries) and ``planar`` joints planar
  ones (``x, y, cos, sin``; 3 velocity entries): see :mod:`jaxkin.configuration`. A planar joint
  moves in the plane normal to its ``<axis>``; jaxkin takes that plane to be its joint frame's xy
  plane, so an axis other than ``0 0 1`` is refused by name (Pinocchio ignores the axis and
  uses the xy plane: rotate the joint's origin instead). Their limits are not read.
* ``floating_base=True`` puts a free joint named ``root_joint`` above the root link, moving it
  relative to a new base frame ``universe`` (Pinocchio's ``JointModelFreeFlyer`` root joint and
  names), for humanoids and legged robots.
* ``<origin xyz rpy>``: ``T_parent_joint = Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)`` (URDF's fixed-
  axis roll-pitch-yaw); missing origin, xyz or rpy mean zero. The joint moves its child link,
  whose frame is the joint frame: ``T_parent_child(q) = T_parent_joint Motion(axis, value)``.
* ``<axis xyz>`` (in the joint frame; default ``1 0 0`` as the URDF spec says) is normalised in
  float64 with an overflow- and underflow-safe norm, so non-unit axes (``0 0 2``) and CAD residue
  (``0 1 6.12323e-17``) are taken as written, scaled to unit length. A zero or non-finite axis on
  a moving joint is an error; a fixed joint's axis is ignored (it must still be numbers).
  Several ``<axis>`` elements with the same ``xyz`` (found in real files; urdfdom takes the
  first) are read as one, with a :class:`URDFWarning`; several that differ are refused, naming
  both lines.
* ``<limit lower upper>``: required on revolute and prismatic joints (as urdfdom requires), lower
  and upper default to 0 there. ``lower > upper`` (``lower="1" upper="-1"``, how some simulators
  write "no limits"; urdfdom loads it) makes the joint unbounded, with a :class:`URDFWarning`
  naming the joint and line (one warning per file). On continuous, fixed, floating and planar
  joints ``<limit>`` is ignored (continuous joints are unbounded), though its values must still
  be numbers. ``effort`` and ``velocity`` are not read.
* ``<mimic joint multiplier offset>`` (defaults 1 and 0): ``value = multiplier * value_leader +
  offset``. Only independent joints are entries of ``q``; a mimic joint's Jacobian column folds
  into its leader's. A ``<mimic>`` on a fixed joint has no effect and is ignored (as urdfdom
  and Pinocchio do), once its leader is found to exist. Chains of mimic joints resolve to the
  independent joint at their end; a mimic joint whose leader lies outside a ``tip``/``base``
  selection is driven by the leader's entry of ``q`` all the same (named after the leader, with
  the leader's limits).
* ``<inertial>`` of a link (``<mass value>``, ``<inertia ixx ixy ixz iyy iyz izz>``, both
  required in it as urdfdom requires; optional ``<origin xyz rpy>``) becomes that frame's mass,
  centre of mass and inertia (``robot.frame_mass``, ``frame_com``, ``frame_inertia``, for
  :func:`jaxkin.center_of_mass`); a link without one is massless. A negative mass is refused;
  the inertia is taken as written, not checked for positive semi-definiteness or the triangle
  inequality (files in use miss them by rounding, e.g. moments of -5e-20, and urdfdom and
  Pinocchio load them).
* Names: ``robot.joint_names`` are the independent joints in ``q`` order: depth-first from the
  root, siblings in file order. (Pinocchio, through urdfdom, visits siblings sorted by joint
  name instead, so its ``q`` order can differ on trees: match joints by name.)
  ``robot.frame_names`` are the links in the same order (the root first), so
  ``jk.fk(robot, q, frame="panda_hand")`` and ``geometric_jacobian(..., frame=...)`` work for
  every link, with zero columns for joints not on that link's path.

The default frame
-----------------
``fk``, ``geometric_jacobian``, ``twist`` ... with ``frame=None`` use the robot's default frame
(:attr:`jaxkin.Robot.tip_frame`). It is never a frame that some moving joint of the loaded
robot does not move (mimic joints included), so no column of its Jacobian is zero by
construction:

* ``tip=`` given: the tip.
* The moving joints form one chain (each lies on the path from the root to the last one): the
  end of that chain. From the child link of the last moving joint, fixed joints are followed
  down while the link has exactly one child joint, and where the fixed frames branch, into the
  child named ``tool0`` if there is one (ROS-Industrial's tool flange, REP 199); the link where
  that stops is the default. So a single ``tool0``/``ee_link``/TCP frame fixed to the flange is
  taken; where the flange carries several fixed frames one of which is ``tool0`` (UR files:
  ``ee_link`` and ``tool0`` both on ``wrist_3_link``), ``tool0`` is; and where it carries
  several and none is ``tool0``, the flange link itself is (pass ``frame=``/``tip=`` for one of
  them). ``jk.robots.load("erd/...")`` follows the same rule (see
  :mod:`jaxkin.robots.example_robot_data` for the arms whose tool frame it cannot give).
* The moving joints branch (an arm with gripper fingers, a humanoid, a legged robot): there is
  no default. Loading succeeds (``fk_all`` and every function given ``frame=`` work), but a
  function asked for the default frame raises :class:`jaxkin.model.NoDefaultFrameError` (a
  :class:`jaxkin.ModelError`), eagerly and while tracing, listing the candidate end frames (the
  end of each branch, found as above) and how to choose: ``frame="..."`` per call, or
  ``load_urdf(path, tip="...")``.

Safety
------
The XML is parsed by expat with handlers that refuse any document type declaration (DOCTYPE),
entity or notation declaration before any of it is processed: no entity is ever expanded, no
external entity, file or URL is ever resolved. Input is capped at ``max_bytes`` (default
:data:`DEFAULT_MAX_BYTES`) before parsing. Mesh references are never opened, ``package://`` URLs
never resolved, xacro never run by the parser (a file with ``xacro:`` elements is refused).

A xacro file is a program, not data: xacro evaluates its ``${...}`` expressions as Python, with
no sandbox (a file can run any code on this machine), and reads the files it includes.
:func:`load_urdf` given a ``.xacro`` path (or ``xacro_args``) therefore refuses it unless called
with ``trust=True`` (only for files you trust), then expands it with the ``xacro`` package (the
``xacro`` extra) within caps: only regular files are read (a FIFO, device or directory is
refused by name, before reading), each at most ``max_bytes``, as is each expression's value; the
expansion stops after :data:`XACRO_TIME_LIMIT` seconds or :data:`XACRO_MAX_ELEMENTS` elements
(a macro doubling itself level after level); the parser's guarantees then hold for the expanded
URDF.

Every tree algorithm is iterative and linear (no recursion limit: a 3,000-joint chain, or a
3,000-joint chain of mimic joints, loads in about a second).

Errors
------
Every problem in a file raises :class:`URDFError` (a :class:`jaxkin.ModelError`) whose message
names the file, the line, the element, the attribute and the offending value, and says how to fix
it; the same facts are attributes of the exception.
"""

from __future__ import annotations

import difflib
import errno
import math
import os
import re
import stat
import sys
import threading
import time
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.parsers import expat

from .build import MimicError, Selection, SelectionError, resolve_mimics, select
from .errors import ModelError
from .model import Robot

__all__ = [
    "DEFAULT_MAX_BYTES",
    "MAX_MAGNITUDE",
    "XACRO_MAX_ELEMENTS",
    "XACRO_TIME_LIMIT",
    "URDFError",
    "URDFInertial",
    "URDFJoint",
    "URDFLink",
    "URDFMimic",
    "URDFModel",
    "URDFWarning",
    "load_urdf",
    "parse_urdf",
]

DEFAULT_MAX_BYTES = 16 * 1024 * 1024
"""Largest URDF accepted by default (16 MiB; the largest file of example-robot-data is 0.2 MB)."""

MAX_MAGNITUDE = 1e6
"""Largest magnitude accepted for a length in metres (origin ``xyz``), an origin angle in radians
(``rpy``), a mimic multiplier or offset, a mass in kg or a moment of inertia in kg m^2.
Anything larger is a typo or a unit error, and would overflow (or lose every digit of) the
kinematics; joint limits are not capped."""

MOVING_TYPES = ("revolute", "continuous", "prismatic")
"""The one-DOF joint types (entries of ``q`` one for one)."""
MULTI_DOF_TYPES = ("floating", "planar")
"""Joint types with several coordinates (free and planar joints of :mod:`jaxkin.configuration`)."""
SUPPORTED_TYPES = (*MOVING_TYPES, "fixed", *MULTI_DOF_TYPES)
REFUSED_TYPES: tuple[str, ...] = ()
ROOT_JOINT = "root_joint"
"""The name of the free joint ``load_urdf(..., floating_base=True)`` adds (Pinocchio's)."""
UNIVERSE = "universe"
"""The name of the base frame above the root link with ``floating_base=True`` (Pinocchio's)."""

_NUMBER = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
_SHOW = 80  # characters of an offending value shown in a message


# ---------------------------------------------------------------------------------- errors
class URDFError(ModelError):
    """An invalid or refused URDF. A :class:`jaxkin.ModelError` (hence a ``ValueError``).

    Attributes: ``file`` (path, ``"<string>"`` or ``"<bytes>"``), ``line`` (1-based, or None),
    ``element`` (e.g. ``"<axis> of joint 'j1'"``), ``attribute``, ``value`` (the offending text,
    or None), ``problem`` and ``fix`` (what was wrong, what to do).
    """

    def __init__(
        self,
        problem: str,
        *,
        file: str,
        line: int | None = None,
        element: str | None = None,
        attribute: str | None = None,
        value: str | None = None,
        fix: str | None = None,
    ) -> None:
        self.file, self.line, self.element = file, line, element
        self.attribute, self.value, self.problem, self.fix = attribute, value, problem, fix
        where = file if line is None else f"{file}, line {line}"
        parts = [where]
        if element:
            parts.append(element)
        if attribute:
            shown = "" if value is None else f"={_show(value)}"
            parts.append(f"attribute {attribute!r}{shown}")
        elif value is not None:
            parts.append(f"value {_show(value)}")
        message = ": ".join(parts) + f": {problem}"
        if fix:
            message += f" Fix: {fix}"
        super().__init__(message)

    def __reduce__(self):  # picklable (multiprocessing, pytest-xdist) despite keyword-only args
        kwargs = dict(
            file=self.file,
            line=self.line,
            element=self.element,
            attribute=self.attribute,
            value=self.value,
            fix=self.fix,
        )
        return (_rebuild_error, (self.problem, kwargs))


def _rebuild_error(problem: str, kwargs: dict[str, Any]) -> URDFError:
    return URDFError(problem, **kwargs)


class URDFWarning(UserWarning):
    """A URDF that urdfdom loads, written in a way jaxkin accepts and reads in one documented way:
    a ``<limit>`` with lower above upper (taken as no limits), a repeated identical ``<axis>``
    (used once). One warning per kind and file, naming the file, the joints and the lines."""


_NOTES = {
    "inverted_limits": (
        '<limit> with lower above upper, which some exporters (simulators) write for "no '
        'limits" and urdfdom loads: jaxkin takes the joint as unbounded (-inf, inf) (urdfdom and '
        "Pinocchio keep the inverted numbers, which no value satisfies). Fix: write the real "
        'limits with lower <= upper, or make a revolute joint type="continuous".'
    ),
    "duplicate_axis": (
        "the joint has several identical <axis> elements; jaxkin uses one, as urdfdom takes "
        "the first. Fix: delete the repeated <axis>."
    ),
}


def _user_stacklevel() -> int:
    """The ``stacklevel`` that makes a warning issued by the caller of this function point at
    the first frame outside jaxkin (the user's call)."""
    package = os.path.dirname(os.path.abspath(__file__)) + os.sep
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_code.co_filename.startswith(package):
        frame, level = frame.f_back, level + 1
    return level


def _show(value: str) -> str:
    text = value if len(value) <= _SHOW else value[:_SHOW] + "..."
    return repr(text)


# ---------------------------------------------------------------------------------- description
@dataclass(frozen=True)
class URDFInertial:
    """A link's ``<inertial>``: ``mass`` (kg), ``xyz``/``rpy`` (its ``<origin>``: the centre of
    mass and the inertia's axes in the link frame), ``inertia`` (``ixx, ixy, ixz, iyy, iyz,
    izz`` about the centre of mass in those axes, kg m^2)."""

    mass: float
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    inertia: tuple[float, float, float, float, float, float]
    line: int | None

    def spec(self) -> dict[str, Any]:
        """The ``inertial`` mapping of :func:`jaxkin.build.from_joints`."""
        return {"mass": self.mass, "xyz": self.xyz, "rpy": self.rpy, "inertia": self.inertia}


@dataclass(frozen=True)
class URDFLink:
    """A ``<link>``: its name, the line it is declared on and its ``<inertial>`` (None: a
    massless link)."""

    name: str
    line: int | None
    inertial: URDFInertial | None = None


@dataclass(frozen=True)
class URDFMimic:
    """A ``<mimic>``: ``value = multiplier * value_joint + offset``."""

    joint: str
    multiplier: float
    offset: float
    line: int | None


@dataclass(frozen=True)
class URDFJoint:
    """A validated ``<joint>``.

    ``xyz``/``rpy``: the origin in the parent link's frame; ``axis``: the unit axis in the joint
    frame (``(1, 0, 0)`` for fixed joints); ``lower``/``upper``: limits (infinite for continuous
    joints and for a ``<limit>`` written with lower above upper, NaN for fixed, floating and
    planar ones).
    """

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float]
    lower: float
    upper: float
    mimic: URDFMimic | None
    line: int | None


@dataclass(frozen=True)
class URDFModel:
    """A validated URDF: one tree of links joined by joints (file order kept)."""

    name: str
    file: str
    links: tuple[URDFLink, ...]
    joints: tuple[URDFJoint, ...]
    root: str

    @property
    def joint_map(self) -> dict[str, URDFJoint]:
        return {j.name: j for j in self.joints}

    @property
    def link_names(self) -> tuple[str, ...]:
        return tuple(link.name for link in self.links)

    @property
    def independent_joints(self) -> tuple[str, ...]:
        """Moving joints that are not mimic joints, depth-first from the root (``q`` order)."""
        return tuple(
            j.name for j in self.depth_first() if j.type in MOVING_TYPES and j.mimic is None
        )

    def children(self) -> dict[str, list[URDFJoint]]:
        """Joints leaving each link, in file order."""
        out: dict[str, list[URDFJoint]] = {link.name: [] for link in self.links}
        for j in self.joints:
            out[j.parent].append(j)
        return out

    def depth_first(self, start: str | None = None) -> Iterator[URDFJoint]:
        """Joints of the subtree below ``start`` (default: the root), depth-first pre-order,
        children in file order. Iterative."""
        children = self.children()
        stack = list(reversed(children[self.root if start is None else start]))
        while stack:
            joint = stack.pop()
            yield joint
            stack.extend(reversed(children[joint.child]))


# ---------------------------------------------------------------------------------- reading
class _Element:
    """A parsed XML element: tag, attributes, line, children (no text: URDF needs none)."""

    __slots__ = ("attrib", "children", "line", "tag")

    def __init__(self, tag: str, attrib: dict[str, str], line: int) -> None:
        self.tag, self.attrib, self.line = tag, attrib, line
        self.children: list[_Element] = []


def _looks_like_xml(text: str) -> bool:
    return text.lstrip("\ufeff \t\r\n").startswith("<")


_TOO_BIG = (
    "raise the cap with jk.load_urdf(..., max_bytes=N) (or parse_urdf(..., max_bytes=N)) "
    "if the file is legitimate."
)


def _read_source(source: Any, max_bytes: int) -> tuple[bytes | str, str]:
    """The document and a label for messages. Reads at most ``max_bytes + 1`` bytes."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        return _read_bytes(bytes(source), max_bytes), "<bytes>"
    if isinstance(source, str) and _looks_like_xml(source):
        return _read_xml_string(source, max_bytes), "<string>"
    if isinstance(source, (str, os.PathLike)):
        return _read_path(source, max_bytes)
    raise ModelError(
        "source must be a URDF path (str or os.PathLike), an XML string or bytes, got "
        f"{type(source).__name__}."
    )


def _read_bytes(data: bytes, max_bytes: int) -> bytes:
    """The document given as bytes, within the size cap."""
    if len(data) > max_bytes:
        raise URDFError(
            f"the document is {len(data)} bytes, over the {max_bytes}-byte limit (max_bytes).",
            file="<bytes>",
            fix=_TOO_BIG,
        )
    return data


def _read_xml_string(source: str, max_bytes: int) -> str:
    """The document given as an XML string, within the size cap (counted in UTF-8 bytes)."""
    if len(source) > max_bytes or len(source.encode("utf-8", "surrogatepass")) > max_bytes:
        raise URDFError(
            f"the document is over the {max_bytes}-byte limit (max_bytes).",
            file="<string>",
            fix=_TOO_BIG,
        )
    return source


def _read_path(source: str | os.PathLike, max_bytes: int) -> tuple[bytes, str]:
    """The bytes of the file at ``source`` and its label (the path, shortened if long)."""
    try:
        path = Path(source)
    except TypeError:
        path = None
    label = str(source)
    if len(label) > 200:  # a long non-XML string: shown shortened in messages
        label = label[:200] + "..."
    if path is None or not str(source):
        raise ModelError(
            f"source must be a URDF path, an XML string or bytes, got {source!r}."
        ) from None
    if path.suffix == ".xacro" or label.endswith(".xacro"):
        raise URDFError(
            "this is a xacro file; jaxkin never runs xacro (it executes code and reads other "
            "files).",
            file=label,
            fix=f"if you trust it, load it with jk.load_urdf({label!r}, trust=True) (runs its "
            f"code with the xacro package: {_XACRO_EXTRA}), or expand it first: "
            f"`xacro {label} > robot.urdf`.",
        )
    data = _read_file(path, label, max_bytes)
    if len(data) > max_bytes:
        raise URDFError(
            f"the file is over the {max_bytes}-byte limit (max_bytes).",
            file=label,
            fix=_TOO_BIG,
        )
    return data, label


def _read_file(path: Path, label: str, max_bytes: int) -> bytes:
    """At most ``max_bytes + 1`` bytes of a regular file; any failure is a :class:`URDFError`."""
    try:
        if not path.is_file():
            if path.is_dir():
                hint = "it is a directory."
            elif path.exists():
                hint = "it is not a regular file."
            else:
                hint = _missing_hint(path)
            raise URDFError(
                f"cannot read the URDF: {hint}",
                file=label,
                fix="pass the path of a .urdf file, or the XML itself as a string "
                "(starting with '<').",
            )
        size = path.stat().st_size
        if size > max_bytes:
            raise URDFError(
                f"the file is {size} bytes, over the {max_bytes}-byte limit (max_bytes).",
                file=label,
                fix=_TOO_BIG,
            )
        with open(path, "rb") as fh:
            return fh.read(max_bytes + 1)
    except URDFError:
        raise
    except (OSError, ValueError) as e:  # ValueError: e.g. an embedded NUL character
        raise URDFError(
            f"cannot read the URDF: {getattr(e, 'strerror', None) or e}.",
            file=label,
            fix="check the path, or pass the XML itself (a string starting with '<').",
        ) from None


def _missing_hint(path: Path) -> str:
    """Why ``path``, which does not resolve to an existing file, cannot be read."""
    try:
        os.stat(path)
    except OSError as e:
        if e.errno == errno.ELOOP:
            return (
                "it is a symbolic link loop (following its links comes back to a link already "
                "followed, so it names no file)."
            )
    if path.is_symlink():
        return f"it is a symbolic link to {_show(os.readlink(path))}, which does not exist."
    return "no such file."


def _parse_xml(data: bytes | str, label: str) -> _Element:
    """Parse with expat, refusing any DTD before it is processed; build a light element tree."""
    is_text = isinstance(data, str)
    data, offset = _strip_leading_space(data)
    # A str is parsed as UTF-8 whatever its XML declaration says (it is already decoded).
    parser = expat.ParserCreate(encoding="UTF-8" if is_text else None)
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    _refuse_dtd(parser, label, offset)
    root = _build_tree(parser, label, offset)
    try:
        parser.Parse(data, True)
    except expat.ExpatError as e:
        raise _syntax_error(e, label, offset) from None
    except RecursionError:  # pragma: no cover - expat is iterative; belt and braces
        raise URDFError("the XML is nested too deeply.", file=label) from None
    if not root:
        raise URDFError("the document has no root element.", file=label)
    return root[0]


def _strip_leading_space(data: bytes | str) -> tuple[bytes | str, int]:
    """The document without its leading whitespace, and the number of lines dropped.

    Leading whitespace (a triple-quoted string's first newline) would make an XML declaration
    illegal; it is dropped and its lines counted so that reported line numbers stay the source's.
    """
    is_text = isinstance(data, str)
    stripped = data.lstrip() if is_text else data.lstrip(b" \t\r\n")
    skipped = data[: len(data) - len(stripped)]
    return stripped, skipped.count("\n" if is_text else b"\n")


def _refuse_dtd(parser: Any, label: str, offset: int) -> None:
    """Install expat handlers that raise on any DTD, entity or notation declaration."""
    fix_dtd = (
        "remove the <!DOCTYPE ...> block and write the values out; URDF needs no DTD, and jaxkin "
        "refuses one so that no entity is ever expanded and no external file or URL is read."
    )

    def refuse(what: str):
        def handler(*args: Any) -> None:
            raise URDFError(
                f"{what} is not allowed in a URDF.",
                file=label,
                line=parser.CurrentLineNumber + offset,
                element=f"<!{what.split()[0]}>" if what.startswith(("DOCTYPE", "ENTITY")) else None,
                value=str(args[0]) if args and args[0] is not None else None,
                fix=fix_dtd,
            )

        return handler

    parser.StartDoctypeDeclHandler = refuse("DOCTYPE (document type declaration)")
    parser.EntityDeclHandler = refuse("ENTITY declaration")
    parser.UnparsedEntityDeclHandler = refuse("ENTITY declaration (unparsed)")
    parser.NotationDeclHandler = refuse("NOTATION declaration")
    parser.ExternalEntityRefHandler = refuse("external entity reference")
    parser.ElementDeclHandler = refuse("ELEMENT declaration")
    parser.AttlistDeclHandler = refuse("ATTLIST declaration")


def _build_tree(parser: Any, label: str, offset: int) -> list[_Element]:
    """Install the element handlers; the returned list receives the root element while parsing.
    ``xacro:`` elements are refused."""
    root: list[_Element] = []
    stack: list[_Element] = []

    def start(tag: str, attrib: dict[str, str]) -> None:
        elem = _Element(tag, attrib, parser.CurrentLineNumber + offset)
        if tag.startswith("xacro:"):
            raise URDFError(
                "xacro macros are not URDF; jaxkin never runs xacro.",
                file=label,
                line=elem.line,
                element=f"<{tag}>",
                fix="expand the file first: `xacro robot.urdf.xacro > robot.urdf`.",
            )
        if stack:
            stack[-1].children.append(elem)
        else:
            root.append(elem)
        stack.append(elem)

    def end(tag: str) -> None:
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    return root


def _syntax_error(e: expat.ExpatError, label: str, offset: int) -> URDFError:
    """The error for malformed XML, at the source's line."""
    message = expat.ErrorString(e.code)
    fix = "fix the XML syntax at that line (a URDF must be well-formed XML)."
    if "undefined entity" in message:
        fix = (
            "write the character out or use one of XML's predefined entities "
            "(&lt; &gt; &amp; &quot; &apos;); entity declarations are refused."
        )
    return URDFError(
        f"not well-formed XML: {message} (column {e.offset + 1}).",
        file=label,
        line=e.lineno + offset,
        fix=fix,
    )


# ---------------------------------------------------------------------------------- validation
class _Context:
    """Builds errors that name the file, line, element and attribute."""

    def __init__(self, label: str) -> None:
        self.file = label
        self.notes: dict[str, list[str]] = {}

    def note(self, kind: str, where: str) -> None:
        """Remember a tolerated oddity of ``kind`` (a key of ``_NOTES``) at ``where``."""
        self.notes.setdefault(kind, []).append(where)

    def warn_notes(self) -> None:
        """One :class:`URDFWarning` per kind of tolerated oddity, naming the places."""
        for kind, places in self.notes.items():
            more = f" and {len(places) - 10} more" if len(places) > 10 else ""
            warnings.warn(
                f"{self.file}: {', '.join(places[:10])}{more}: {_NOTES[kind]}",
                URDFWarning,
                stacklevel=_user_stacklevel(),
            )

    def error(self, problem: str, elem: _Element | None = None, **kw: Any) -> URDFError:
        line = kw.pop("line", elem.line if elem is not None else None)
        return URDFError(problem, file=self.file, line=line, **kw)

    def number(self, elem: _Element, owner: str, attr: str, default: float | None) -> float:
        text = elem.attrib.get(attr)
        if text is None:
            if default is None:
                raise self.error(
                    "the attribute is missing.",
                    elem,
                    element=owner,
                    attribute=attr,
                    fix=f'add {attr}="..." (a number).',
                )
            return default
        return self._to_float(text.strip(), elem, owner, attr, text)

    def vector3(self, elem: _Element, owner: str, attr: str, default: tuple) -> tuple:
        text = elem.attrib.get(attr)
        if text is None:
            return tuple(default)
        tokens = text.split()
        if len(tokens) != 3:
            raise self.error(
                f"expected 3 numbers separated by spaces, got {len(tokens)}.",
                elem,
                element=owner,
                attribute=attr,
                value=text,
                fix=f'write {attr}="x y z", e.g. {attr}="0 0 1".',
            )
        return tuple(self._to_float(t, elem, owner, attr, text) for t in tokens)

    def _to_float(self, token: str, elem: _Element, owner: str, attr: str, text: str) -> float:
        if not _NUMBER.fullmatch(token):
            if token.lower().lstrip("+-") in ("nan", "inf", "infinity"):
                problem = f"{token!r} is not a finite number."
                fix = "give a finite number (URDF uses metres and radians)."
            elif "$" in token or "{" in token:
                problem = f"{token!r} is a xacro expression, not a number."
                fix = "expand the file with xacro first: `xacro robot.urdf.xacro > robot.urdf`."
            else:
                problem = f"{token!r} is not a number." if token else "the value is empty."
                fix = "give a decimal number such as 0.1, -2 or 1.5e-3."
            raise self.error(problem, elem, element=owner, attribute=attr, value=text, fix=fix)
        x = float(token)
        if not math.isfinite(x):
            raise self.error(
                f"{token!r} overflows to infinity.",
                elem,
                element=owner,
                attribute=attr,
                value=text,
                fix="give a finite number.",
            )
        return x

    def bounded(self, values: tuple, elem: _Element, owner: str, attr: str, unit: str):
        big = [x for x in values if abs(x) > MAX_MAGNITUDE]
        if big:
            raise self.error(
                f"{big[0]!r} exceeds {MAX_MAGNITUDE:g}{f' {unit}' if unit else ''} in magnitude.",
                elem,
                element=owner,
                attribute=attr,
                value=elem.attrib.get(attr),
                fix=f"URDF is in SI units (metres, radians, kilograms); a value this large is a "
                "typo or a unit error "
                f"(jaxkin accepts |value| <= {MAX_MAGNITUDE:g}).",
            )

    def single(self, elem: _Element, tag: str, owner: str, required: bool) -> _Element | None:
        found = [c for c in elem.children if c.tag == tag]
        if len(found) > 1:
            raise self.error(
                f"{len(found)} <{tag}> elements (lines {[c.line for c in found]}); exactly one "
                "is allowed.",
                found[1],
                element=owner,
                fix=f"keep one <{tag}> and delete the others.",
            )
        if not found:
            if required:
                raise self.error(
                    f"the <{tag}> element is missing.",
                    elem,
                    element=owner,
                    fix=f"add <{tag} .../> inside it.",
                )
            return None
        return found[0]

    def name(self, elem: _Element, owner: str, attr: str = "name", example: str = "") -> str:
        value = elem.attrib.get(attr)
        if value is None or not value.strip():
            example = example or {"robot": "my_robot", "link": "link1", "joint": "joint1"}.get(
                elem.tag, "link1"
            )
            raise self.error(
                f"the {attr!r} attribute is {'missing' if value is None else 'empty'}.",
                elem,
                element=owner,
                attribute=attr,
                value=value,
                fix=f'give it a non-empty {attr}, e.g. {attr}="{example}".',
            )
        return value


def _axis(ctx: _Context, v: tuple, elem: _Element, owner: str, kind: str):
    norm = math.hypot(*v)  # scales internally: no overflow, no underflow
    if norm == 0.0:
        if kind not in MOVING_TYPES:
            return (1.0, 0.0, 0.0)
        raise ctx.error(
            f"the axis of a {kind} joint is a zero vector, which has no direction.",
            elem,
            element=owner,
            attribute="xyz",
            value=elem.attrib.get("xyz"),
            fix='give the direction of motion, e.g. xyz="0 0 1".',
        )
    u = tuple(x / norm for x in v)
    if not all(map(math.isfinite, u)):  # pragma: no cover - hypot is finite on finite input
        raise ctx.error("the axis cannot be normalised.", elem, element=owner, attribute="xyz")
    return u


def _joint(ctx: _Context, elem: _Element) -> URDFJoint:
    name = ctx.name(elem, "<joint>")
    owner = f"<joint name={name!r}>"
    kind = _joint_type(ctx, elem, owner)
    parent_el = ctx.single(elem, "parent", owner, required=True)
    child_el = ctx.single(elem, "child", owner, required=True)
    parent = ctx.name(parent_el, f"<parent> of joint {name!r}", "link")
    child = ctx.name(child_el, f"<child> of joint {name!r}", "link")
    xyz, rpy = _joint_origin(ctx, elem, owner, name)
    axis = _joint_axis(ctx, elem, owner, name, kind)
    lower, upper = _joint_limits(ctx, elem, owner, name, kind)
    mimic = _joint_mimic(ctx, elem, owner, name, kind)
    return URDFJoint(
        name=name,
        type=kind,
        parent=parent,
        child=child,
        xyz=xyz,
        rpy=rpy,
        axis=axis,
        lower=float(lower),
        upper=float(upper),
        mimic=mimic,
        line=elem.line,
    )


def _joint_type(ctx: _Context, elem: _Element, owner: str) -> str:
    """The ``type`` of a ``<joint>``, one of :data:`SUPPORTED_TYPES`."""
    kind = elem.attrib.get("type")
    if kind is None or kind not in SUPPORTED_TYPES:
        raise ctx.error(
            "unknown joint type." if kind is not None else "the joint has no type.",
            elem,
            element=owner,
            attribute="type",
            value=kind,
            fix=f"use one of {', '.join(SUPPORTED_TYPES)}.",
        )
    return kind


def _joint_origin(ctx: _Context, elem: _Element, owner: str, name: str) -> tuple[tuple, tuple]:
    """``(xyz, rpy)`` of the joint's ``<origin>`` (zero where missing), bounded in magnitude."""
    return _origin(ctx, elem, owner, f"<origin> of joint {name!r}")


def _origin(ctx: _Context, elem: _Element, owner: str, where: str) -> tuple[tuple, tuple]:
    """``(xyz, rpy)`` of ``elem``'s ``<origin>`` (zero where missing), bounded in magnitude."""
    xyz, rpy = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    origin = ctx.single(elem, "origin", owner, required=False)
    if origin is not None:
        xyz = ctx.vector3(origin, where, "xyz", (0.0, 0.0, 0.0))
        ctx.bounded(xyz, origin, where, "xyz", "m")
        rpy = ctx.vector3(origin, where, "rpy", (0.0, 0.0, 0.0))
        ctx.bounded(rpy, origin, where, "rpy", "rad")
    return xyz, rpy


_INERTIA = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")


def _inertial(ctx: _Context, link: _Element, name: str) -> URDFInertial | None:
    """The link's ``<inertial>`` (None without one): ``<mass value>`` and ``<inertia>`` with its
    six attributes are required (as urdfdom requires them), ``<origin>`` optional. A negative
    mass is refused; the moments are taken as written (files in use hold -5e-20 for 0)."""
    elem = ctx.single(link, "inertial", f"<link name={name!r}>", required=False)
    if elem is None:
        return None
    owner = f"<inertial> of link {name!r}"
    xyz, rpy = _origin(ctx, elem, owner, f"<origin> of {owner}")
    mass_el = ctx.single(elem, "mass", owner, required=True)
    where = f"<mass> of link {name!r}"
    mass = ctx.number(mass_el, where, "value", None)
    ctx.bounded((mass,), mass_el, where, "value", "kg")
    if mass < 0.0:
        raise ctx.error(
            f"the mass {mass!r} is negative.",
            mass_el,
            element=where,
            attribute="value",
            value=mass_el.attrib.get("value"),
            fix="give the link's mass in kg (>= 0; 0 for a massless frame).",
        )
    inertia_el = ctx.single(elem, "inertia", owner, required=True)
    where = f"<inertia> of link {name!r}"
    inertia = tuple(ctx.number(inertia_el, where, a, None) for a in _INERTIA)
    for a, x in zip(_INERTIA, inertia, strict=True):
        ctx.bounded((x,), inertia_el, where, a, "kg m^2")
    return URDFInertial(float(mass), xyz, rpy, inertia, elem.line)  # type: ignore[arg-type]


def _joint_axis(ctx: _Context, elem: _Element, owner: str, name: str, kind: str) -> tuple:
    """The unit axis of the joint's ``<axis>`` (default ``1 0 0``; ``1 0 0`` for fixed joints)."""
    axis: tuple[float, float, float] = (1.0, 0.0, 0.0)
    axis_el = _axis_element(ctx, elem, owner, name)
    if axis_el is not None:
        where = f"<axis> of joint {name!r}"
        v = ctx.vector3(axis_el, where, "xyz", (1.0, 0.0, 0.0))
        axis = _axis(ctx, v, axis_el, where, kind)
    if kind not in MOVING_TYPES:
        axis = (1.0, 0.0, 0.0) if kind == "fixed" else axis
    return axis


def _axis_element(ctx: _Context, elem: _Element, owner: str, name: str) -> _Element | None:
    """The joint's ``<axis>``, or None. Repeated ``<axis>`` elements with the same ``xyz``
    (urdfdom takes the first) are accepted with one warning; differing ones are refused."""
    found = [c for c in elem.children if c.tag == "axis"]
    where = f"<axis> of joint {name!r}"
    values = [ctx.vector3(c, where, "xyz", (1.0, 0.0, 0.0)) for c in found]
    for c, v in zip(found[1:], values[1:], strict=True):
        if v != values[0]:
            first = found[0].attrib.get("xyz", "1 0 0 (no xyz)")
            raise ctx.error(
                f"{len(found)} <axis> elements that differ: xyz={first!r} on line "
                f"{found[0].line} and xyz={c.attrib.get('xyz', '1 0 0 (no xyz)')!r} on line "
                f"{c.line}; jaxkin does not guess which is meant (urdfdom silently takes the "
                "first).",
                c,
                element=owner,
                attribute="xyz",
                value=c.attrib.get("xyz"),
                fix="keep the right <axis> and delete the other.",
            )
    if len(found) > 1:
        lines = ", ".join(str(c.line) for c in found)
        ctx.note("duplicate_axis", f"joint {name!r} (<axis> on lines {lines})")
    return found[0] if found else None


def _joint_limits(ctx: _Context, elem: _Element, owner: str, name: str, kind: str):
    """``(lower, upper)`` of the joint: its ``<limit>`` (required on revolute and prismatic
    joints; lower above upper means no limits, with a warning), infinite for continuous joints,
    NaN for the others (whose ``<limit>``, if any, must hold numbers but is not used)."""
    lower, upper = math.nan, math.nan
    limit = ctx.single(elem, "limit", owner, required=False)
    if kind in ("revolute", "prismatic") and limit is None:
        raise ctx.error(
            f"a {kind} joint needs a <limit> element (URDF requires one).",
            elem,
            element=owner,
            fix='add <limit lower="..." upper="..." effort="..." velocity="..."/>'
            + (
                ", or make it type='continuous' if it turns without limits."
                if kind == "revolute"
                else "."
            ),
        )
    if limit is not None:
        where = f"<limit> of joint {name!r}"
        lo = ctx.number(limit, where, "lower", 0.0)
        hi = ctx.number(limit, where, "upper", 0.0)
        if kind in ("revolute", "prismatic"):
            lower, upper = lo, hi
            if lo > hi:  # some exporters' "no limits"; urdfdom loads it
                ctx.note("inverted_limits", f"joint {name!r} (line {limit.line}: {lo!r} > {hi!r})")
                lower, upper = -math.inf, math.inf
    if kind == "continuous":
        lower, upper = -math.inf, math.inf
    return lower, upper


def _joint_mimic(
    ctx: _Context, elem: _Element, owner: str, name: str, kind: str
) -> URDFMimic | None:
    """The joint's ``<mimic>`` (multiplier 1 and offset 0 by default), or None."""
    mimic_el = ctx.single(elem, "mimic", owner, required=False)
    if mimic_el is None:
        return None
    where = f"<mimic> of joint {name!r}"
    if kind in MULTI_DOF_TYPES:
        raise ctx.error(
            f"a {kind} joint cannot mimic another joint.",
            mimic_el,
            element=where,
            fix="remove the <mimic>, or give the joint a moving type.",
        )
    leader = ctx.name(mimic_el, where, "joint", example="joint1")
    mult = ctx.number(mimic_el, where, "multiplier", 1.0)
    off = ctx.number(mimic_el, where, "offset", 0.0)
    for attr, val in (("multiplier", mult), ("offset", off)):
        ctx.bounded((val,), mimic_el, where, attr, "")
    return URDFMimic(leader, mult, off, mimic_el.line)


def _suggest(name: str, candidates: Sequence[str]) -> str:
    close = difflib.get_close_matches(name, list(candidates), n=3)
    return f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


def _topology(ctx: _Context, links: list[URDFLink], joints: list[URDFJoint]) -> str:
    """Check that links and joints form one tree; return the root link. Iterative."""
    link_line = {link.name: link.line for link in links}
    parent_joint = _parent_joints(ctx, link_line, joints)
    roots = [link.name for link in links if link.name not in parent_joint]
    # Every link reachable from a root is fine; any other link lies on a cycle (each link has at
    # most one parent, so walking up from it must come back to itself).
    children: dict[str, list[str]] = {link.name: [] for link in links}
    for j in joints:
        children[j.parent].append(j.child)
    seen = set(roots)
    stack = list(roots)
    while stack:
        for c in children[stack.pop()]:
            if c not in seen:
                seen.add(c)
                stack.append(c)
    if len(seen) != len(links):
        start = next(link.name for link in links if link.name not in seen)
        raise _cycle_error(ctx, start, parent_joint)
    if len(roots) > 1:
        shown = roots if len(roots) <= 8 else [*roots[:8], "..."]
        raise ctx.error(
            f"the links form {len(roots)} separate trees, with roots {shown}; a URDF has exactly "
            "one root link.",
            line=link_line[roots[1]],
            element=f"<link name={roots[1]!r}>",
            fix="connect every root but one to the robot with a joint, or delete the stray links.",
        )
    return roots[0]


def _parent_joints(
    ctx: _Context, link_line: dict[str, int | None], joints: list[URDFJoint]
) -> dict[str, URDFJoint]:
    """The joint above each child link, checking that every joint joins two different declared
    links and that no link has two parents."""
    parent_joint: dict[str, URDFJoint] = {}
    for j in joints:
        for role, link in (("parent", j.parent), ("child", j.child)):
            if link not in link_line:
                raise ctx.error(
                    f"{role} link {link!r} is not declared by any <link>."
                    f"{_suggest(link, link_line)}",
                    line=j.line,
                    element=f"<{role}> of joint {j.name!r}",
                    attribute="link",
                    value=link,
                    fix=f'declare <link name="{link}"/> or correct the name.',
                )
        if j.parent == j.child:
            raise ctx.error(
                f"the joint connects link {j.child!r} to itself (a cycle).",
                line=j.line,
                element=f"<joint name={j.name!r}>",
                fix="a joint must join two different links.",
            )
        if j.child in parent_joint:
            other = parent_joint[j.child]
            raise ctx.error(
                f"link {j.child!r} has two parents: joint {other.name!r} (line {other.line}) and "
                f"joint {j.name!r} both name it as their child. A URDF is a tree; closed chains "
                "are not expressible.",
                line=j.line,
                element=f"<child> of joint {j.name!r}",
                attribute="link",
                value=j.child,
                fix="give each link at most one parent joint (remove or re-parent one of them).",
            )
        parent_joint[j.child] = j
    return parent_joint


def _cycle_error(ctx: _Context, start: str, parent_joint: dict[str, URDFJoint]) -> URDFError:
    """The error for the cycle of joints reached by walking up the parents from ``start`` (a link
    that no root reaches)."""
    path = [start]
    visited = {start}
    cur = parent_joint[start].parent
    while cur not in visited:
        path.append(cur)
        visited.add(cur)
        cur = parent_joint[cur].parent
    cycle = [*path[path.index(cur) :], cur]
    cycle.reverse()
    j = parent_joint[cycle[1]]
    return ctx.error(
        f"the joints form a cycle: {' -> '.join(cycle)}. A URDF is a tree.",
        line=j.line,
        element=f"<joint name={j.name!r}>",
        fix="break the cycle: every link but the root needs exactly one parent joint, and "
        "following parents must end at the root.",
    )


def _resolve_mimics(
    ctx: _Context, joints: Sequence[URDFJoint]
) -> dict[str, tuple[str, float, float]]:
    """Validate every ``<mimic>`` of the file (:func:`jaxkin.build.resolve_mimics`), with the
    line of the offending ``<mimic>`` in the error. A ``<mimic>`` on a fixed joint is ignored, as
    urdfdom and Pinocchio do (Talos' grippers have such joints), once its leader exists."""
    by_name = {j.name: j for j in joints}
    mimics = {}
    for j in joints:
        if j.mimic is None:
            continue
        if j.type in MOVING_TYPES:
            mimics[j.name] = (j.mimic.joint, j.mimic.multiplier, j.mimic.offset)
        elif j.mimic.joint not in by_name:
            raise _mimic_error(ctx, j, j.mimic.joint, "does not exist", by_name, fixed=True)
    kinds = {j.name: j.type if j.type not in MOVING_TYPES else "revolute" for j in joints}
    try:
        return resolve_mimics(mimics, kinds)
    except MimicError as e:
        j = by_name[e.joint]
        if e.problem == "missing":
            raise _mimic_error(ctx, j, e.leader, "does not exist", by_name) from None
        if e.problem == "not_moving":
            raise _mimic_error(ctx, j, e.leader, f"is {by_name[e.leader].type}", by_name) from None
        raise ctx.error(
            f"mimic joints form a cycle ({' -> '.join(e.cycle)}): none of them is independent.",
            line=j.mimic.line,
            element=f"<mimic> of joint {j.name!r}",
            attribute="joint",
            value=e.leader,
            fix="remove the <mimic> of one joint of the cycle, so that it drives the others.",
        ) from None


def _mimic_error(ctx, j: URDFJoint, leader: str, what: str, by_name, fixed=False) -> URDFError:
    if fixed:
        fix = (
            "name an existing joint, or delete the <mimic> (a fixed joint does not move, so its "
            "<mimic> has no effect)."
        )
    elif what == "does not exist":
        fix = "name an existing revolute, continuous or prismatic joint."
    else:
        fix = "a mimic joint must follow a revolute, continuous or prismatic joint."
    hint = _suggest(leader, by_name) if what == "does not exist" else ""
    return ctx.error(
        f"it mimics joint {leader!r}, which {what}.{hint}",
        line=j.mimic.line,
        element=f"<mimic> of joint {j.name!r}",
        attribute="joint",
        value=leader,
        fix=fix,
    )


def parse_urdf(source: Any, *, max_bytes: int = DEFAULT_MAX_BYTES) -> URDFModel:
    """Read and validate a URDF; return its description (:class:`URDFModel`).

    Args:
      source: a path (``str`` or ``os.PathLike``), the XML as a ``str`` (starting with ``<``,
        after optional whitespace) or as ``bytes``.
      max_bytes: size cap, checked before parsing.

    Raises:
      URDFError: for any invalid or refused input (see the module doc).

    Warns:
      URDFWarning: once per kind of tolerated oddity (lower above upper, a repeated identical
        ``<axis>``), naming the joints and lines, after the file is found valid.
    """
    _check_max_bytes(max_bytes)
    data, label = _read_source(source, max_bytes)
    root = _parse_xml(data, label)
    ctx = _Context(label)
    if root.tag != "robot":
        hint = {
            "sdf": "this is an SDF file",
            "mujoco": "this is an MJCF (MuJoCo) file",
        }.get(root.tag, f"the root element is <{root.tag}>")
        raise ctx.error(
            f"{hint}, not a URDF (whose root element is <robot>).",
            root,
            element=f"<{root.tag}>",
            fix="pass a URDF file.",
        )
    links: list[URDFLink] = []
    link_line: dict[str, int] = {}
    joints: list[URDFJoint] = []
    joint_line: dict[str, int | None] = {}
    for elem in root.children:
        if elem.tag == "link":
            name = ctx.name(elem, "<link>")
            if name in link_line:
                raise ctx.error(
                    f"link {name!r} is declared twice (first on line {link_line[name]}).",
                    elem,
                    element=f"<link name={name!r}>",
                    attribute="name",
                    value=name,
                    fix="link names must be unique: rename or delete one.",
                )
            link_line[name] = elem.line
            links.append(URDFLink(name, elem.line, _inertial(ctx, elem, name)))
        elif elem.tag == "joint":
            j = _joint(ctx, elem)
            if j.name in joint_line:
                raise ctx.error(
                    f"joint {j.name!r} is declared twice (first on line {joint_line[j.name]}).",
                    elem,
                    element=f"<joint name={j.name!r}>",
                    attribute="name",
                    value=j.name,
                    fix="joint names must be unique: rename or delete one.",
                )
            joint_line[j.name] = j.line
            joints.append(j)
    if not links:
        raise ctx.error(
            "the robot has no <link>.",
            root,
            element="<robot>",
            fix="a URDF needs at least one link (is this an unexpanded or empty xacro output?).",
        )
    robot_name = ctx.name(root, "<robot>")
    root_link = _topology(ctx, links, joints)
    _resolve_mimics(ctx, joints)
    ctx.warn_notes()
    return URDFModel(robot_name, label, tuple(links), tuple(joints), root_link)


# ---------------------------------------------------------------------------------- building
_FREE_ROOT = {
    "name": ROOT_JOINT,
    "type": "free",
    "parent": UNIVERSE,
    "xyz": (0.0,) * 3,
    "rpy": (0.0,) * 3,
}
"""The spec of the free joint ``floating_base=True`` puts above the selection (its child is set
by :func:`jaxkin.build.select`)."""


def _select(
    model: URDFModel, tip: str | None, base: str | None, ctx: _Context, floating: bool = False
) -> tuple[Selection, list[URDFJoint]]:
    """The selected chain or subtree (:func:`jaxkin.build.select`, with a free joint above it
    when ``floating``) and its URDF joints (parents first); a ``base`` below which the selection
    has no moving joint is refused (:func:`_refuse_motionless`)."""
    above = _FREE_ROOT if floating else None
    mass = {link.name: link.inertial.spec() for link in model.links if link.inertial is not None}
    specs = [_joint_spec(j, mass.get(j.child)) for j in model.joints]
    try:
        sel = select(specs, model.root, base, tip, above=above, root_inertial=mass.get(model.root))
    except SelectionError as e:
        raise _selection_error(model, ctx, e, base) from None
    joints = [model.joints[i] for i in sel.index]
    if base is not None and not floating:
        _refuse_motionless(model, tip, base, joints, ctx)
    return sel, joints


def _selection_error(
    model: URDFModel, ctx: _Context, e: SelectionError, base: str | None
) -> URDFError:
    """:func:`jaxkin.build.select`'s refusal, with the file's context."""
    if e.problem == "not_below":
        start = model.root if base is None else base
        return ctx.error(
            f"tip {e.name!r} is not below base {start!r}: the path from the root "
            f"{model.root!r} to {e.name!r} does not pass through {start!r}.",
            fix="choose a base link that is an ancestor of the tip (or leave base=None).",
        )
    names = model.link_names
    return ctx.error(
        f"{e.problem}={e.name!r} is not a link of robot {model.name!r}."
        f"{_suggest(str(e.name), names)}",
        fix=f"pass the name of a link ({len(names)} links, e.g. {list(names[:5])}).",
    )


def _refuse_motionless(
    model: URDFModel, tip: str | None, base: str, joints: list[URDFJoint], ctx: _Context
) -> None:
    """Refuse an explicit ``base`` whose selection (the subtree below it, or the chain to
    ``tip``) has no moving joint while the file has some: a robot with nothing to move. A file
    with no moving joint at all (dof 0 whole) loads with any base."""
    if any(j.type != "fixed" for j in joints) or all(j.type == "fixed" for j in model.joints):
        return
    parent_joint = {j.child: j for j in model.joints}
    if tip is None:
        what = f"nothing moves below base {base!r} (a leaf, or only fixed joints below it)"
        wanted = {j.parent for j in model.joints if j.type != "fixed"}  # links above a mover
        for j in reversed(list(model.depth_first())):  # children before parents
            if j.child in wanted:
                wanted.add(j.parent)
    else:
        what = f"no joint between base {base!r} and tip {tip!r} moves"
        on_path = [tip, *_ancestors(tip, parent_joint)]
        wanted = {
            parent_joint[link].parent
            for link in on_path
            if link in parent_joint and parent_joint[link].type != "fixed"
        }
    up = next((link for link in _ancestors(base, parent_joint) if link in wanted), None)
    to = "down" if tip is None else f"to tip {tip!r}"
    hint = f"base={up!r} (the nearest link above it with a moving joint {to}), " if up else ""
    raise ctx.error(
        f"{what}: the robot would have no degree of freedom.",
        line=next(link.line for link in model.links if link.name == base),
        element=f"<link name={base!r}>",
        fix=f"choose a base above a moving joint, e.g. {hint}or leave base=None (the whole "
        f"robot, from its root {model.root!r}); to read the pose of {base!r}, pass "
        f"frame={base!r} to fk.",
    )


def _ancestors(link: str, parent_joint: Mapping[str, URDFJoint]) -> Iterator[str]:
    """The links above ``link``, nearest first."""
    while link in parent_joint:
        link = parent_joint[link].parent
        yield link


def _refuse_unsupported(ctx: _Context, joints: list[URDFJoint]) -> None:
    """Planar joints whose plane is not their joint frame's xy plane are refused by name."""
    for j in joints:
        off = max(abs(a - b) for a, b in zip(j.axis, (0.0, 0.0, 1.0), strict=True))
        if j.type == "planar" and off > 1e-12:
            axis = " ".join(f"{a:g}" for a in j.axis)
            raise ctx.error(
                f"joint {j.name!r} is planar with axis {axis} (the normal of its plane; "
                "1 0 0 when <axis> is missing); jaxkin's planar joint moves in the joint frame's "
                "xy plane (axis 0 0 1), and does not silently move it in another plane "
                "(Pinocchio ignores the axis).",
                line=j.line,
                element=f"<joint name={j.name!r}>",
                attribute="axis",
                value=axis,
                fix="rotate the joint's <origin rpy> so that the plane's normal is its z axis and "
                'write <axis xyz="0 0 1"/>, or load what hangs below it with '
                f"base={j.child!r} (poses are then relative to {j.child!r}).",
            )


def load_urdf(
    source: Any,
    tip: str | None = None,
    base: str | None = None,
    *,
    max_bytes: int = DEFAULT_MAX_BYTES,
    dtype: Any = None,
    name: str | None = None,
    xacro_args: Mapping[str, Any] | None = None,
    floating_base: bool = False,
    trust: bool = False,
) -> Robot:
    """Load a URDF as a :class:`~jaxkin.Robot` (a placement robot; see the module doc).

    Args:
      source: a path (``str`` or ``os.PathLike``), the XML as ``str`` or ``bytes``.
      tip: optional link name: keep only the chain from ``base`` to ``tip`` (the default frame of
        ``fk``/``geometric_jacobian`` is then ``tip``).
      base: optional link name: the root of the model (default: the URDF's root link). Its frame
        is the world frame of the result; joints above it are dropped. A base below which
        (or, with ``tip``, between which and ``tip``) no joint moves is refused, naming a base
        that works, unless the file has no moving joint at all or ``floating_base=True``.
      max_bytes: size cap (default 16 MiB), checked before parsing.
      dtype: float32 or float64 (default: JAX's default float).
      name: the robot's name (default: the URDF's ``<robot name>``).
      xacro_args: ``name -> value`` of the file's ``<xacro:arg>`` (``xacro robot.urdf.xacro
        name:=value``). A path ending in ``.xacro`` (or any path given with ``xacro_args``) is
        first expanded with the ``xacro`` package (``pip install 'jaxkin[xacro]'``), and only
        with ``trust=True``.
      floating_base: add a free joint ``"root_joint"`` above the root link (``base`` when
        given), moving it relative to a new base frame ``"universe"``, as Pinocchio's
        ``buildModelFromUrdf(path, pin.JointModelFreeFlyer())``: ``q`` starts with the 7
        entries ``root_joint.x`` ... ``root_joint.qz`` (position, then unit quaternion, scalar
        first) and the velocity with 6 (the root link's twist in its own axes); see
        :mod:`jaxkin.configuration`.
      trust: ``True`` lets a xacro file be expanded, which runs code from the file: xacro
        evaluates its ``${...}`` expressions as Python, with no sandbox, so a file can do
        anything your user can (read, write, delete files). Only for files you trust; without
        it a xacro file is refused (a plain URDF never runs anything, trusted or not). A trusted
        expansion is still capped: it reads only regular files (a FIFO, device or directory is
        refused) of at most ``max_bytes``, stops after :data:`XACRO_TIME_LIMIT` seconds or
        :data:`XACRO_MAX_ELEMENTS` elements, and parses the result with the strict parser.

    Returns:
      A robot whose ``frame_names`` are the selected links (``base`` first, then depth-first,
      siblings in file order), whose ``joint_names`` are the independent joints (``q`` order) and
      whose limits are the URDF's (continuous joints unbounded). The default frame (``frame=None``)
      is ``tip``; without ``tip``, the end of the chain of moving joints, or none when they
      branch (then functions need ``frame=``): see "The default frame" in the module doc.

    Raises:
      URDFError: invalid or refused file (a :class:`jaxkin.ModelError`), with file, line,
        element, attribute, value and a fix in the message.

    Warns:
      URDFWarning: a file urdfdom loads that jaxkin reads in one documented way (``<limit>``
        with lower above upper: no limits; a repeated identical ``<axis>``); once per kind.
    """
    _check_trust(trust)
    if xacro_args is not None or _is_xacro_path(source):
        model = _parse_xacro(source, xacro_args or {}, max_bytes, trust)
    else:
        model = parse_urdf(source, max_bytes=max_bytes)
    ctx = _Context(model.file)
    sel, joints = _select(model, tip, base, ctx, floating_base)
    _refuse_unsupported(ctx, joints)
    if floating_base and (UNIVERSE in model.link_names or ROOT_JOINT in model.joint_map):
        clash = UNIVERSE if UNIVERSE in model.link_names else ROOT_JOINT
        raise ctx.error(
            f"floating_base=True adds a base frame {UNIVERSE!r} and a free joint "
            f"{ROOT_JOINT!r}, but the file already has a link or joint named {clash!r}.",
            fix="rename it in the file, or load without floating_base.",
        )
    try:
        return Robot.from_joints(
            sel.joints,
            root=sel.root,
            name=name or model.name,
            dtype=dtype,
            leaders=sel.leaders,
            default_frames=sel.default_frames,
            root_inertial=sel.root_inertial,
        )
    except URDFError:
        raise
    except ModelError as e:  # pragma: no cover - the parser validates everything first
        raise ctx.error(f"invalid model: {e}") from None


_XACRO_EXTRA = "pip install 'jaxkin[xacro]' (or pip install xacro)"

XACRO_TIME_LIMIT = 10.0
"""Seconds :func:`load_urdf` lets xacro expand one file (``trust=True``) before refusing it,
checked at every element, expression and file xacro reads (real robot descriptions expand in
well under 0.1 s). Code that runs inside one expression is not interrupted. For a file known to
be slow, raise it (``jaxkin.urdf.XACRO_TIME_LIMIT = 60``) or expand the file with the ``xacro``
command."""

XACRO_MAX_ELEMENTS = 100_000
"""Elements xacro may process while expanding one file in :func:`load_urdf` (macro bodies and
output elements; a dual-arm Panda description needs about 550) before it is refused: a macro
that calls itself twice per level doubles at each one. Raise it like
:data:`XACRO_TIME_LIMIT`."""

_XACRO_LOCK = threading.RLock()  # xacro keeps its state in module globals: one expansion at once
_xacro_active = threading.local()  # .budget: the caps of this thread's expansion, if any
_xacro_originals: dict[str, Any] = {}  # xacro's own functions, while the hooks replace them
_ABSENT = object()
_SPECIAL_FILES = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISCHR, "a device"),
    (stat.S_ISBLK, "a device"),
    (stat.S_ISSOCK, "a socket"),
)


def _is_xacro_path(source: Any) -> bool:
    if isinstance(source, str) and _looks_like_xml(source):
        return False
    return isinstance(source, (str, os.PathLike)) and str(source).endswith(".xacro")


def _check_trust(trust: Any) -> None:
    if not isinstance(trust, bool):
        raise ModelError(
            f"trust must be True or False, got {trust!r}; trust=True lets load_urdf run the "
            "code of a xacro file."
        )


class _XacroStop(Exception):
    """Raised inside xacro by the hooks. Not an ``OSError``, so that an optional include cannot
    skip it; the refusal itself is kept in the budget, whatever xacro wraps this in."""


class _XacroBudget:
    """The caps of one expansion, checked by the hooks (see :func:`_xacro_caps`)."""

    def __init__(self, label: str, max_bytes: int) -> None:
        self.label, self.max_bytes = label, max_bytes
        self.limit, self.max_elements = XACRO_TIME_LIMIT, XACRO_MAX_ELEMENTS
        self.deadline = time.monotonic() + self.limit
        self.elements = 0
        self.refusal: URDFError | None = None

    def refuse(self, problem: str, fix: str, value: str | None = None) -> None:
        """Record the first refusal and stop xacro."""
        if self.refusal is None:
            self.refusal = URDFError(problem, file=self.label, value=value, fix=fix)
        raise _XacroStop(problem)

    def check(self, elements: int = 0) -> None:
        """Stop xacro if it is over the time or element cap (or was stopped before)."""
        if self.refusal is not None:
            raise _XacroStop(self.refusal.problem)
        self.elements += elements
        if self.elements > self.max_elements:
            self.refuse(
                f"expanding it makes over {self.max_elements} elements "
                "(jaxkin.urdf.XACRO_MAX_ELEMENTS): is a macro calling itself more than once?",
                self._fix("XACRO_MAX_ELEMENTS"),
            )
        if time.monotonic() > self.deadline:
            self.refuse(
                f"expanding it takes over {self.limit:g} s (jaxkin.urdf.XACRO_TIME_LIMIT): is a "
                "macro calling itself more than once?",
                self._fix("XACRO_TIME_LIMIT"),
            )

    def check_file(self, file: Any, status: os.stat_result) -> None:
        """Refuse what xacro is about to read unless it is a regular file of ``max_bytes``."""
        name = os.fspath(file)
        if not stat.S_ISREG(status.st_mode):
            kind = next((k for test, k in _SPECIAL_FILES if test(status.st_mode)), "special")
            self.refuse(
                f"xacro would read {name!r}, which is {kind}, not a regular file (reading it "
                "could block or never end).",
                "include only regular files (.xacro, .urdf, .yaml).",
                value=name,
            )
        if status.st_size > self.max_bytes:
            self.refuse(
                f"xacro would read {name!r}: {status.st_size} bytes, over the "
                f"{self.max_bytes}-byte limit (max_bytes).",
                "raise the cap with jk.load_urdf(..., max_bytes=N) if the file is legitimate.",
                value=name,
            )

    def check_text(self, result: Any) -> None:
        """Refuse an expression whose value is longer than the whole URDF may be."""
        if isinstance(result, str) and len(result) > self.max_bytes:
            self.refuse(
                f"an expression gives a text of {len(result)} characters, over the "
                f"{self.max_bytes}-byte limit (max_bytes) of the expanded URDF.",
                "raise the cap with jk.load_urdf(..., max_bytes=N) if the file is legitimate.",
            )

    def _fix(self, cap: str) -> str:
        return (
            f"if the file is right, expand it with the xacro command (`xacro {self.label} > "
            f"robot.urdf`) and load robot.urdf, or raise jaxkin.urdf.{cap}."
        )


def _xacro_budget() -> _XacroBudget | None:
    return getattr(_xacro_active, "budget", None)


def _xacro_eval_all(*args: Any, **kwargs: Any) -> Any:
    """xacro's ``eval_all`` (one element and, recursively, its children), counted and timed."""
    budget = _xacro_budget()
    if budget is not None:
        budget.check(elements=1)
    return _xacro_originals["eval_all"](*args, **kwargs)


def _xacro_eval_text(*args: Any, **kwargs: Any) -> Any:
    """xacro's ``eval_text`` (an attribute or text with ``${...}``), timed, its value capped."""
    budget = _xacro_budget()
    if budget is not None:
        budget.check()
    result = _xacro_originals["eval_text"](*args, **kwargs)
    if budget is not None:
        budget.check_text(result)
    return result


def _xacro_open(file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
    """The ``open`` of xacro's module (its files, includes, YAML): only regular files of at most
    ``max_bytes``, checked on the open descriptor (opened non-blocking, so that a FIFO does not
    block, and checked after opening, so that one swapped in after a check is refused too)."""
    original = _xacro_originals["open"]
    budget = _xacro_budget()
    if budget is None or not isinstance(file, (str, os.PathLike)) or set(mode) & set("wax+"):
        return original(file, mode, *args, **kwargs)
    budget.check()
    nonblocking = getattr(os, "O_NONBLOCK", 0)
    fd = os.open(file, os.O_RDONLY | nonblocking | getattr(os, "O_NOCTTY", 0))
    try:
        budget.check_file(file, os.fstat(fd))
        if nonblocking:
            os.set_blocking(fd, True)
        return original(fd, mode, *args, **kwargs)
    except BaseException:
        os.close(fd)
        raise


_XACRO_HOOKS = {"eval_all": _xacro_eval_all, "eval_text": _xacro_eval_text, "open": _xacro_open}


@contextmanager
def _xacro_caps(xacro: Any, budget: _XacroBudget) -> Iterator[None]:
    """Apply ``budget`` to what xacro does in this thread during the ``with`` block.

    xacro is pure Python and calls its own ``eval_all``, ``eval_text`` and ``open`` through its
    module's globals: the hooks replace them there (other threads' calls pass straight through)
    and xacro's own are put back afterwards, on error too. One expansion runs at a time (a lock),
    since xacro keeps its state in module globals anyway."""
    with _XACRO_LOCK:
        outer = _xacro_budget()  # a load_urdf from within a trusted expansion: hooks in place
        saved = {} if outer is not None else {k: vars(xacro).get(k, _ABSENT) for k in _XACRO_HOOKS}
        for name, value in saved.items():
            _xacro_originals[name] = open if value is _ABSENT else value
            setattr(xacro, name, _XACRO_HOOKS[name])
        _xacro_active.budget = budget
        try:
            yield
        finally:
            _xacro_active.budget = outer
            for name, value in saved.items():
                if value is _ABSENT:
                    delattr(xacro, name)
                else:
                    setattr(xacro, name, value)


def _parse_xacro(source: Any, args: Mapping[str, Any], max_bytes: int, trust: bool) -> URDFModel:
    """Expand the xacro file ``source`` with the ``xacro`` package (only if ``trust``), within
    the caps, then parse the result."""
    if not isinstance(source, (str, os.PathLike)) or (
        isinstance(source, str) and _looks_like_xml(source)
    ):
        raise ModelError("xacro_args needs the path of a .xacro file as source.")
    label = str(source)
    if not trust:
        raise URDFError(
            "this is a xacro file, that is a program: xacro evaluates its ${...} expressions as "
            "Python code, which no sandbox confines (a file can run any code on this machine), "
            "so jaxkin expands one only when told to.",
            file=label,
            fix=f"jk.load_urdf({label!r}, trust=True), only for files you trust; or expand it "
            f"yourself with the xacro command (`xacro {label} > robot.urdf`, which runs it too) "
            "and load the URDF.",
        )
    _check_max_bytes(max_bytes)
    try:
        import xacro
    except ImportError as exc:
        raise URDFError(
            f"expanding a xacro file needs the xacro package ({exc}).",
            file=label,
            fix=f"{_XACRO_EXTRA}, or expand it first: `xacro {label} > robot.urdf`.",
        ) from None
    try:
        os.stat(source)
    except OSError as e:
        hint = "no such file" if isinstance(e, FileNotFoundError) else e.strerror or str(e)
        raise URDFError(f"cannot read the xacro file: {hint}.", file=label) from None
    mappings = {str(k): str(v) for k, v in args.items()}
    budget = _XacroBudget(label, max_bytes)
    try:
        with _xacro_caps(xacro, budget):
            document = xacro.process_file(str(source), mappings=mappings)
        text = document.toxml()
    except Exception as e:  # xacro raises many kinds (XacroException, NameError, OSError)
        if budget.refusal is not None:  # a cap, maybe wrapped by xacro
            raise budget.refusal from None
        raise URDFError(
            f"xacro could not expand the file: {type(e).__name__}: {' '.join(str(e).split())}",
            file=label,
            fix="fix the file or its arguments (xacro_args={'name': 'value'} for "
            "<xacro:arg name=...>); `xacro FILE name:=value` shows the same error.",
        ) from None
    if budget.refusal is not None:  # xacro caught the stop and went on
        raise budget.refusal
    try:
        model = parse_urdf(text.encode("utf-8"), max_bytes=max_bytes)
    except URDFError as e:
        raise URDFError(
            f"{e.problem} (in the URDF that xacro expanded)",
            file=label,
            line=e.line,
            element=e.element,
            attribute=e.attribute,
            value=e.value,
            fix=e.fix,
        ) from None
    return URDFModel(model.name, label, model.links, model.joints, model.root)


def _check_max_bytes(max_bytes: Any) -> None:
    if not isinstance(max_bytes, int) or isinstance(max_bytes, bool) or max_bytes <= 0:
        raise ModelError(f"max_bytes must be a positive integer, got {max_bytes!r}.")


def _joint_spec(j: URDFJoint, inertial: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The :func:`jaxkin.build.from_joints` spec of a URDF joint (continuous -> revolute,
    floating -> free), with the ``inertial`` of its child link when it has one."""
    kinds = {"fixed": "fixed", "prismatic": "prismatic", "floating": "free", "planar": "planar"}
    spec: dict[str, Any] = {
        "name": j.name,
        "type": kinds.get(j.type, "revolute"),
        "parent": j.parent,
        "child": j.child,
        "xyz": j.xyz,
        "rpy": j.rpy,
    }
    if inertial is not None:
        spec["inertial"] = inertial
    if j.type not in MULTI_DOF_TYPES:
        spec["axis"] = j.axis
    if j.type in MOVING_TYPES:
        spec["lower"], spec["upper"] = j.lower, j.upper
        if j.mimic is not None:
            spec["mimic"] = {
                "joint": j.mimic.joint,
                "multiplier": j.mimic.multiplier,
                "offset": j.mimic.offset,
            }
    return spec
