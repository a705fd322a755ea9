"""The URDFs of ``example-robot-data`` as jaxkin robots (optional; never a runtime dependency).

``example-robot-data`` (``pip install example-robot-data``; Pinocchio's collection of about 70
robot descriptions) ships its files under ``cmeel.prefix/share/example-robot-data/robots`` in
site-packages and, from version 5, no Python loader. This module finds them through the
installed distribution's file list (nothing is imported or executed) and loads them with
:func:`jaxkin.load_urdf`.

Names
-----
Every ``.urdf`` file is one robot named ``"erd/<stem>"``, ``<stem>`` being the file name without
``.urdf``: ``"erd/panda"``, ``"erd/ur5_robot"``, ``"erd/kinova"``, ``"erd/talos_reduced"``. The
``erd/`` prefix keeps them apart from the zoo's hand-written models (``"panda"`` and ``"ur5"``
are the zoo's DH models): nothing is shadowed. When two files share a stem, each is named
``"erd/<package>/<stem>"``, ``<package>`` being its description folder without
``_description`` (``"erd/anymal_b_simple/anymal"``, ``"erd/anymal_c_simple/anymal"``).

``jk.robots.erd_names()`` lists them (empty when the package is not installed);
``jk.robots.load("erd/panda", dtype=..., tip=..., base=..., floating_base=...)`` loads one
(``floating_base=True``: a free root joint for humanoids and legged robots);
``jk.robots.info("erd/panda").path`` is its file (``.source`` says the same in words, with the
package's version), and ``.tip`` the chain the zoo loads (see below), so that
``jk.load_urdf(info.path, tip=info.tip, name=info.name)`` builds the same robot. Some files
of the collection are not loadable kinematic models, and loading them raises a
:class:`jaxkin.ModelError` that says why and lists the other files of the same package
(``ur3.urdf`` of 6.0 is an empty xacro output, use ``"erd/ur3_robot"``; ``alex_psyonic_hands``
has mimic joints whose leader does not exist). ``quadrotor_base`` and ``iris_simple`` have no
moving joint: they load with dof 0 (``fk``/``fk_all`` work, Jacobians have shape (6, 0)).

Default frames
--------------
``jk.robots.load("erd/...")`` loads the file whole, with :func:`jaxkin.load_urdf`'s default
frame (see "The default frame" in :mod:`jaxkin.urdf`), the same robot as
``jk.load_urdf(path)``: the UR arms (``erd/ur3_robot``, ``erd/ur5_robot``, ``erd/ur10_robot``,
their ``_joint_limited_robot`` variants, ``erd/ur3_gripper``, ``erd/ur5_gripper``) end at
``tool0`` (the ROS-Industrial tool flange, where their fixed frames branch), ``erd/xarm7`` at
``link_eef``. Where that rule cannot give an arm's standard tool frame, because its gripper's
moving joints branch the robot or its tool frame is one of several fixed frames none of which
is ``tool0``, the zoo loads, without ``tip=``, the chain to that frame (:data:`TOOL_FRAMES`),
which is then the default frame of ``fk``, ``geometric_jacobian`` and the rest; gripper joints,
which do not move it, are not entries of ``q``:

* ``erd/panda``, ``erd/panda_collision``: ``panda_hand_tcp`` (the Franka Hand's TCP), or
  ``panda_hand`` in a file without it; 7 dof, the finger joints left out.
* ``erd/kinova``: ``j2s6s200_end_effector`` (Kinova's end-effector frame, 0.16 m past link 6,
  not the fixed finger links that hang beside it); 6 dof.
* ``erd/z1``: ``link06`` (the flange; the gripper joint is left out); 6 dof.
* ``erd/so100``: ``gripper`` (the wrist-roll link that carries the fixed jaw; the moving jaw's
  joint is left out); 5 dof.
* ``erd/so101``: ``gripper_frame_link`` (the file's gripper frame); 5 dof.
* ``erd/talos_left_arm``: ``wrist_left_ft_tool_link`` (the tool side of the wrist force
  sensor, where the gripper mounts; the gripper joint is left out); 6 dof.

example-robot-data 6.0 ships no KUKA iiwa (``tests/data/kuka_iiwa14.urdf`` stands in for it in
the tests; loaded with :func:`jaxkin.load_urdf` it defaults to ``lbr_iiwa_link_7``, its flange).
Every other file gets :func:`jaxkin.load_urdf`'s default: the end of the chain of moving joints,
or, when they branch (humanoids, legged robots, mobile manipulators, hands), no default frame:
functions then need ``frame=`` and say so, listing the candidate end frames. Pass ``tip=`` to
choose another chain; load the whole file, fingers included, with
``jk.load_urdf(jk.robots.example_robot_data.path("erd/panda"))``.

Set ``JAXKIN_EXAMPLE_ROBOT_DATA`` to a ``robots`` folder to use another copy (e.g. a source
checkout).
"""

