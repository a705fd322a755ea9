"""Write a :class:`~jaxkin.Robot` as URDF, for Pinocchio, MuJoCo, RViz or any URDF reader.

:func:`to_urdf` turns any jaxkin robot (standard or modified DH, URDF-like placements, trees,
mimic joints, base and tool) into a URDF string whose links carry the robot's frame names, so
``fk(robot, q, frame=name)`` and the other library's pose of link ``name`` agree. Each joint's
motion ``B_j Motion(axis_j, m_j q + o_j) A_j`` (see :mod:`jaxkin.model`) is written as:

* a URDF joint with origin ``B_j Motion(axis_j, o_j)`` (the zero offset folded into the origin),
  the joint's axis and limits, whose child is the frame itself when ``A_j`` is the identity;
* otherwise (standard DH) a child link ``<frame>_motion`` and a fixed joint ``<frame>_dh`` with
  origin ``A_j`` from it to the frame;
* joints sharing one entry of ``q`` become URDF ``<mimic>`` joints of the first of them with
  multiplier ``m_j`` (offset 0: offsets live in the origins).

Each frame's mass, centre of mass and inertia (``robot.has_inertia``) is written as its link's
``<inertial>`` (origin ``rpy`` zero: the inertia in the link's axes), for the frames whose
inertial data is not all zero.

A base transform other than the identity adds a root link ``world`` (a fixed joint
``base_placement`` places ``base``); a tool adds the fixed joint ``tool_placement``. Numbers are
written with ``repr`` (shortest round-tripping float64), orientations as URDF rpy
(``R = Rz(yaw) Ry(pitch) Rx(roll)``, which rebuilds ``R`` to rounding even at pitch +-pi/2).

What URDF cannot say raises :class:`~jaxkin.ModelError`: an independent joint scaled by a
multiplier other than +-1, a revolute joint bounded on one side only, (unless
``prismatic_limit`` is given) an unbounded prismatic joint, and a robot, joint or frame name
holding a character XML 1.0 cannot carry (``\\x00``-``\\x1f`` other than tab, line feed and
carriage return, lone surrogates, ``\\ufffe``, ``\\uffff``): no URDF parser, jaxkin's included,
would read the file back. Every other character is escaped (``quoteattr``: ``<``, ``&``,
quotes, and tab/newline as character references, so they survive attribute normalisation).
"""

from __future__ import annotations

import math
import re
from xml.sax.saxutils import quoteattr

import numpy as np

from ._checks import is_traced
from .errors import ModelError
from .model import Robot
from .placements import joint_placements
from .spatial import make_transform_np, matrix_to_rpy_np, rotation_about_axis_np

__all__ = ["to_urdf"]


def _num(x: float) -> str:
    x = float(x)
    return "0" if x == 0.0 else repr(x)


def _origin(T: np.ndarray) -> str:
    xyz = " ".join(_num(v) for v in T[:3, 3])
    rpy = " ".join(_num(v) for v in matrix_to_rpy_np(T[:3, :3]))
    return f"<origin xyz={quoteattr(xyz)} rpy={quoteattr(rpy)}/>"


def _fixed(name: str, parent: str, child: str, T: np.ndarray) -> list[str]:
    return [
        f'  <joint name={quoteattr(name)} type="fixed">',
        f"    <parent link={quoteattr(parent)}/>",
        f"    <child link={quoteattr(child)}/>",
        f"    {_origin(T)}",
        "  </joint>",
    ]


def _fresh(name: str, taken: set[str]) -> str:
    out = name
    while out in taken:
        out += "_"
    taken.add(out)
    return out


