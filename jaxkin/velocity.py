"""End-effector velocities and the classification of rigid-body motion.

A twist is ``V = [v; omega]`` (linear first), shape (6,). ``reference`` has the meaning of
:mod:`jaxkin.jacobians` (``world_aligned``: velocity of the frame origin in world axes).
:func:`velocity_results` gives the per-configuration function of everything ``jaxkin
velocities`` reports (Jacobians, twist, representation margin, singular values), for batching.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import (
    check_frames,
    check_path,
    check_point,
    check_points,
    check_q,
    check_reference,
    check_robot,
    check_twist,
    check_v,
    host_side,
    result_dtype,
)
from ._jacobian_pass import geometric_pass, jacobian_pass
from ._jit import eager
from .jacobians import change_reference, jacobian_fwd
from .model import Robot
from .representations import (
    analytical_from_geometric,
    check_representation,
    from_matrix,
    representation_margin,
)

__all__ = [
    "MOTION_KINDS",
    "classify_motion",
    "classify_twist",
    "point_velocity",
    "twist",
    "velocity_results",
]

MOTION_KINDS = ("rest", "pure_translation", "pure_rotation", "general")


def twist(
    robot: Robot,
    q: Any,
    qd: Any,
    frame: Any = None,
    reference: str = "world_aligned",
    point: Any = None,
) -> jax.Array:
    """Twist ``[v; omega] = J(q) @ qd`` of ``frame`` (default: the tip); shape (6,), or (k, 6)
    for several frames (``frame`` and ``point`` as in :func:`~jaxkin.geometric_jacobian`: a list
    or tuple of names and indices, one forward pass).

    ``qd`` has shape (nv,) (a velocity: for free, ball and planar joints the child frame's
    twist in its own axes, see :mod:`jaxkin.configuration`); batch ``q`` and ``qd`` together
    with ``jax.vmap``. Computed column by column from the same forward pass as
    :func:`~jaxkin.geometric_jacobian`, without forming J.

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q, qd = jnp.array([0.0, jnp.pi / 2]), jnp.array([1.0, 0.0])  # joint 1 at 1 rad/s
    >>> V = jk.twist(robot, q, qd)
    >>> V.shape
    (6,)
    >>> V[:2].round(6).tolist(), float(V[5])  # (v_x, v_y) of the tip at (1, 1), omega_z
    ([-1.0, 1.0], 1.0)
    >>> bool(jnp.allclose(V, jk.geometric_jacobian(robot, q) @ qd))
    True
    >>> jk.twist(robot, q, qd, frame=["link1", "link2"]).shape
    (2, 6)
    """
    hint = "jax.vmap(lambda q, qd: jk.twist(robot, q, qd))(qs, qds)"
    q = check_q(robot, q, fn="jk.twist", batch_hint=hint, host=True)
    qd = check_v(robot, qd, what="qd", fn="jk.twist", batch_hint=hint, host=True)
    check_reference(reference)
    dtype = result_dtype(robot, q)
    frames = check_frames(robot, frame, "jk.twist")
    if frames is None:
        f, pt = robot.frame_index(frame), check_point(point, dtype, "jk.twist")
    else:
        f, pt = frames, check_points(point, len(frames), dtype, "jk.twist")
    return _twist(robot, q, f, qd, pt, reference)


def _twist_kernel(robot: Robot, q, frame, qd, point, reference: str) -> jax.Array:
    g = geometric_pass(robot, q, frame, point, reference)
    return g.times(qd.astype(g.dtype))


_twist = eager(_twist_kernel, ("frame", "reference"))


def point_velocity(robot: Robot, q: Any, qd: Any, point: Any, frame: Any = None) -> jax.Array:
    """Velocity (3,) in world axes of a point fixed to ``frame``, given as an offset (3,) from the
    frame origin in the frame's own axes: ``v_point = v + omega x (R @ point)``. For several
    frames (``frame`` a list or tuple) the velocities (k, 3), ``point`` (3,) or (k, 3).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> robot = jk.robots.load("two_link_planar")
    >>> q, qd = jnp.array([0.0, jnp.pi / 2]), jnp.array([1.0, 0.0])
    >>> v = jk.point_velocity(robot, q, qd, point=[0.1, 0.0, 0.0])  # 0.1 past the tip, at (1, 1.1)
    >>> bool(jnp.allclose(v, jnp.array([-1.1, 1.0, 0.0])))
    True
    """
    hint = "jax.vmap(lambda q, qd: jk.point_velocity(robot, q, qd, point))(qs, qds)"
    q = check_q(robot, q, fn="jk.point_velocity", batch_hint=hint)
    qd = check_v(robot, qd, what="qd", fn="jk.point_velocity", batch_hint=hint)
    return twist(robot, q, qd, frame=frame, point=point)[..., :3]


def velocity_results(
    robot: Robot,
    frame: int | str | None = None,
    reference: str = "world_aligned",
    representation: str = "rpy",
    *,
    check: bool = False,
) -> Callable[[Any, Any], dict[str, jax.Array]]:
    """The per-configuration function ``f(q, qd) -> dict`` of ``frame``'s velocity results, all
    from one forward pass: what ``jaxkin velocities`` computes and writes for each row.

    Made for batching (``jax.vmap``, :func:`jaxkin.batch.chunked_map`): ``robot``, ``frame``,
    ``reference`` and ``representation`` are checked here, once; ``q`` (nq,) and ``qd`` (nv,)
    are not checked in ``f``. The entries, for one configuration:

    * ``q`` (nq,), ``qd`` (nv,): the inputs, as given;
    * ``J`` (6, nv): the geometric Jacobian at ``reference`` (rows ``[v; omega]``, as
      :func:`~jaxkin.geometric_jacobian`);
    * ``twist`` (6,): ``J @ qd``, ``[v; omega]``;
    * ``Ja`` (6, nv): the analytical Jacobian ``d[p; phi]/dq``, ``phi`` in ``representation``
      (``blkdiag(I, B(phi)^-1)`` times the world-aligned ``J``, whatever ``reference``), and
      ``margin`` (): its :func:`~jaxkin.representation_margin` (0 at the singularity, where
      ``Ja`` is not finite);
    * ``sigma`` (min(6, nv),): the singular values of ``J``, descending;
    * with ``check=True`` also ``jac_err`` (): ``max |J - jacobian_fwd(...)|``, the largest
      difference from the autodiff Jacobian (:func:`~jaxkin.jacobian_fwd`), an independent
      check (a second, autodiff pass: slower).

    >>> import jax, jax.numpy as jnp, jaxkin as jk
    >>> from jaxkin.velocity import velocity_results
    >>> robot = jk.robots.load("two_link_planar")
    >>> f = jax.jit(velocity_results(robot, check=True))  # compiled once; jax.vmap(f) batches it
    >>> out = f(jnp.array([0.0, jnp.pi / 2]), jnp.array([1.0, 0.0]))
    >>> sorted(out)
    ['J', 'Ja', 'jac_err', 'margin', 'q', 'qd', 'sigma', 'twist']
    >>> out["twist"][:2].round(6).tolist(), bool(out["jac_err"] < 1e-6)
    ([-1.0, 1.0], True)
    >>> jax.vmap(f)(jnp.zeros((5, 2)), jnp.ones((5, 2)))["J"].shape  # a batch of 5
    (5, 6, 2)
    """
    check_robot(robot, "velocity_results")
    check_reference(reference)
    check_representation(representation)
    f = robot.frame_index(frame)

    def results(q: Any, qd: Any) -> dict[str, jax.Array]:
        g = jacobian_pass(robot, q, f, None, "world_aligned")
        J_wa = g.matrix()
        J = J_wa if reference == "world_aligned" else change_reference(
            J_wa, g.pose(), "world_aligned", reference
        )  # fmt: skip
        phi = from_matrix(g.rotation(), representation)
        out = {
            "q": q,
            "qd": qd,
            "twist": g.times(qd) if reference == "world_aligned" else J @ qd,
            "J": J,
            "Ja": analytical_from_geometric(J_wa, phi, representation),
            "margin": representation_margin(phi, representation),
            "sigma": jnp.linalg.svd(J, compute_uv=False),
        }
        if check:
            J_ad = jacobian_fwd(robot, q, frame=f, reference=reference)
            out["jac_err"] = jnp.max(jnp.abs(J - J_ad))
        return out

    return results


def classify_twist(V: Any, tol: float = 1e-9) -> str:
    """Classify an instantaneous rigid-body motion given by its twist ``[v; omega]`` at a point.

    * ``"rest"``: v = 0 and omega = 0;
    * ``"pure_translation"``: omega = 0, v != 0 (every point has the same velocity);
    * ``"pure_rotation"``: omega != 0 and v . omega = 0: some point is momentarily at rest
      (rotation about an instantaneous axis, zero screw pitch);
    * ``"general"``: omega != 0 and v . omega != 0 (a screw motion: no point is at rest).

    ``tol`` is absolute on ``|omega|`` and ``|v|`` and relative on the pitch
    ``|v . omega| / |omega|^2``.
    Host-side: returns a Python string, so it raises :class:`~jaxkin.JaxkinError` under
    ``jit``/``vmap``/``grad``, and for a non-finite ``V`` or ``tol`` (the non-finite policy of
    :mod:`jaxkin.analysis`: a string cannot be NaN).

    >>> import jax.numpy as jnp, jaxkin as jk
    >>> jk.classify_twist(jnp.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    'pure_translation'
    >>> jk.classify_twist(jnp.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0]))
    'pure_rotation'
    >>> jk.classify_twist(jnp.array([0.0, 0.0, 1.0, 0.0, 0.0, 1.0]))  # a screw
    'general'
    """
    fn = "jk.classify_twist"
    V = check_twist(V, fn)
    host_side(fn, V=V, tol=tol)
    V = np.asarray(V, dtype=float)
    v, w = V[:3], V[3:]
    nw, nv = np.linalg.norm(w), np.linalg.norm(v)
    if nw <= tol:
        return "rest" if nv <= tol else "pure_translation"
    pitch_speed = abs(float(v @ w)) / nw  # speed along the screw axis
    return "pure_rotation" if pitch_speed <= tol * max(1.0, nv) else "general"


def classify_motion(Ts: Any, tol: float = 1e-9) -> str:
    """Classify a finite rigid-body motion given as a trajectory of poses (the chapter's 4.2).

    ``Ts`` (N, 4, 4) are the poses ``T_world_body`` at N >= 2 instants.

    * ``"rest"``: all poses equal;
    * ``"pure_translation"``: the orientation never changes (every point of the body follows the
      same path, as the Ferris-wheel cabin of practice question 3c);
    * ``"pure_rotation"``: one body point stays fixed in space throughout (the paths of all points
      are arcs about it, practice question 3a);
    * ``"general"``: neither (rotation and translation together, e.g. a rolling wheel, 3b).

    The fixed point ``c`` solves ``R_k c + p_k = w`` for all k in least squares (unknowns: ``c``
    in body axes, ``w`` in world axes); the motion is a pure rotation when the residual is within
    ``tol * (1 + max |p|)``. Host-side, like :func:`classify_twist`: raises
    :class:`~jaxkin.JaxkinError` under ``jit``/``vmap``/``grad`` and for a non-finite ``Ts`` or
    ``tol``.
    """
    fn = "jk.classify_motion"
    host_side(fn, Ts=Ts, tol=tol)
    Ts = check_path(np.asarray(Ts, dtype=float), "Ts", fn)
    R, p = Ts[:, :3, :3], Ts[:, :3, 3]
    scale = 1.0 + float(np.max(np.abs(p)))
    same_R = np.max(np.abs(R - R[0])) <= tol
    if same_R:
        return "rest" if np.max(np.abs(p - p[0])) <= tol * scale else "pure_translation"
    n = Ts.shape[0]
    A = np.concatenate([R, -np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2).reshape(3 * n, 6)
    b = -p.reshape(3 * n)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    residual = float(np.max(np.abs(A @ sol - b)))
    return "pure_rotation" if residual <= tol * scale else "general"
