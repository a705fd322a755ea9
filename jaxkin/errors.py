"""Exceptions and warnings raised by jaxkin.

Every error a user can cause derives from :class:`JaxkinError`, itself a
``ValueError`` so that generic ``except ValueError`` handlers keep working.
Messages say what was expected, what was given, and how to fix it.
"""

from __future__ import annotations


class JaxkinError(ValueError):
    """Base class of all errors raised by jaxkin for bad input."""


class ModelError(JaxkinError):
    """A robot description (DH table, joint list, URDF file) is invalid."""


class ShapeError(JaxkinError):
    """An array argument has the wrong shape or dtype."""


class UnknownRobotError(JaxkinError):
    """A robot name is not in the zoo."""


class RepresentationSingularityError(JaxkinError):
    """An orientation representation is singular (e.g. rpy at pitch = +-pi/2)."""


class JaxkinPrecisionWarning(UserWarning):
    """float64 was asked for while ``jax_enable_x64`` is off (float32 is used)."""
