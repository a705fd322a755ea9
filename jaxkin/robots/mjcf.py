"""MJCF arm and hand models shipped inside installed PyPI packages, loaded with
:func:`jaxkin.load_mjcf` (optional; needs the ``mjcf`` extra and the package holding the file).

The files are found through each distribution's file list (nothing of the package is imported or
executed, nothing is downloaded) and compiled by MuJoCo without their mesh files.

MJCF model names
----------------
``jk.robots.mjcf_names()`` lists the models whose package is installed;
``jk.robots.load("mjcf/jaco_arm", dtype=..., tip=..., base=...)`` loads one;
``jk.robots.info("mjcf/jaco_arm").path`` is its file (``.source`` says the same in words, with
the package's version), and ``.tip``/``.base`` the part loaded, so that
``jk.load_mjcf(info.path, tip=info.tip, base=info.base, name=info.name)`` builds the same robot.
Each model is loaded as the part of the file that is the robot (``base``: scene objects with
free joints, tables and targets are left out) and, for the arms whose standard tool frame is
not already :func:`jaxkin.load_mjcf`'s default frame, as the chain to it (``tip``), which is
then the default frame; pass ``tip=``/``base=`` to choose another part.

=======================  ======================  =============================================
name                     package                 file; part loaded
=======================  ======================  =============================================
``mjcf/jaco_arm``        ``dm-control``          ``third_party/kinova/jaco_arm.xml``: Kinova
                                                 Jaco, 6 dof, default frame ``wristsite`` (the
                                                 flange)
``mjcf/jaco_hand``       ``dm-control``          ``third_party/kinova/jaco_hand.xml``: its
                                                 3-finger hand (branches: no default frame)
``mjcf/manipulator``     ``dm-control``          ``suite/manipulator.xml``: planar arm, 4 dof,
                                                 tip ``grasp`` (the fingers' coupling is a
                                                 tendon equality: left out)
``mjcf/reacher``         ``dm-control``          ``suite/reacher.xml``: 2-link planar arm
``mjcf/fetch``           ``gymnasium-robotics``  ``envs/assets/fetch/reach.xml``: Fetch, base
                                                 slides, torso lift and 7-dof arm (11 dof), tip
                                                 ``robot0:grip``
``mjcf/shadow_hand``     ``gymnasium-robotics``  ``envs/assets/hand/reach.xml``: Shadow Dexterous
                                                 Hand, 24 dof from ``robot0:hand mount``
``mjcf/adroit_hand``     ``gymnasium-robotics``  ``envs/assets/adroit_hand/adroit_pen.xml``:
                                                 Adroit (Shadow) hand, 24 dof from ``forearm``
``mjcf/franka_kitchen``  ``gymnasium-robotics``  ``envs/assets/kitchen_franka/kitchen_assets/
                                                 kitchen_env_model.xml``: Franka Panda, 7 dof,
                                                 base ``panda0_link0``, tip ``end_effector``
=======================  ======================  =============================================
"""

from __future__ import annotations

import functools
import importlib.metadata
from pathlib import Path
from typing import Any, NamedTuple

from ..errors import UnknownRobotError
from ..model import Robot

__all__ = ["MODELS", "PREFIX", "entry", "load", "names", "path"]

PREFIX = "mjcf/"


class Model(NamedTuple):
    """Where an MJCF model lives and which part of it is the robot."""

    dist: str
    file: str  # path inside the distribution
    description: str
    tip: str | None = None
    base: str | None = None


