"""Tools for property-based tests of kinematics: hypothesis strategies and invariant checks.

Requires ``hypothesis`` (``pip install jaxkin[test]``). Strategies:

* robots: :func:`dh_robots` (random standard/modified DH chains of a given size or joint mix,
  ``kinds="RRPRRR"``), :func:`tree_robots` (URDF-style trees), :func:`robots_and_configurations`;
* configurations: :func:`configurations` (within the limits), :func:`near_singular_configurations`
  (where the Jacobian loses rank);
* geometry: :func:`rotations`, :func:`unit_vectors`, :func:`transforms`.

Checks: :func:`assert_jacobian_consistent` (hand-built Jacobian == ``jax.jacfwd`` == ``jax.jacrev``
== finite differences) and the oracle :func:`finite_difference_jacobian`.

Use them in your own tests (float64: ``jax.config.update("jax_enable_x64", True)`` first)::

    import jax.numpy as jnp
    from hypothesis import given
    import jaxkin as jk
    import jaxkin.testing as jkt

    @given(jkt.robots_and_configurations(max_joints=7))
    def test_jacobians_agree(robot_and_q):
        robot, q = robot_and_q
        jkt.assert_jacobian_consistent(robot, q)

    MY_ROBOT = jk.robots.load("niryo_one")  # or jk.load_urdf("my_robot.urdf")

    @given(jkt.near_singular_configurations(MY_ROBOT))
    def test_my_controller_survives_singularities(q):
        qd = my_controller(MY_ROBOT, q)          # your code
        assert jnp.all(jnp.isfinite(qd))

The finite-difference oracle :func:`finite_difference_jacobian` works on SE(3) and needs float64
(``jax.config.update("jax_enable_x64", True)``); do not finite-difference in float32.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import spatial
from ._checks import (
    check_point,
    check_q,
    check_reference,
    refuse_multi_dof,
    result_dtype,
)
from ._forward import forward_pass, frame_pose
from ._jacobian_pass import autodiff_jacobian
from ._jit import block_width, one_shot_compiler_options, padded_to_block
from .jacobians import REFERENCES, geometric_jacobian
from .model import Robot
from .sampling import sampling_bounds

try:
    from hypothesis import strategies as st
except ImportError as exc:  # pragma: no cover - exercised only without the test extra
    raise ImportError(
        "jaxkin.testing needs hypothesis: pip install 'jaxkin[test]' (or pip install hypothesis)."
    ) from exc

__all__ = [
    "assert_jacobian_consistent",
    "configurations",
    "dh_robots",
    "dh_rows",
    "finite_difference_jacobian",
    "near_singular_configurations",
    "robots_and_configurations",
    "rotations",
    "transforms",
    "tree_robots",
    "unit_vectors",
]

_SPECIAL_ANGLES = (0.0, math.pi / 2, -math.pi / 2, math.pi)
# XLA on CPU flushes subnormal floats to zero; keep them out of generated values.
_FINITE = dict(allow_nan=False, allow_subnormal=False)


def _angle(special: bool = True) -> st.SearchStrategy[float]:
    base = st.floats(-math.pi, math.pi, **_FINITE)
    if special:
        return st.one_of(st.sampled_from(_SPECIAL_ANGLES), base)
    return base


def _length(scale: float = 1.0) -> st.SearchStrategy[float]:
    return st.one_of(st.just(0.0), st.floats(-scale, scale, **_FINITE))


def unit_vectors() -> st.SearchStrategy[np.ndarray]:
    """Unit 3-vectors (numpy float64), including the coordinate axes."""
    axes = st.sampled_from([np.eye(3)[i] * s for i in range(3) for s in (1.0, -1.0)])
    gaussian = st.tuples(*[st.floats(-1, 1, **_FINITE)] * 3).map(np.array)
    gaussian = gaussian.filter(lambda v: np.linalg.norm(v) > 1e-3)
    return st.one_of(axes, gaussian.map(lambda v: v / np.linalg.norm(v)))


def rotations() -> st.SearchStrategy[np.ndarray]:
    """Rotation matrices (3, 3), numpy float64: random axis and angle in [0, pi], ends included.

    Built on the host (Rodrigues in numpy: no JAX dispatch per drawn rotation)."""
    angle = st.one_of(st.sampled_from([0.0, math.pi, 1e-9, math.pi - 1e-9]), _angle(False))
    rotation = lambda ax, t: spatial.rotation_about_axis_np(ax, abs(t))  # noqa: E731
    return st.builds(rotation, unit_vectors(), angle)


def transforms(scale: float = 1.0) -> st.SearchStrategy[np.ndarray]:
    """Homogeneous transforms (4, 4), numpy float64."""
    position = st.tuples(*[_length(scale)] * 3).map(np.array)
    return st.builds(spatial.make_transform_np, rotations(), position)


def _check_kinds(kinds: str | None) -> str | None:
    if kinds is not None and (not isinstance(kinds, str) or not kinds or set(kinds) - {"R", "P"}):
        raise ValueError(f"kinds must be a non-empty string of 'R' and 'P', got {kinds!r}.")
    return kinds


def dh_rows(
    min_joints: int = 1,
    max_joints: int = 12,
    prismatic: bool = True,
    kinds: str | None = None,
) -> st.SearchStrategy[list[dict]]:
    """A DH table (list of row dicts) with mixed revolute/prismatic joints and finite limits.

    ``kinds`` (e.g. ``"RRPRRR"``) fixes the number and kind of the joints (R revolute, P
    prismatic) and overrides ``min_joints``, ``max_joints`` and ``prismatic``.
    """
    return _dh_rows(min_joints, max_joints, prismatic, _check_kinds(kinds))


@st.composite
def _dh_rows(draw, min_joints, max_joints, prismatic, kinds):
    if kinds is not None:
        names = ["revolute" if k == "R" else "prismatic" for k in kinds]
    else:
        n = draw(st.integers(min_joints, max_joints))
        names = [
            draw(st.sampled_from(["revolute", "prismatic"])) if prismatic else "revolute"
            for _ in range(n)
        ]
    rows = []
    for kind in names:
        row = dict(
            a=draw(_length()),
            alpha=draw(_angle()),
            d=draw(_length()),
            theta=draw(_angle()),
            joint=kind,
            offset=draw(st.one_of(st.just(0.0), st.floats(-1, 1, **_FINITE))),
        )
        if kind == "revolute":
            row.update(lower=-math.pi, upper=math.pi)
        else:
            row.update(lower=-1.0, upper=1.0)
        rows.append(row)
    return rows


def dh_robots(
    min_joints: int = 1,
    max_joints: int = 12,
    convention: str | None = None,
    prismatic: bool = True,
    dtype: Any = None,
    kinds: str | None = None,
) -> st.SearchStrategy[Robot]:
    """Random DH robots (standard or modified, random base and tool transforms).

    Size: ``min_joints`` to ``max_joints`` joints; joint mix: ``prismatic=False`` for revolute
    joints only, or ``kinds="RRPRRR"`` for exactly that sequence.
    """
    if convention not in (None, "standard", "modified"):
        raise ValueError(f"convention must be None, 'standard' or 'modified', got {convention!r}.")
    rows = dh_rows(min_joints, max_joints, prismatic, kinds)
    return _dh_robots(rows, convention, dtype)


@st.composite
def _dh_robots(draw, rows, convention, dtype):
    rows = draw(rows)
    conv = convention or draw(st.sampled_from(["standard", "modified"]))
    base = draw(st.one_of(st.none(), transforms()))
    tool = draw(st.one_of(st.none(), transforms(0.3)))
    return Robot.from_dh(rows, convention=conv, base=base, tool=tool, dtype=dtype)


@st.composite
def tree_robots(draw, min_joints: int = 1, max_joints: int = 10, dtype: Any = None):
    """Random URDF-style robots: trees with revolute, prismatic and fixed joints, arbitrary axes."""
    n = draw(st.integers(min_joints, max_joints))
    joints = []
    frames = ["root"]
    for j in range(n):
        kind = draw(st.sampled_from(["revolute", "revolute", "prismatic", "fixed"]))
        if j == n - 1 and all(s["type"] == "fixed" for s in joints):
            kind = "revolute"
        parent = draw(st.sampled_from(frames))
        spec = dict(
            name=f"j{j}",
            type=kind,
            parent=parent,
            child=f"f{j}",
            xyz=tuple(draw(st.tuples(*[_length(0.5)] * 3))),
            rpy=tuple(draw(st.tuples(*[_angle()] * 3))),
            axis=tuple(draw(unit_vectors())),
        )
        if kind == "revolute":
            spec.update(lower=-math.pi, upper=math.pi)
        elif kind == "prismatic":
            spec.update(lower=-1.0, upper=1.0)
        joints.append(spec)
        frames.append(spec["child"])
    base = draw(st.one_of(st.none(), transforms()))
    return Robot.from_joints(joints, root="root", base=base, name="random_tree", dtype=dtype)


def configurations(robot: Robot, margin: float = 0.0) -> st.SearchStrategy[np.ndarray]:
    """Joint vectors (nq,) within :func:`jaxkin.sampling_bounds` (the joint limits; unbounded
    sides as :mod:`jaxkin.sampling` documents), ``margin`` (a fraction of each range) kept
    clear of both ends. Quaternions and planar (cos, sin) pairs are scaled to unit length (a
    zero one becomes the identity)."""
    lo, hi = sampling_bounds(robot)
    elems = []
    for a, b in zip(lo, hi, strict=True):
        a, b = a + margin * (b - a), b - margin * (b - a)
        elems.append(st.floats(float(a), float(b), **_FINITE))
    rotations = []
    for j in robot.multi_dof_joints:
        qi = robot.q_index[j]
        start, end = {"free": (3, 7), "ball": (0, 4), "planar": (2, 4)}[robot.kinds[j]]
        rotations.append((qi + start, qi + end))

    def to_manifold(t) -> np.ndarray:
        q = np.array(t, dtype=float)
        for a, b in rotations:
            n = np.linalg.norm(q[a:b])
            q[a:b] = q[a:b] / n if n > 1e-3 else np.eye(b - a)[0]
        return q

    return st.tuples(*elems).map(to_manifold)


_ROWS = {"all": slice(0, 6), "translation": slice(0, 3), "rotation": slice(3, 6)}


@functools.partial(jax.jit, static_argnames=("frame", "rows", "rank"))
def _smallest_singular_value_and_grad(robot: Robot, q, frame, rows: str, rank: int):
    """``(sigma_rank, sigma_1)`` of the world-aligned J's ``rows`` at ``q``, and the gradient of
    sigma_rank."""

    def sigmas(qq):
        J = geometric_jacobian(robot, qq, frame=frame)[_ROWS[rows]]
        s = jnp.linalg.svd(J, compute_uv=False)
        return s[rank - 1], s[0]

    (s_r, s_1), grad = jax.value_and_grad(sigmas, has_aux=True)(q)
    return s_r, s_1, grad


def _generic_rank(robot: Robot, frame, rows: str, lo: np.ndarray, hi: np.ndarray, dtype) -> int:
    """The Jacobian's largest rank, from a few fixed random configurations within the limits."""
    rng = np.random.default_rng(0)
    rank = 0
    for _ in range(4):
        q = jnp.asarray(lo + (hi - lo) * rng.random(robot.nq), dtype=dtype)
        J = np.asarray(geometric_jacobian(robot, q, frame=frame))[_ROWS[rows]]
        s = np.linalg.svd(J, compute_uv=False)
        rank = max(rank, int(np.count_nonzero(s > 1e-9 * max(float(s[0]), 1e-300))))
    return rank


