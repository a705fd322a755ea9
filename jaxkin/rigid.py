"""Host-side rigid transforms in numpy float64, shared by the builders, parsers and writers
(:mod:`jaxkin.build`, :mod:`jaxkin.mjcf`, :mod:`jaxkin.urdf_export`). Traced code uses
:mod:`jaxkin.spatial`.

>>> import numpy as np
>>> from jaxkin.rigid import axis_rotation, homogeneous, quaternion_matrix
>>> bool(np.allclose(quaternion_matrix([0.0, 0.0, 0.0, 1.0]), axis_rotation([0, 0, 1], np.pi)))
True
>>> homogeneous(None, [1.0, 2.0, 3.0])[:3, 3].tolist()
[1.0, 2.0, 3.0]
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["axis_rotation", "homogeneous", "quaternion_matrix"]


def quaternion_matrix(q: Any) -> np.ndarray:
    """(3, 3) rotation of the quaternion ``(w, x, y, z)`` (scalar first, MuJoCo's order),
    normalised in float64 first (as MuJoCo's compiler does); ``q`` must be nonzero."""
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = q / math.hypot(*(float(v) for v in q))
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def axis_rotation(axis: Any, angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` (rad) about ``axis`` (normalised here), by Rodrigues."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def homogeneous(R: Any = None, p: Any = None) -> np.ndarray:
    """(4, 4) ``[[R, p], [0, 1]]``; ``R`` None means identity, ``p`` None means zero."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T