def to_urdf(robot: Robot, *, prismatic_limit: float | None = None) -> str:
    """The robot as a URDF document (a ``str``); see the module doc for the mapping.

    Args:
      robot: a robot with concrete (not traced) parameters.
      prismatic_limit: for prismatic joints without limits: write ``[-L, L]`` metres (URDF has no
        unbounded prismatic joint). Default: raise instead.

    Returns:
      URDF XML with one link per frame of ``robot.frame_names`` (plus ``<frame>_motion`` links
      for standard DH and a ``world`` root when ``robot.base`` is not the identity) and one
      revolute/continuous/prismatic joint per entry of ``q`` named ``robot.joint_names``.
      ``jk.load_urdf(to_urdf(robot))`` gives the same pose for every frame name.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> text = jk.to_urdf(robot)
    >>> text.count('type="revolute"')
    2
    >>> back = jk.load_urdf(text)  # the same robot again
    >>> q = jnp.array([0.3, -0.5])
    >>> bool(jnp.allclose(jk.fk(back, q), jk.fk(robot, q)))
    True
    """
    _check_exportable(robot, prismatic_limit)
    w = _Writer(robot, prismatic_limit)
    lines = ['<?xml version="1.0"?>', f"<robot name={quoteattr(robot.name)}>"]
    body: list[str] = []
    base = _f64(robot.base)
    if not np.array_equal(base, np.eye(4)):
        world = _fresh("world", w.links)
        lines.append(f"  <link name={quoteattr(world)}/>")
        body += _fixed(_fresh("base_placement", w.joints), world, w.frames[0], base)
    for j in range(len(robot.kinds)):
        body += w.joint(j)
    if robot.has_tool:
        body += _fixed(
            _fresh("tool_placement", w.joints), w.frames[-2], w.frames[-1], _f64(robot.tool)
        )
    masses = _inertials(robot)
    for n in w.frames + w.extra_links:
        lines += _link(n, masses.get(n))
    lines += body
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def _inertials(robot: Robot) -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
    """``{frame name: (mass, com, inertia)}`` of the frames whose inertial data is not all zero
    (the root frame's too when there is none, so that ``has_inertia`` survives)."""
    if not robot.has_inertia:
        return {}
    mass, com, inertia = (_f64(x) for x in (robot.frame_mass, robot.frame_com, robot.frame_inertia))
    out = {
        name: (float(mass[f]), com[f], inertia[f])
        for f, name in enumerate(robot.frame_names)
        if mass[f] != 0.0 or np.any(com[f] != 0.0) or np.any(inertia[f] != 0.0)
    }
    return out or {robot.frame_names[0]: (float(mass[0]), com[0], inertia[0])}


def _link(name: str, inertial: tuple[float, np.ndarray, np.ndarray] | None) -> list[str]:
    """A ``<link>``, with its ``<inertial>`` (centre of mass and inertia in the link's axes)."""
    if inertial is None:
        return [f"  <link name={quoteattr(name)}/>"]
    mass, com, I = inertial
    xyz = " ".join(_num(v) for v in com)
    moments = " ".join(
        f"{k}={quoteattr(_num(I[a, b]))}"
        for k, (a, b) in zip(
            ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
            ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)),
            strict=True,
        )
    )
    return [
        f"  <link name={quoteattr(name)}>",
        "    <inertial>",
        f'      <origin xyz={quoteattr(xyz)} rpy="0 0 0"/>',
        f"      <mass value={quoteattr(_num(mass))}/>",
        f"      <inertia {moments}/>",
        "    </inertial>",
        "  </link>",
    ]