def near_singular_configurations(
    robot: Robot,
    frame: int | str | None = None,
    *,
    rows: str = "all",
    tol: float = 1e-6,
    max_steps: int = 40,
) -> st.SearchStrategy[np.ndarray]:
    """Configurations (dof,) within the limits where ``frame``'s Jacobian is (nearly) singular.

    ``J`` is the world-aligned geometric Jacobian's ``rows``: ``"all"`` (6 x dof),
    ``"translation"`` (``J_v``, the frame origin's velocity: e.g. the planar two-link arm, whose
    full J never loses rank, is singular in ``J_v`` at ``q2 = 0, pi``) or ``"rotation"``.
    Each example starts from a configuration drawn within the limits and takes Newton steps on
    ``sigma_r(J(q))``, the r-th singular value, r being the largest rank J reaches
    (``min(rows, dof)`` unless the robot is degenerate), projecting onto the limits after each
    step. It yields ``q`` once ``sigma_r / sigma_1 <= tol`` and rejects the
    start (``hypothesis.reject``) if that takes more than ``max_steps`` steps. So every example
    is a configuration where J has lost rank to within ``tol``: at or next to a singularity.

    Which singularity each example lands on depends on its start: all kinds that lie within the
    limits come up (e.g. for the Niryo One: wrist, ``q5 = 0``; shoulder, wrist centre on the base
    axis). A robot that has no singular configuration within its limits (a single revolute joint)
    makes hypothesis report the strategy as unsatisfiable. Compiles one Newton step per robot
    topology (a second or two); float64 (x64) reaches ``tol = 1e-6`` reliably, float32 about
    ``1e-4``.
    """
    if not (isinstance(tol, (int, float)) and 0 < tol < 1):
        raise ValueError(f"tol must be a number in (0, 1), got {tol!r}.")
    if rows not in _ROWS:
        raise ValueError(f"rows must be one of {tuple(_ROWS)}, got {rows!r}.")
    refuse_multi_dof(
        robot, "jaxkin.testing.near_singular_configurations", "takes Newton steps on q in a box"
    )
    robot.frame_index(frame)  # validates frame now, not inside hypothesis
    dtype = jnp.result_type(float)
    lo, hi = sampling_bounds(robot)
    rank = _generic_rank(robot, frame, rows, lo, hi, dtype)
    if rank == 0:
        raise ValueError(f"no joint moves frame {frame!r} of robot {robot.name!r}.")

    def newton(q0: np.ndarray) -> np.ndarray:
        q = np.clip(q0, lo, hi)
        for _ in range(max_steps):
            s_r, s_1, g = _smallest_singular_value_and_grad(
                robot, jnp.asarray(q, dtype=dtype), frame, rows, rank
            )
            s_r, s_1, g = float(s_r), float(s_1), np.asarray(g, dtype=float)
            if s_r <= tol * s_1:
                return q
            g2 = float(g @ g)
            if not (np.isfinite(g2) and g2 > 0):
                break
            step = -s_r * g / g2  # Newton on the (locally linear) distance sigma_r
            norm = float(np.linalg.norm(step))
            if norm > 0.5:
                step *= 0.5 / norm  # damped: stay in the region where the model holds
            q = np.clip(q + step, lo, hi)
        return None

    return configurations(robot).map(newton).filter(lambda q: q is not None)