from __future__ import annotations

import functools
import importlib.metadata
import os
from pathlib import Path
from typing import Any

from ..errors import UnknownRobotError
from ..model import Robot

__all__ = ["PREFIX", "TOOL_FRAMES", "entry", "load", "names", "path", "robots_dir", "tool_frame"]

PREFIX = "erd/"
ENV = "JAXKIN_EXAMPLE_ROBOT_DATA"
_DIST = "example-robot-data"
_MARKER = "example-robot-data/robots/"

TOOL_FRAMES: dict[str, tuple[str, ...]] = {
    "erd/panda": ("panda_hand_tcp", "panda_hand"),
    "erd/panda_collision": ("panda_hand_tcp", "panda_hand"),
    "erd/kinova": ("j2s6s200_end_effector",),
    "erd/z1": ("link06",),
    "erd/so100": ("gripper",),
    "erd/so101": ("gripper_frame_link",),
    "erd/talos_left_arm": ("wrist_left_ft_tool_link",),
}
"""The standard tool frame of each well-known arm whose file's default frame (the rule of
:func:`jaxkin.load_urdf`) is not it: the gripper's moving joints branch the robot (panda, z1,
so100, so101, talos_left_arm), or the tool frame is one of several fixed frames, none named
``tool0`` (kinova). The first of these links that the file has becomes ``tip`` when
:func:`load` is given none (see "Default frames" above)."""


@functools.lru_cache(maxsize=1)
def robots_dir() -> Path | None:
    """The ``robots`` folder of the installed example-robot-data, or None if there is none."""
    env = os.environ.get(ENV)
    if env:
        return Path(env) if Path(env).is_dir() else None
    try:
        dist = importlib.metadata.distribution(_DIST)
    except importlib.metadata.PackageNotFoundError:
        return None
    for f in dist.files or ():
        s = str(f).replace("\\", "/")
        k = s.find(_MARKER)
        if k >= 0 and s.endswith(".urdf"):
            root = Path(str(dist.locate_file(s[: k + len(_MARKER)])))
            return root if root.is_dir() else None
    return None


@functools.lru_cache(maxsize=1)
def _index() -> dict[str, Path]:
    root = robots_dir()
    if root is None:
        return {}
    files = sorted(p for p in root.rglob("*.urdf") if p.is_file())
    stems: dict[str, list[Path]] = {}
    for p in files:
        stems.setdefault(p.stem, []).append(p)
    out: dict[str, Path] = {}
    for stem, paths in stems.items():
        if len(paths) == 1:
            out[PREFIX + stem] = paths[0]
            continue
        for p in paths:
            package = p.relative_to(root).parts[0].removesuffix("_description")
            out[f"{PREFIX}{package}/{stem}"] = p
    return dict(sorted(out.items()))


def names() -> list[str]:
    """Names (``"erd/..."``) of every example-robot-data URDF, sorted; [] if not installed."""
    return list(_index())