def _f64(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _check_exportable(robot: Robot, prismatic_limit: float | None) -> None:
    """Refuse what is not a concrete robot, and a prismatic limit that is not positive."""
    if not isinstance(robot, Robot):
        raise ModelError(f"to_urdf expects a jaxkin Robot, got {type(robot).__name__}.")
    if is_traced(robot):
        raise ModelError(
            "to_urdf needs concrete parameters; call it outside jit/vmap/grad (a URDF is text)."
        )
    if robot.multi_dof_joints:
        names = [robot.frame_names[j + 1] for j in robot.multi_dof_joints]
        raise ModelError(
            f"to_urdf writes revolute, prismatic and fixed joints only; robot {robot.name!r} has "
            f"free, ball or planar joints (moving frames {names}). Export the part below them "
            "(load it with base=...)."
        )
    if prismatic_limit is not None and not (math.isfinite(prismatic_limit) and prismatic_limit > 0):
        raise ModelError(f"prismatic_limit must be a positive number, got {prismatic_limit!r}.")
    named = [("robot", robot.name)]
    named += [("joint", n) for n in robot.joint_names] + [("frame", n) for n in robot.frame_names]
    for what, name in named:
        bad = _XML_INVALID.search(name)
        if bad:
            raise ModelError(
                f"to_urdf: {what} name {name!r} holds {bad.group()!r} (U+{ord(bad.group()):04X}), "
                "a character XML 1.0 cannot carry; no URDF reader could load the file. Rename "
                f"the {what} where the robot is built (from_dh/from_joints names, the model "
                "file) without control characters."
            )


# Characters outside XML 1.0's Char production (tab, LF and CR are allowed).
_XML_INVALID = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def _leaders(robot: Robot, mult: np.ndarray) -> dict[int, int]:
    """The independent joint of each q entry: the first joint driving it with multiplier +-1."""
    leader: dict[int, int] = {}
    for j, i in enumerate(robot.q_index):
        if i >= 0 and i not in leader and abs(abs(mult[j]) - 1.0) <= 1e-12:
            leader[i] = j
    for i, name in enumerate(robot.joint_names):
        if i not in leader:
            raise ModelError(
                f"to_urdf: joint {name!r} is driven with multiplier "
                f"{float(mult[robot.q_index.index(i)])!r}; URDF can scale only mimic joints. "
                "Build the robot with multiplier 1 (scale q instead)."
            )
    return leader


class _Writer:
    """One export: the robot's numbers in float64, the link and joint names taken so far (URDF
    keeps link and joint names apart) and the extra links written (``<frame>_motion``)."""

    def __init__(self, robot: Robot, prismatic_limit: float | None) -> None:
        self.robot, self.prismatic_limit = robot, prismatic_limit
        self.pl = joint_placements(robot, xp=np)
        self.axis, self.offset = _f64(robot.axis), _f64(robot.offset)
        self.mult = _f64(robot.multiplier)
        self.lower, self.upper = _f64(robot.lower), _f64(robot.upper)
        self.frames = list(robot.frame_names)
        self.links = set(self.frames)
        self.joints = set(robot.joint_names)
        self.extra_links: list[str] = []
        self.leader = _leaders(robot, self.mult)

    def joint(self, j: int) -> list[str]:
        """The lines of joint ``j``: its URDF joint, and the fixed ``<frame>_dh`` joint after it
        when it has a placement ``A_j``."""
        robot, pl = self.robot, self.pl
        parent, child = self.frames[robot.parents[j]], self.frames[j + 1]
        B = make_transform_np(*(None, None) if pl.B is None else (pl.B[0][j], pl.B[1][j]))
        has_A = pl.A is not None
        motion_link = self._new_link(f"{child}_motion") if has_A else child
        if robot.kinds[j] == "fixed":
            out = _fixed(_fresh(f"{child}_joint", self.joints), parent, motion_link, B)
        else:
            out = self._moving(j, parent, motion_link, B)
        if has_A:
            A = make_transform_np(pl.A[0][j], pl.A[1][j])
            out += _fixed(_fresh(f"{child}_dh", self.joints), motion_link, child, A)
        return out

    def _new_link(self, name: str) -> str:
        name = _fresh(name, self.links)
        self.extra_links.append(name)
        return name

    def _moving(self, j: int, parent: str, motion_link: str, B: np.ndarray) -> list[str]:
        """The URDF joint of moving joint ``j``: the zero offset folded into the origin ``B``, a
        ``<mimic>`` unless it is the leader of its q entry."""
        robot, kind, mult = self.robot, self.robot.kinds[j], self.mult
        child = self.frames[j + 1]
        i = robot.q_index[j]
        a = self.axis[j] / np.linalg.norm(self.axis[j])
        if kind == "revolute":
            B = B @ make_transform_np(rotation_about_axis_np(a, self.offset[j]), None)
        else:
            B = B @ make_transform_np(None, a * self.offset[j])
        lead = self.leader[i]
        if lead == j:
            name, a_out = robot.joint_names[i], a * np.sign(mult[j])
            lo, hi = self.lower[i], self.upper[i]
        else:
            name, a_out = _fresh(f"{child}_joint", self.joints), a
            lo, hi = sorted((mult[j] * self.lower[i], mult[j] * self.upper[i]))
        urdf_type, limit = _limits(kind, lo, hi, name, self.prismatic_limit)
        return [
            f"  <joint name={quoteattr(name)} type={quoteattr(urdf_type)}>",
            f"    <parent link={quoteattr(parent)}/>",
            f"    <child link={quoteattr(motion_link)}/>",
            f"    {_origin(B)}",
            f"    <axis xyz={quoteattr(' '.join(_num(v) for v in a_out))}/>",
            *([f"    {limit}"] if limit else []),
            *(
                []
                if lead == j
                else [
                    f"    <mimic joint={quoteattr(robot.joint_names[i])} "
                    f"multiplier={quoteattr(_num(mult[j] * np.sign(mult[lead])))} "
                    'offset="0"/>'
                ]
            ),
            "  </joint>",
        ]


def _limits(kind, lo, hi, name, prismatic_limit) -> tuple[str, str | None]:
    """URDF joint type and ``<limit>`` element of one moving joint."""
    effort = 'effort="0" velocity="0"'
    finite = math.isfinite(lo), math.isfinite(hi)
    if kind == "revolute":
        if not any(finite):
            return "continuous", None
        if not all(finite):
            raise ModelError(
                f"to_urdf: revolute joint {name!r} is bounded on one side only ({lo}, {hi}); "
                "URDF joints are either continuous or bounded on both sides. Give it both "
                "limits (robot.replace(lower=..., upper=...))."
            )
    elif not all(finite):
        if prismatic_limit is None:
            raise ModelError(
                f"to_urdf: prismatic joint {name!r} has no limit on one side ({lo}, {hi}) and "
                "URDF has no unbounded prismatic joint. Pass prismatic_limit=L to write [-L, L] "
                "metres for missing limits, or give the joint limits."
            )
        lo = lo if math.isfinite(lo) else -prismatic_limit
        hi = hi if math.isfinite(hi) else prismatic_limit
    return kind, f'<limit lower="{_num(lo)}" upper="{_num(hi)}" {effort}/>'