def robots_and_configurations(
    min_joints: int = 1, max_joints: int = 12, kind: str = "any", dtype: Any = None
):
    """Pairs ``(robot, q)``: random DH or tree robots and a configuration within limits."""
    if kind == "dh":
        robots = dh_robots(min_joints, max_joints, dtype=dtype)
    elif kind == "tree":
        robots = tree_robots(min_joints, max_joints, dtype=dtype)
    else:
        robots = st.one_of(
            dh_robots(min_joints, max_joints, dtype=dtype),
            tree_robots(min_joints, max_joints, dtype=dtype),
        )
    return robots.flatmap(lambda r: st.tuples(st.just(r), configurations(r)))


def finite_difference_jacobian(
    robot: Robot,
    q: Any,
    frame: int | str | None = None,
    point: Any = None,
    reference: str = "world_aligned",
    h: float = 1e-6,
) -> np.ndarray:
    """Central finite differences on SE(3): an oracle independent of any Jacobian code.

    Linear rows: ``(p(q + h e_k) - p(q - h e_k)) / 2h`` of the (offset) point; angular rows:
    ``log(R(q + h e_k) R(q - h e_k)^T) / 2h``. Float64 only; error about ``h^2`` plus
    ``eps / h`` (1e-9 .. 1e-10 at h = 1e-6).
    """
    if not jax.config.read("jax_enable_x64"):
        raise RuntimeError("finite_difference_jacobian needs jax_enable_x64 (float64).")
    robot = robot.astype(np.float64)
    q = check_q(
        robot,
        q,
        fn="jk.testing.finite_difference_jacobian",
        batch_hint="jax.numpy.stack([jk.testing.finite_difference_jacobian(robot, q) for q in qs])",
    ).astype(jnp.float64)
    f = robot.frame_index(frame)
    pt = None if point is None else jnp.asarray(point, dtype=jnp.float64)
    J = _fd_in(reference, *_fd_world_aligned(robot, q, f, pt, h))
    return np.asarray(J)[:, : robot.nv]


