"""Forward kinematics: the pose of one frame, of several frames, or of every frame.

All poses are in the world frame (the frame ``robot.base`` is expressed in; the robot's base frame
when ``base`` is None): ``T_world_frame``, shape (4, 4). Each function takes one configuration
``q`` of shape ``(nq,)``; batch with ``jax.vmap``.

Free and ball joints' quaternions (and planar joints' (cos, sin) pairs) are normalised inside the
kernel, as MuJoCo's ``mj_kinematics`` does: any nonzero quaternion is the rotation of its unit
multiple. A zero or non-finite one raises a :class:`~jaxkin.JaxkinError` when called eagerly and
gives NaN under ``jit``/``vmap``.

Only the joints on the paths to the frames asked for are computed, once however many of those
frames they move. A path of many joints whose constants do not fold runs through ``lax.scan``
(:func:`uses_scan`).
"""

from __future__ import annotations

from typing import Any

import jax

from ._checks import check_frames, check_q
from ._forward import all_frame_transforms, frame_transform, frame_transforms, uses_scan
from ._jit import eager
from .model import Robot

__all__ = [
    "fk",
    "fk_all",
    "uses_scan",
]

_fk = eager(frame_transform, ("frame",))
_fk_several = eager(frame_transforms, ("frames",))
_fk_all = eager(all_frame_transforms)


def fk_all(robot: Robot, q: Any) -> jax.Array:
    """Poses ``T_world_frame`` of every frame, shape (n_frames, 4, 4), in ``robot.frame_names``
    order (base first, tool last when present).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q = jnp.array([0.0, jnp.pi / 2])
    >>> Ts = jk.fk_all(robot, q)
    >>> Ts.shape, robot.frame_names
    ((3, 4, 4), ('base', 'link1', 'link2'))
    >>> bool(jnp.allclose(Ts[-1], jk.fk(robot, q)))  # the last frame is the tip
    True
    """
    return _fk_all(robot, check_q(robot, q, fn="jk.fk_all", host=True))


def fk(robot: Robot, q: Any, frame: Any = None) -> jax.Array:
    """Pose ``T_world_frame`` of one frame (default: the tip, tool included), shape (4, 4); of
    several frames, shape (k, 4, 4), when ``frame`` is a list or tuple of names and indices.

    Several frames come from one forward pass: each joint on their paths is computed once (not
    k calls); the result's row i equals ``fk(robot, q, frame=frames[i])``. Duplicates are
    allowed; an empty list raises a :class:`~jaxkin.JaxkinError`.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")  # two unit links in the xy plane
    >>> T = jk.fk(robot, jnp.array([0.0, jnp.pi / 2]))
    >>> T.shape
    (4, 4)
    >>> T[:2, 3].round(6).tolist()  # the tip: link 1 along x, then link 2 along y
    [1.0, 1.0]
    >>> Ts = jk.fk(robot, jnp.array([0.0, jnp.pi / 2]), frame=["link1", "link2"])
    >>> Ts.shape, Ts[:, :2, 3].round(6).tolist()
    ((2, 4, 4), [[1.0, 0.0], [1.0, 1.0]])
    """
    q = check_q(robot, q, fn="jk.fk", host=True)
    frames = check_frames(robot, frame, "jk.fk")
    if frames is None:
        return _fk(robot, q, robot.frame_index(frame))
    return _fk_several(robot, q, frames)
