"""jaxkin: differential kinematics of robot manipulators in JAX.

Forward kinematics, geometric and analytical Jacobians and end-effector twists as pure, jittable,
differentiable functions of one configuration; batch them with ``jax.vmap``.

Conventions: ``T_a_b`` is the pose of b in a; twists and Jacobian rows are ``[v; omega]``;
``reference`` is ``"world_aligned"`` (default), ``"local"`` or ``"world"``; rpy means
``R = Rz(yaw) Ry(pitch) Rx(roll)`` ordered (roll, pitch, yaw).
"""

from . import robots as robots
from . import spatial as spatial
from .errors import JaxkinError as JaxkinError
from .errors import JaxkinPrecisionWarning as JaxkinPrecisionWarning
from .errors import ModelError as ModelError
from .errors import RepresentationSingularityError as RepresentationSingularityError
from .errors import ShapeError as ShapeError
from .errors import UnknownRobotError as UnknownRobotError
from .jacobians import analytical_jacobian as analytical_jacobian
from .jacobians import change_reference as change_reference
from .jacobians import geometric_jacobian as geometric_jacobian
from .jacobians import jacobian_fwd as jacobian_fwd
from .jacobians import jacobian_rev as jacobian_rev
from .kinematics import fk as fk
from .kinematics import fk_all as fk_all
from .model import Robot as Robot
from .representations import analytical_from_geometric as analytical_from_geometric
from .representations import rate_matrix as rate_matrix
from .representations import representation_margin as representation_margin
from .urdf import load_urdf as load_urdf
from .velocity import classify_motion as classify_motion
from .velocity import classify_twist as classify_twist
from .velocity import point_velocity as point_velocity
from .velocity import twist as twist

__version__ = "0.1.0"