def _fd_world_aligned(robot: Robot, q, f: int, pt, h: float):
    """``(Jv, Jw, p0, R0)``: finite-difference columns in base axes at the (offset) point, and the
    pose at ``q`` (float64 robot and ``q``; traceable). The columns are padded with zero columns
    to :func:`jaxkin._jit.block_width` columns (cut them off with ``[:, :robot.nv]``)."""

    def pose(qq):
        R, p = frame_pose(robot, qq, f)
        return (p if pt is None else p + R @ pt), R

    nv = robot.nv
    # Every step (+h and -h along each column) is a row of one batch, the columns padded with
    # zero steps to a block (``block_width``) and cut off only at the end: op by op (property
    # tests under jax.disable_jit) every batched operation then has one shape per block of
    # columns, not one per robot size, and compiles once for all robots up to that size.
    wide = block_width(nv)
    if robot.nq == nv:
        # q widened to as many entries (the forward pass reads q's entries by index: the
        # padding is never read), so even the steps have one shape per block
        x = padded_to_block(q, wide)
        steps = h * jnp.eye(wide, dtype=jnp.float64)
        ps, Rs = jax.vmap(pose)(jnp.concatenate([x[None, :] + steps, x[None, :] - steps]))
    else:  # steps along the configuration manifold (free, ball, planar joints)
        from .configuration import integrate_kernel

        eye = jnp.eye(wide, nv, dtype=jnp.float64)
        steps = jnp.concatenate([h * eye, -h * eye])
        ps, Rs = jax.vmap(lambda v: pose(integrate_kernel(robot, q, v)))(steps)
        x = q
    Jv = ((ps[:wide] - ps[wide:]) / (2 * h)).T
    Jw = (jax.vmap(lambda a, b: spatial.log_so3(a @ b.T))(Rs[:wide], Rs[wide:]) / (2 * h)).T
    p0, R0 = pose(x)
    return Jv, Jw, p0, R0


