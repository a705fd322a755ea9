"""Exceptions and warnings raised by jaxkin.

Every error a user can cause derives from :class:`JaxkinError`, itself a
``ValueError`` so that generic ``except ValueError`` handlers keep working.
Messages say what was expected, what was given, and how to fix it.
"""

from __future__ import annotations

from collections.abc import Sequence


class JaxkinError(ValueError):
    """Base class of all errors raised by jaxkin for bad input."""


class ModelError(JaxkinError):
    """A robot description (DH table, joint list, URDF file) is invalid."""


class ShapeError(JaxkinError):
    """An array argument has the wrong shape or dtype."""


class NoDefaultFrameError(ModelError):
    """A function was asked for the robot's default frame (``frame=None``) but the robot has
    none: its moving joints branch (arm + gripper fingers, a humanoid), so no frame is moved by
    all of them. ``candidates`` holds the end frames of the branches; pass one as ``frame=``, or
    load the chain to one with ``jk.load_urdf(path, tip=...)``."""

    def __init__(self, message: str, robot: str = "", candidates: Sequence[str] = ()) -> None:
        super().__init__(message)
        self.robot, self.candidates = robot, tuple(candidates)

    def __reduce__(self):
        return (type(self), (str(self), self.robot, self.candidates))


class UnknownRobotError(JaxkinError):
    """A robot name is not in the zoo."""


class RepresentationSingularityError(JaxkinError):
    """An orientation representation is singular (e.g. rpy at pitch = +-pi/2)."""


class JaxkinPrecisionWarning(UserWarning):
    """float64 was asked for while ``jax_enable_x64`` is off (float32 is used)."""
