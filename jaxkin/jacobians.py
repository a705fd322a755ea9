"""Jacobians: the hand-built geometric Jacobian (Table 4.1) and the autodiff ones.

Rows are always ``[v; omega]`` (linear first); columns follow the velocity ``v``
(``robot.velocity_names``: the entries of ``q``, ``robot.joint_names``, unless the robot has free,
ball or planar joints, whose columns are those of their velocity coordinates: see
:mod:`jaxkin.configuration`). Every Jacobian has ``robot.nv`` columns.
``reference`` says which point's velocity the linear rows give and in which basis:

==================  =====================================  ======================================
reference           point                                  basis
==================  =====================================  ======================================
``world_aligned``   the frame origin (or ``point``)        world axes (Pinocchio
                                                           LOCAL_WORLD_ALIGNED, RTB ``jacob0``)
``local``           the frame origin (or ``point``)        the frame's own axes (Pinocchio LOCAL,
                                                           RTB ``jacobe``)
``world``           the point coinciding with the world    world axes (Pinocchio WORLD; spatial
                    origin                                 velocity)
==================  =====================================  ======================================

Identities: ``J_local = blkdiag(R^T, R^T) J_world_aligned`` and ``J_world = Ad(T) J_local``,
whose linear rows are ``J_v + skew(p) J_w``.

Several references at once: ``reference`` a tuple (or list) of names, e.g.
``("local", "world", "world_aligned")`` (Pinocchio's LOCAL, WORLD, LOCAL_WORLD_ALIGNED), gives a
tuple of Jacobians in that order (duplicates allowed, not empty), each equal bit for bit to the
call with that reference alone. The Jacobians of this module take it (:func:`geometric_jacobian`,
:func:`frame_jacobian`, :func:`jacobian_fwd`, :func:`jacobian_rev`; ``jk.jacobian_dot`` and
``jk.twist`` take one reference); ``jacobian_fwd``/``jacobian_rev`` then differentiate forward
kinematics once for all of them.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

from . import spatial
from ._checks import (
    REFERENCES,
    check_frames,
    check_point,
    check_points,
    check_q,
    check_reference,
    result_dtype,
)
from ._jacobian_pass import analytical_jacobian_pass, autodiff_jacobian, geometric_pass
from ._jit import eager
from .errors import JaxkinError, ShapeError
from .model import Robot
from .representations import check_representation, guard_singular

__all__ = [
    "REFERENCES",
    "analytical_jacobian",
    "change_reference",
    "frame_jacobian",
    "geometric_jacobian",
    "jacobian_fwd",
    "jacobian_rev",
]


def _passes(robot: Robot, q: jax.Array, frame, point, reference) -> list:
    refs = reference if isinstance(reference, tuple) else (reference,)
    return [geometric_pass(robot, q, frame, point, ref) for ref in refs]


def _matrix(robot: Robot, q: jax.Array, frame, point, reference):
    """The geometric Jacobian in ``reference``, or a tuple of them for a tuple of references."""
    Js = tuple(g.matrix() for g in _passes(robot, q, frame, point, reference))
    return Js if isinstance(reference, tuple) else Js[0]


def _matrix_and_pose(robot: Robot, q: jax.Array, frame, point, reference):
    """``(J, T)``; ``J`` a tuple (one per reference) when ``reference`` is a tuple."""
    passes = _passes(robot, q, frame, point, reference)
    Js = tuple(g.matrix() for g in passes)
    return (Js if isinstance(reference, tuple) else Js[0]), passes[0].pose()


_geometric = eager(_matrix, ("frame", "reference"))
_geometric_and_pose = eager(_matrix_and_pose, ("frame", "reference"))
_autodiff = eager(autodiff_jacobian, ("frame", "reference", "mode"))
_analytical = eager(analytical_jacobian_pass, ("frame", "representation", "method"))


def geometric_jacobian(
    robot: Robot,
    q: Any,
    frame: Any = None,
    point: Any = None,
    reference: str | tuple[str, ...] = "world_aligned",
) -> jax.Array | tuple[jax.Array, ...]:
    """Geometric Jacobian ``J(q)`` with ``[v; omega] = J(q) @ qd``; shape (6, nv), or (k, 6, nv)
    for several frames (``frame`` a list or tuple); for a tuple of references, a tuple of them.

    Built column by column from one forward pass (the chapter's Table 4.1): a revolute joint i
    contributes ``[z_i x (p - o_i); z_i]``, a prismatic one ``[z_i; 0]``, a joint not on the path
    to ``frame`` a zero column. A free, ball or planar joint contributes one column per entry of
    its velocity (child-frame axes, :mod:`jaxkin.configuration`), so ``qd`` is a velocity of
    shape (nv,), not a time derivative of ``q``. Elementwise, with the model's constants folded
    when the robot is concrete.

    Several frames come from one forward pass (each joint on their paths computed once, not k
    calls); row i equals the Jacobian of ``frame[i]`` alone.

    Args:
      robot: the robot.
      q: joint values, shape (nq,).
      frame: frame name or index (default: the tip, tool included), or a list or tuple of names
        and indices (duplicates allowed, not empty).
      point: optional offset (3,) of the point of interest from the frame origin, in the frame's
        own axes; the linear rows then give that point's velocity. For several frames: (3,) for
        every frame, or (k, 3), row i in frame i's axes.
      reference: ``"world_aligned"`` (default), ``"local"`` or ``"world"``; see the module doc.
        A tuple (or list) of them gives a tuple of Jacobians in that order, each equal to the
        call with that reference alone.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> J = jk.geometric_jacobian(robot, jnp.array([0.0, jnp.pi / 2]))
    >>> J.shape
    (6, 2)
    >>> J[0].round(6).tolist(), J[5].round(6).tolist()  # v_x and omega_z rows
    ([-1.0, -1.0], [1.0, 1.0])
    >>> jk.geometric_jacobian(robot, jnp.zeros(2), frame=["link1", "link2"]).shape
    (2, 6, 2)
    >>> q = jnp.zeros(2)
    >>> J_wa, J_local = jk.geometric_jacobian(robot, q, reference=("world_aligned", "local"))
    >>> bool(jnp.array_equal(J_local, jk.geometric_jacobian(robot, q, reference="local")))
    True
    """
    fn = "jk.geometric_jacobian"
    q, f, pt, ref = _check_frame_call(robot, q, frame, point, reference, fn)
    return _geometric(robot, q, f, pt, ref)


def frame_jacobian(
    robot: Robot,
    q: Any,
    frame: Any = None,
    point: Any = None,
    reference: str | tuple[str, ...] = "world_aligned",
) -> tuple[Any, jax.Array]:
    """``(J, T)``: the geometric Jacobian (6, nv) of :func:`geometric_jacobian` and the frame's
    pose ``T_world_frame`` (4, 4) (its origin, not ``point``), from one forward pass; for several
    frames (``frame`` a list or tuple) ``J`` (k, 6, nv) and ``T`` (k, 4, 4), from one pass too.
    For a tuple of references ``J`` is a tuple of Jacobians, one per reference in that order.

    For solvers and controllers that need both at every step (IK, resolved-rate control,
    calibration); as pytorch_kinematics' ``jacobian(..., ret_eef_pose=True)``.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("puma560")
    >>> J, T = jk.jacobians.frame_jacobian(robot, jnp.zeros(6))
    >>> J.shape, T.shape
    ((6, 6), (4, 4))
    """
    fn = "jk.jacobians.frame_jacobian"
    q, f, pt, ref = _check_frame_call(robot, q, frame, point, reference, fn)
    return _geometric_and_pose(robot, q, f, pt, ref)


def _check_frame_call(robot, q, frame, point, reference, fn, several: bool = True):
    """The checks shared by every Jacobian entry point: ``(q, frame, point, reference)``, the
    frame an index and the point None or (3,), or for several frames (``several``) a tuple of
    indices and the points None or (k, 3); the reference a name, or a tuple of them."""
    reference = _check_references(reference, fn)
    q = check_q(robot, q, fn=fn, host=True)
    dtype = result_dtype(robot, q)
    frames = check_frames(robot, frame, fn)
    if frames is None:
        return q, robot.frame_index(frame), check_point(point, dtype, fn), reference
    if not several:
        raise JaxkinError(
            f"{fn} takes one frame (a name or an index), got {len(frames)}: call it once per frame."
        )
    return q, frames, check_points(point, len(frames), dtype, fn), reference


def _check_references(reference: Any, fn: str) -> str | tuple[str, ...]:
    """One reference name, or a list or tuple of them (not empty) as a tuple; each name checked
    by ``check_reference``."""
    if not isinstance(reference, (list, tuple)):
        return check_reference(reference)
    if not reference:
        raise JaxkinError(
            f"{fn}: reference must be one of {REFERENCES} or a tuple of them, got an empty "
            f"{type(reference).__name__}. Name at least one, e.g. reference=('local', 'world')."
        )
    return tuple(check_reference(ref) for ref in reference)


def change_reference(
    J: jax.Array, T: jax.Array, from_reference: str, to_reference: str
) -> jax.Array:
    """Re-express a (6, dof) Jacobian of the frame with pose ``T`` (4, 4) in another reference.

    ``local = blkdiag(R^T, R^T) world_aligned``; ``world = Ad(T) local``.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q = jnp.array([0.0, jnp.pi / 2])
    >>> J, T = jk.geometric_jacobian(robot, q), jk.fk(robot, q)
    >>> J_local = jk.change_reference(J, T, "world_aligned", "local")
    >>> bool(jnp.allclose(J_local, jk.geometric_jacobian(robot, q, reference="local")))
    True
    """
    check_reference(from_reference)
    check_reference(to_reference)
    J = jnp.asarray(J)
    T = jnp.asarray(T)
    if J.ndim != 2 or J.shape[0] != 6 or T.shape != (4, 4):
        raise ShapeError(
            f"expected J of shape (6, dof) and T of shape (4, 4), got {J.shape}, {T.shape}."
        )
    R = T[:3, :3]
    if from_reference == "world_aligned":
        local = jnp.concatenate([R.T @ J[:3], R.T @ J[3:]], axis=0)
    elif from_reference == "local":
        local = J
    else:
        local = jnp.linalg.solve(spatial.adjoint(T), J)
    if to_reference == "local":
        return local
    if to_reference == "world_aligned":
        return jnp.concatenate([R @ local[:3], R @ local[3:]], axis=0)
    return spatial.adjoint(T) @ local


def _autodiff_jacobian(robot, q, frame, point, reference, mode, fn):
    q, f, pt, ref = _check_frame_call(robot, q, frame, point, reference, fn)
    return _autodiff(robot, q, f, pt, ref, mode)


def jacobian_fwd(
    robot, q, frame=None, point=None, reference="world_aligned"
) -> jax.Array | tuple[jax.Array, ...]:
    """The geometric Jacobian from ``jax.jacfwd`` of forward kinematics; shape (6, nv), or
    (k, 6, nv) for several frames (``frame`` and ``point`` as in :func:`geometric_jacobian`:
    one forward pass, differentiated once).

    ``reference`` a tuple (or list) of references gives a tuple of Jacobians in that order from
    one differentiation (each equal bit for bit to the call with that reference alone): cheaper
    to trace and compile than one call per reference.

    Linear rows are d(point)/dq; angular rows are ``vee(dR/dq_k R^T)``. Independent of the
    hand-built Table 4.1 assembly, so the two check each other. For a robot with free, ball or
    planar joints the derivative is taken with respect to ``v`` of
    ``fk(jaxkin.integrate(robot, q, v))`` at ``v = 0`` (:mod:`jaxkin.configuration`).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("puma560")
    >>> q = jnp.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    >>> bool(jnp.allclose(jk.jacobian_fwd(robot, q), jk.geometric_jacobian(robot, q)))
    True
    >>> J_local, J_world = jk.jacobian_fwd(robot, q, reference=("local", "world"))
    >>> J_local.shape, J_world.shape
    ((6, 6), (6, 6))
    """
    return _autodiff_jacobian(robot, q, frame, point, reference, "fwd", "jk.jacobian_fwd")


def jacobian_rev(
    robot, q, frame=None, point=None, reference="world_aligned"
) -> jax.Array | tuple[jax.Array, ...]:
    """As :func:`jacobian_fwd` but with ``jax.jacrev`` (reverse mode); shape (6, nv) (or
    (k, 6, nv) for several frames; a tuple of them for a tuple of references, from one
    differentiation).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("puma560")
    >>> q = jnp.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    >>> bool(jnp.allclose(jk.jacobian_rev(robot, q), jk.geometric_jacobian(robot, q)))
    True
    """
    return _autodiff_jacobian(robot, q, frame, point, reference, "rev", "jk.jacobian_rev")


def analytical_jacobian(
    robot: Robot,
    q: Any,
    representation: str = "rpy",
    frame: int | str | None = None,
    point: Any = None,
    *,
    method: str = "chain",
    singular_tol: float | None = None,
    return_margin: bool = False,
):
    """Analytical Jacobian ``d[p; phi]/dq``; shape (6, nv).

    ``p`` is the frame origin (or ``point``, an offset in the frame's axes) in world coordinates,
    ``phi`` the frame's orientation in world coordinates in ``representation`` (``"rpy"``, the
    chapter's; ``"zyz"``; ``"rotvec"``). Rows ``[dp; dphi]``, columns follow ``q`` (for a robot
    with free, ball or planar joints: the velocity ``v``, the derivative being taken along
    ``jaxkin.integrate(robot, q, v)`` at ``v = 0``). It equals
    ``blkdiag(I, B(phi)^-1) @ geometric_jacobian(...)`` (see
    :func:`jaxkin.representations.analytical_from_geometric`).

    ``method``:

    * ``"chain"`` (default, fast): ``dp/dq`` is the hand-built linear block and
      ``dphi/dq_k = (dphi/dR) : (skew(J_w[:, k]) R)``, where ``dphi/dR`` is ``jax.jacfwd`` of the
      representation map and ``dR/dq_k = skew(J_w[:, k]) R`` is exact (one forward pass);
    * ``"jacfwd"``: ``jax.jacfwd`` of the whole map ``q -> [p; phi(R(q))]`` through forward
      kinematics (about 3 - 4x slower; independent of the hand-built Jacobian, which the tests
      use to check one against the other).

    Representation singularities (rpy pitch = +-pi/2, zyz theta = 0 or pi) make ``J_a`` unbounded.
    With ``margin = representation_margin(phi)`` and ``tol = singular_tol`` (default: the square
    root of the dtype's machine epsilon):

    * called eagerly, ``margin < tol`` raises :class:`~jaxkin.RepresentationSingularityError`;
    * under ``jit``/``vmap`` (where values cannot raise), the Jacobian of such a configuration is
      all NaN, so it can never pass for a number; pass ``return_margin=True`` to get
      ``(J_a, margin)`` instead, unmasked, and filter yourself.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> Ja = jk.analytical_jacobian(robot, jnp.array([0.0, jnp.pi / 2]), "rpy")
    >>> Ja.shape
    (6, 2)
    >>> Ja[5].round(6).tolist()  # d(yaw)/dq: a planar arm's yaw is q1 + q2
    [1.0, 1.0]
    """
    check_representation(representation)
    if method not in ("chain", "jacfwd"):
        raise JaxkinError(f"method must be 'chain' or 'jacfwd', got {method!r}.")
    fn = "jk.analytical_jacobian"
    q, f, pt, _ = _check_frame_call(robot, q, frame, point, "world_aligned", fn, several=False)
    Ja, margin = _analytical(robot, q, f, pt, representation, method)
    if return_margin:
        return Ja, margin
    return guard_singular(
        Ja,
        margin,
        representation,
        singular_tol,
        "the analytical Jacobian",
        "jk.geometric_jacobian",
        robot,
        q,
    )