def _fd_in(reference: str, Jv, Jw, p0, R0):
    """The finite-difference Jacobian in ``reference`` from :func:`_fd_world_aligned`."""
    if reference == "local":
        Jv, Jw = R0.T @ Jv, R0.T @ Jw
    elif reference == "world":
        Jv = Jv + spatial.skew(p0) @ Jw
    return jnp.concatenate([Jv, Jw], axis=0)


def assert_jacobian_consistent(
    robot: Robot,
    q: Any,
    frame: int | str | None = None,
    point: Any = None,
    references: tuple[str, ...] = REFERENCES,
    atol: float | None = None,
    fd_atol: float = 1e-7,
    finite_differences: bool | None = None,
) -> None:
    """Assert hand-built == jacfwd == jacrev (``atol``) == finite differences (``fd_atol``).

    ``atol`` defaults to ``1e-12 * max(1, reach)`` in float64 and ``1e-5 * max(1, reach)`` in
    float32, reach being the largest distance of a frame from the base. Finite differences run
    only in float64 (default: whenever x64 is on and the robot is float64). Everything is
    evaluated by four programs compiled for the call (the hand-built Jacobians, ``jacfwd``,
    ``jacrev`` and the finite differences: XLA compiles four small programs faster than one
    large one), with jaxkin's compiler options and XLA's cheapest backend passes (they run once:
    compiling is their cost). The autodiff Jacobians of all ``references`` come from one
    ``jax.jacfwd`` and one ``jax.jacrev`` of forward kinematics, each reference's columns
    converted as :func:`jaxkin.jacobian_fwd` and :func:`jaxkin.jacobian_rev` convert them.
    Under ``jax.disable_jit()`` it runs op by op, the autodiff and finite-difference columns
    padded to a block of 8: each operation compiles once per block, not once per robot size (a
    property over random robots, each used once).
    """
    fn = "jk.testing.assert_jacobian_consistent"
    q = check_q(robot, q, fn=fn, batch_hint=f"[{fn}(robot, q) for q in qs]")
    references = tuple(check_reference(ref) for ref in references)
    is64 = result_dtype(robot, q) == np.float64
    fd = finite_differences if finite_differences is not None else is64
    if fd and not jax.config.read("jax_enable_x64"):
        raise RuntimeError("finite differences need jax_enable_x64 (float64).")
    f = robot.frame_index(frame)
    pt = check_point(point, result_dtype(robot, q), fn)
    robot64 = robot.astype(np.float64) if fd else None
    pt64 = None if point is None or not fd else jnp.asarray(point, dtype=jnp.float64)

    def hand_built(q):
        Js = [
            geometric_jacobian(robot, q, frame=frame, point=point, reference=ref)
            for ref in references
        ]
        return forward_pass(robot, q).p, Js

    def jac_fwd(q):
        return autodiff_jacobian(robot, q, f, pt, references, "fwd")

    def jac_rev(q):
        return autodiff_jacobian(robot, q, f, pt, references, "rev")

    def finite_difference(q):
        parts = _fd_world_aligned(robot64, q.astype(jnp.float64), f, pt64, 1e-6)
        return [_fd_in(ref, *parts)[:, : robot.nv] for ref in references]

    # Four programs, not one: XLA's compile time grows faster than a program's size (a random
    # 10-joint robot: about 5 CPU s as one program, 3.5 as four).
    programs = (hand_built, jac_fwd, jac_rev) + ((finite_difference,) if fd else ())
    options = one_shot_compiler_options() or None
    results = jax.device_get([jax.jit(fn, compiler_options=options)(q) for fn in programs])
    (origins, Js), fwd, rev = results[:3]
    fds = results[3] if fd else [None] * len(references)
    out = dict(zip(references, zip(Js, fwd, rev, fds, strict=True), strict=True))
    reach = float(np.max(np.linalg.norm(origins - origins[:1], axis=1)))
    tol = atol if atol is not None else (1e-12 if is64 else 1e-5) * max(1.0, reach)
    for ref in references:
        J, Jf, Jr, Jd = out[ref]
        assert np.all(np.isfinite(J)), f"non-finite Jacobian ({ref})"
        np.testing.assert_allclose(J, Jf, rtol=0, atol=tol, err_msg=f"hand-built vs jacfwd ({ref})")
        np.testing.assert_allclose(J, Jr, rtol=0, atol=tol, err_msg=f"hand-built vs jacrev ({ref})")
        if fd:
            scale = fd_atol * max(1.0, reach)
            np.testing.assert_allclose(J, Jd, rtol=0, atol=scale, err_msg=f"vs FD ({ref})")