_DMC, _GR = "dm-control", "gymnasium-robotics"
_GRA = "gymnasium_robotics/envs/assets/"
MODELS: dict[str, Model] = {
    "mjcf/jaco_arm": Model(
        _DMC,
        "dm_control/third_party/kinova/jaco_arm.xml",
        "Kinova Jaco arm (dm_control), 6 dof, to its flange site",  # the default frame
    ),
    "mjcf/jaco_hand": Model(
        _DMC, "dm_control/third_party/kinova/jaco_hand.xml", "Kinova Jaco 3-finger hand"
    ),
    "mjcf/manipulator": Model(
        _DMC, "dm_control/suite/manipulator.xml", "dm_control planar manipulator arm", tip="grasp"
    ),
    "mjcf/reacher": Model(_DMC, "dm_control/suite/reacher.xml", "dm_control 2-link reacher"),
    "mjcf/fetch": Model(
        _GR,
        _GRA + "fetch/reach.xml",
        "Fetch mobile manipulator (Gymnasium-Robotics), 11 dof, to its grip site",
        tip="robot0:grip",
    ),
    "mjcf/shadow_hand": Model(
        _GR,
        _GRA + "hand/reach.xml",
        "Shadow Dexterous Hand (Gymnasium-Robotics), 24 dof",
        base="robot0:hand mount",
    ),
    "mjcf/adroit_hand": Model(
        _GR,
        _GRA + "adroit_hand/adroit_pen.xml",
        "Adroit hand (Gymnasium-Robotics), 24 dof",
        base="forearm",
    ),
    "mjcf/franka_kitchen": Model(
        _GR,
        _GRA + "kitchen_franka/kitchen_assets/kitchen_env_model.xml",
        "Franka Panda of the Franka Kitchen (Gymnasium-Robotics), 7 dof",
        tip="end_effector",
        base="panda0_link0",
    ),
}
"""Every MJCF model jaxkin knows, by name."""


@functools.cache
def _locate(dist: str, file: str) -> Path | None:
    try:
        d = importlib.metadata.distribution(dist)
    except importlib.metadata.PackageNotFoundError:
        return None
    for f in d.files or ():
        if str(f).replace("\\", "/") == file:
            p = Path(str(d.locate_file(f)))
            return p if p.is_file() else None
    return None


def names() -> list[str]:
    """Names (``"mjcf/..."``) of the models whose package is installed, sorted."""
    return sorted(n for n, m in MODELS.items() if _locate(m.dist, m.file) is not None)


def path(name: str) -> Path:
    """The MJCF file of ``name``."""
    if name not in MODELS:
        from . import did_you_mean

        raise UnknownRobotError(
            f"unknown MJCF robot {name!r}.{did_you_mean(name, list(MODELS))} jaxkin knows "
            f"{sorted(MODELS)}; "
            "jk.robots.mjcf_names() lists those installed. Load any MJCF file with "
            "jk.load_mjcf(path)."
        )
    m = MODELS[name]
    p = _locate(m.dist, m.file)
    if p is None:
        raise UnknownRobotError(
            f"robot {name!r} is a file of the {m.dist!r} package, which is not installed (or "
            f"lacks {m.file}). Install it with `pip install {m.dist}`."
        )
    return p


def load(name: str, dtype: Any = None, tip: str | None = None, base: str | None = None) -> Robot:
    """Load the MJCF model ``name`` with :func:`jaxkin.load_mjcf`; ``tip``/``base`` default to
    the model's robot part and standard tool frame (see the module doc)."""
    from ..mjcf import load_mjcf

    p = path(name)
    m = MODELS[name]
    tip = m.tip if tip is None else tip
    base = m.base if base is None else base
    return load_mjcf(p, tip=tip, base=base, dtype=dtype, name=name)


def entry(name: str):
    """The :class:`jaxkin.robots.ZooEntry` of an ``"mjcf/..."`` name."""
    from . import ZooEntry

    p = path(name)
    m = MODELS[name]
    try:
        version = importlib.metadata.version(m.dist)
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - removed meanwhile
        version = "unknown version"

    def builder(dtype: Any = None, tip: str | None = None, base: str | None = None) -> Robot:
        return load(name, dtype=dtype, tip=tip, base=base)

    return ZooEntry(
        name=name,
        builder=builder,
        description=f"{m.description}: {m.dist} {m.file} (MJCF, loaded with jk.load_mjcf)",
        source=f"{p} ({m.dist} {version})",
        path=p,
        tip=m.tip,
        base=m.base,
    )
