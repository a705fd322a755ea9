"""jaxkin: differential kinematics of robot manipulators in JAX.

Forward kinematics, geometric and analytical Jacobians and end-effector twists as pure, jittable,
differentiable functions of one configuration; batch them with ``jax.vmap``.

Conventions: ``T_a_b`` is the pose of b in a; twists and Jacobian rows are ``[v; omega]``;
``reference`` is ``"world_aligned"`` (default), ``"local"`` or ``"world"``; rpy means
``R = Rz(yaw) Ry(pitch) Rx(roll)`` ordered (roll, pitch, yaw).
"""

from . import analysis as analysis
from . import calibration as calibration
from . import compilation as compilation
from . import configuration as configuration
from . import derivatives as derivatives
from . import ik as ik
from . import inverse_velocity as inverse_velocity
from . import motion as motion
from . import robots as robots
from . import sampling as sampling
from . import spatial as spatial
from . import tasks as tasks
from .analysis import condition_number as condition_number
from .analysis import dependent_columns as dependent_columns
from .analysis import force_ellipsoid as force_ellipsoid
from .analysis import joint_torques as joint_torques
from .analysis import manipulability as manipulability
from .analysis import manipulability_gradient as manipulability_gradient
from .analysis import near_singular as near_singular
from .analysis import singular_values as singular_values
from .analysis import velocity_ellipsoid as velocity_ellipsoid
from .analysis import wrist_centre as wrist_centre
from .analysis import wrist_decoupling as wrist_decoupling
from .calibration import calibrate as calibrate
from .calibration import identifiability as identifiability
from .com import center_of_mass as center_of_mass
from .com import com_jacobian as com_jacobian
from .configuration import difference as difference
from .configuration import integrate as integrate
from .configuration import neutral as neutral
from .configuration import normalize as normalize
from .derivatives import analytical_jacobian_dot as analytical_jacobian_dot
from .derivatives import analytical_jacobian_dot_qd as analytical_jacobian_dot_qd
from .derivatives import jacobian_dot as jacobian_dot
from .derivatives import jacobian_dot_qd as jacobian_dot_qd
from .derivatives import kinematic_hessian as kinematic_hessian
from .errors import JaxkinError as JaxkinError
from .errors import JaxkinPrecisionWarning as JaxkinPrecisionWarning
from .errors import ModelError as ModelError
from .errors import NoDefaultFrameError as NoDefaultFrameError
from .errors import RepresentationSingularityError as RepresentationSingularityError
from .errors import ShapeError as ShapeError
from .errors import UnknownRobotError as UnknownRobotError
from .ik import IKError as IKError
from .ik import IKSolution as IKSolution
from .ik import solve_ik as solve_ik
from .inverse_velocity import adaptive_damping as adaptive_damping
from .inverse_velocity import damped_least_squares as damped_least_squares
from .inverse_velocity import null_space_projector as null_space_projector
from .inverse_velocity import null_space_velocity as null_space_velocity
from .inverse_velocity import pinv_velocity as pinv_velocity
from .inverse_velocity import pose_error as pose_error
from .inverse_velocity import resolved_rate_control as resolved_rate_control
from .jacobians import analytical_jacobian as analytical_jacobian
from .jacobians import change_reference as change_reference
from .jacobians import geometric_jacobian as geometric_jacobian
from .jacobians import jacobian_fwd as jacobian_fwd
from .jacobians import jacobian_rev as jacobian_rev
from .kinematics import fk as fk
from .kinematics import fk_all as fk_all
from .mjcf import load_mjcf as load_mjcf
from .model import Robot as Robot
from .motion import retarget as retarget
from .representations import analytical_from_geometric as analytical_from_geometric
from .representations import rate_matrix as rate_matrix
from .representations import representation_margin as representation_margin
from .sampling import sample_configurations as sample_configurations
from .sampling import sampling_bounds as sampling_bounds
from .tasks import ComTask as ComTask
from .tasks import FollowResult as FollowResult
from .tasks import FrameTask as FrameTask
from .tasks import PostureTask as PostureTask
from .tasks import TaskSolution as TaskSolution
from .tasks import follow_paths as follow_paths
from .tasks import solve_tasks as solve_tasks
from .urdf import load_urdf as load_urdf
from .urdf_export import to_urdf as to_urdf
from .velocity import classify_motion as classify_motion
from .velocity import classify_twist as classify_twist
from .velocity import point_velocity as point_velocity
from .velocity import twist as twist

# What `from jaxkin import *` binds: the names above, never a submodule such as jaxkin.io
# (which would shadow the standard library's io).
__all__ = [
    "ComTask",
    "FollowResult",
    "FrameTask",
    "IKError",
    "IKSolution",
    "JaxkinError",
    "JaxkinPrecisionWarning",
    "ModelError",
    "NoDefaultFrameError",
    "PostureTask",
    "RepresentationSingularityError",
    "Robot",
    "ShapeError",
    "TaskSolution",
    "UnknownRobotError",
    "adaptive_damping",
    "analysis",
    "analytical_from_geometric",
    "analytical_jacobian",
    "analytical_jacobian_dot",
    "analytical_jacobian_dot_qd",
    "calibrate",
    "calibration",
    "center_of_mass",
    "change_reference",
    "classify_motion",
    "classify_twist",
    "com_jacobian",
    "compilation",
    "condition_number",
    "configuration",
    "damped_least_squares",
    "dependent_columns",
    "derivatives",
    "difference",
    "fk",
    "fk_all",
    "follow_paths",
    "force_ellipsoid",
    "geometric_jacobian",
    "identifiability",
    "ik",
    "integrate",
    "inverse_velocity",
    "jacobian_dot",
    "jacobian_dot_qd",
    "jacobian_fwd",
    "jacobian_rev",
    "joint_torques",
    "kinematic_hessian",
    "load_mjcf",
    "load_urdf",
    "manipulability",
    "manipulability_gradient",
    "motion",
    "near_singular",
    "neutral",
    "normalize",
    "null_space_projector",
    "null_space_velocity",
    "pinv_velocity",
    "point_velocity",
    "pose_error",
    "rate_matrix",
    "representation_margin",
    "resolved_rate_control",
    "retarget",
    "robots",
    "sample_configurations",
    "sampling",
    "sampling_bounds",
    "singular_values",
    "solve_ik",
    "solve_tasks",
    "spatial",
    "tasks",
    "to_urdf",
    "twist",
    "velocity_ellipsoid",
    "wrist_centre",
    "wrist_decoupling",
]

__version__ = "0.1.0"