def path(name: str) -> Path:
    """The URDF file of ``name``."""
    index = _index()
    if name in index:
        return index[name]
    if not index:
        raise UnknownRobotError(
            f"robot {name!r} needs example-robot-data, which is not installed (or has no URDF "
            f"files). Install it with `pip install example-robot-data`, or set {ENV} to its "
            "robots folder."
        )
    from . import did_you_mean

    raise UnknownRobotError(
        f"unknown example-robot-data robot {name!r}.{did_you_mean(name, list(index))} "
        f"jk.robots.erd_names() lists all {len(index)}."
    )


def tool_frame(name: str, base: str | None = None) -> str | None:
    """The standard tool frame of ``name`` (:data:`TOOL_FRAMES`) that its file has (below
    ``base`` when given), or None."""
    from ..urdf import parse_urdf

    if name not in TOOL_FRAMES:
        return None
    model = parse_urdf(path(name))
    parent = {j.child: j.parent for j in model.joints}
    for link in TOOL_FRAMES[name]:
        if link not in parent and link != model.root:
            continue
        up = link
        while base is not None and up != base and up in parent:
            up = parent[up]
        if base is None or up == base:
            return link
    return None


def load(
    name: str,
    dtype: Any = None,
    tip: str | None = None,
    base: str | None = None,
    floating_base: bool = False,
) -> Robot:
    """Load the example-robot-data robot ``name`` (see :func:`names`) with
    :func:`jaxkin.load_urdf` (``tip``/``base`` select a chain or subtree). Without ``tip``, the
    whole file, with :func:`jaxkin.load_urdf`'s default frame (``erd/ur5_robot``: ``tool0``),
    except the arms of :data:`TOOL_FRAMES`, loaded as the chain to their standard tool frame
    (``erd/panda``: ``panda_hand_tcp``), their default frame. ``floating_base=True`` adds a free
    root joint ``"root_joint"`` (humanoids, quadrupeds: see :func:`jaxkin.load_urdf`), e.g.
    ``jk.robots.load("erd/solo12", floating_base=True)``."""
    from ..urdf import URDFError, load_urdf

    p = path(name)
    if tip is None:
        try:
            tip = tool_frame(name, base)
        except URDFError:
            pass  # an unloadable file: load_urdf below says why
    try:
        return load_urdf(p, tip=tip, base=base, dtype=dtype, name=name, floating_base=floating_base)
    except URDFError as e:
        siblings = [n for n, q in _index().items() if q.parent == p.parent and n != name]
        folder = p.parent.relative_to(robots_dir()) if robots_dir() else p.parent
        more = f" Other example-robot-data robots in {folder}/: {siblings}." if siblings else ""
        raise URDFError(
            e.problem,
            file=e.file,
            line=e.line,
            element=e.element,
            attribute=e.attribute,
            value=e.value,
            fix=((e.fix or "") + more).strip() or None,
        ) from None


def entry(name: str):
    """The :class:`jaxkin.robots.ZooEntry` of an ``"erd/..."`` name: ``path`` its file, ``tip``
    the standard tool frame the zoo loads the chain to (:data:`TOOL_FRAMES`), or None."""
    from ..urdf import URDFError
    from . import ZooEntry

    p = path(name)
    try:
        tip = tool_frame(name)
    except URDFError:  # an unloadable file: loading it says why
        tip = None
    rel = p.relative_to(robots_dir()) if robots_dir() is not None else p
    try:
        version = importlib.metadata.version(_DIST)
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - env override
        version = "unknown version"

    def builder(
        dtype: Any = None,
        tip: str | None = None,
        base: str | None = None,
        floating_base: bool = False,
    ) -> Robot:
        return load(name, dtype=dtype, tip=tip, base=base, floating_base=floating_base)

    return ZooEntry(
        name=name,
        builder=builder,
        description=f"example-robot-data {rel} (URDF, loaded with jk.load_urdf)",
        source=f"{p} (example-robot-data {version})",
        path=p,
        tip=tip,
    )
