"""Task stacks (jaxkin.tasks): prioritised inverse differential kinematics with hard limits.

Oracles, written here in numpy independently of the module:

* one task: the damped pseudo-inverse ``V diag(sigma / (sigma^2 + lambda_i^2)) U^T v`` with
  ``lambda_i^2 = max(lambda^2 - sigma^2 / 4, 0)`` (the damping the module states), which is
  ``pinv(J) v`` where every singular value is at least ``2 lambda``, and bounded by
  ``|v| / (sqrt(3) lambda)`` at singularities;
* two tasks: the textbook's closed form ``qd = J1^+ v1 + (J2 N1)^+ (v2 - J2 J1^+ v1)``,
  ``N1 = I - J1^+ J1``: the primary met exactly, the secondary minimised in its null space;
* limits: the velocity box ``max(-v_max, (lower - q) / dt) <= qd <= min(v_max, (upper - q) / dt)``
  checked on every answer (hypothesis over configurations, task velocities, limits and steps);
  a feasible task that plain clipping would break is met exactly with a joint at its bound
  (saturation in the null space), an infeasible one keeps its direction, scaled;
* the resolved-rate loop against its own targets (independent forward kinematics), closed loop
  against open loop, on the zoo's Panda and on a small floating-base robot with a ball joint;
* the centre-of-mass rows against ``jk.com_jacobian`` in the same closed form.

Each robot and task structure compiles once (the tests share them). One test batches with
``jit(vmap(...))``; the others call eagerly, which compiles with jaxkin's compiler options and
is several times cheaper to compile than a user's jit around the call.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE
from hypothesis import given
from hypothesis import strategies as st

import jaxkin as jk

DT = 0.01
LAM = 1e-2  # the default damping
UR5 = jk.robots.load("ur5")
PANDA = jk.robots.load("panda")
PANDA_VMAX = 2.0
POSE_ERROR = jax.jit(jk.pose_error, compiler_options=FAST_COMPILE)  # one compile, not op by op


def hopper() -> jk.Robot:
    """A free-floating body with a three-joint leg and a ball-jointed arm, with masses."""

    def inertial(m, xyz=(0.0, 0.0, 0.0)):
        return dict(mass=m, xyz=list(xyz))

    return jk.Robot.from_joints(
        [
            dict(name="root", type="free", child="body", xyz=[0, 0, 0.5], inertial=inertial(5.0)),
            dict(name="hip_y", type="revolute", parent="body", child="hip", axis=[0, 1, 0],
                 lower=-1.5, upper=1.5, inertial=inertial(0.5)),
            dict(name="hip_x", type="revolute", child="thigh", axis=[1, 0, 0], lower=-1.0,
                 upper=1.0, inertial=inertial(1.0, (0, 0, -0.15))),
            dict(name="knee", type="revolute", child="shin", xyz=[0, 0, -0.3], axis=[0, 1, 0],
                 lower=0.0, upper=2.5, inertial=inertial(1.0, (0, 0, -0.15))),
            dict(name="foot", type="fixed", child="foot", xyz=[0, 0, -0.3]),
            dict(name="shoulder", type="ball", parent="body", child="arm", xyz=[0.1, 0, 0.2],
                 inertial=inertial(1.0, (0.15, 0, 0))),
            dict(name="hand", type="fixed", child="hand", xyz=[0.3, 0, 0]),
        ],
        name="hopper",
        dtype=np.float64,
        default_frames=["hand"],
    )  # fmt: skip


HOPPER = hopper()


def hopper_q0() -> jax.Array:
    names = HOPPER.joint_names
    q = np.array(jk.neutral(HOPPER))  # numpy: no eager scatter programs
    q[names.index("knee")], q[names.index("hip_y")] = 1.0, -0.5
    return jnp.asarray(q)


# ----------------------------------------------------------------------------- numpy oracles
def damped_pinv(A, lam):
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    keep = s > np.sqrt(np.finfo(float).eps) * np.linalg.norm(A)
    lam_i2 = np.maximum(lam**2 - s**2 / 4, 0.0)
    g = np.where(keep, s / np.where(keep, s**2 + lam_i2, 1.0), 0.0)
    return Vt.T @ np.diag(g) @ U.T


def pinv(A):
    return np.linalg.pinv(A, rcond=1e-10)


def two_task_closed_form(J1, v1, J2, v2):
    J1p = pinv(J1)
    N1 = np.eye(J1.shape[1]) - J1p @ J1
    return J1p @ v1 + pinv(J2 @ N1) @ (v2 - J2 @ J1p @ v1)


def smallest_nonzero_singular_value(A):
    s = np.linalg.svd(A, compute_uv=False)
    return s[s > 1e-9 * s[0]].min()


def velocity_box(robot, q, dt, vmax):
    """The joint-velocity box of the limits, for a robot whose q entries are its velocities."""
    lower, upper, q = (np.asarray(a, dtype=np.float64) for a in (robot.lower, robot.upper, q))
    return np.maximum(-vmax, (lower - q) / dt), np.minimum(vmax, (upper - q) / dt)


# ----------------------------------------------------------------------------- one task
def test_one_task_is_the_damped_pseudo_inverse_under_jit_vmap():
    rng = np.random.default_rng(0)
    qs = rng.uniform(-np.pi, np.pi, size=(12, 6))
    qs[8:, 4] = 0.0  # the UR5's wrist singularity: sin(q5) = 0
    qs[10:, 2] = 0.0  # and the elbow stretched out
    vs = rng.normal(size=(12, 6))

    def solve(q, v):
        task = jk.FrameTask(None, velocity=v)
        return jk.solve_tasks(UR5, q, [task], dt=DT, position_limits=False)

    out = jax.jit(jax.vmap(solve), compiler_options=FAST_COMPILE)(jnp.asarray(qs), jnp.asarray(vs))
    assert out.qd.shape == (12, 6) and out.scale.shape == (12, 1)
    Js = np.stack([np.asarray(jk.geometric_jacobian(UR5, q)) for q in qs])  # one eager kernel
    for J, v, qd in zip(Js, vs, np.asarray(out.qd), strict=True):
        np.testing.assert_allclose(qd, damped_pinv(J, LAM) @ v, atol=1e-9)
        assert np.all(np.isfinite(qd))
        assert np.linalg.norm(qd) <= np.linalg.norm(v) / (np.sqrt(3) * LAM) * (1 + 1e-9)
        if np.linalg.svd(J, compute_uv=False).min() >= 2 * LAM:  # exact away from singularities
            np.testing.assert_allclose(qd, np.linalg.solve(J, v), atol=1e-9)
            np.testing.assert_allclose(J @ qd, v, atol=1e-9)
    smallest = np.linalg.svd(Js, compute_uv=False).min(axis=1)
    assert np.any((smallest > 1e-6) & (smallest < 2 * LAM))  # damped cases are among them
    assert np.all(smallest[10:] < 1e-12)  # and singular ones
    singular = np.asarray(out.qd)[8:]
    assert np.abs(singular).max() < 1e3  # bounded where the pseudo-inverse is not
    np.testing.assert_array_equal(np.asarray(out.scale), 1.0)


# ----------------------------------------------------------------------------- two tasks
def test_two_tasks_match_the_textbook_closed_form():
    """Primary: the tool's position (3 rows); secondary: the tool's whole twist in its own axes
    (6 rows, 4 left free by the primary on a 7-joint arm): exact, then least squares in the
    primary's null space."""
    rng = np.random.default_rng(1)
    lo, hi = np.asarray(PANDA.lower), np.asarray(PANDA.upper)
    qs, v1s, v2s = [], [], []
    while len(qs) < 6:
        q = rng.uniform(lo + 0.2, hi - 0.2)
        J = np.asarray(jk.geometric_jacobian(PANDA, q))
        J1, J2 = J[:3], np.asarray(jk.geometric_jacobian(PANDA, q, reference="local"))
        N1 = np.eye(7) - pinv(J1) @ J1
        sigma = min(smallest_nonzero_singular_value(J1), smallest_nonzero_singular_value(J2 @ N1))
        if sigma < 0.05:
            continue  # keep away from damping's reach: the closed form is undamped
        qs.append(q)
        v1s.append(rng.normal(size=3) * 0.2)
        v2s.append(rng.normal(size=6) * 0.2)

    def solve(q, v1, v2):
        tasks = [
            jk.FrameTask("tool", velocity=v1, rows="position"),
            jk.FrameTask("tool", velocity=v2, reference="local"),
        ]
        return jk.solve_tasks(PANDA, q, tasks, dt=DT, position_limits=False).qd

    for q, v1, v2 in zip(qs, v1s, v2s, strict=True):
        qd = np.asarray(solve(q, v1, v2))
        J1 = np.asarray(jk.geometric_jacobian(PANDA, q))[:3]
        J2 = np.asarray(jk.geometric_jacobian(PANDA, q, reference="local"))
        np.testing.assert_allclose(qd, two_task_closed_form(J1, v1, J2, v2), atol=1e-9)
        np.testing.assert_allclose(J1 @ qd, v1, atol=1e-10)  # the primary, exactly
        # the secondary cannot be improved without disturbing the primary
        N1 = np.eye(7) - pinv(J1) @ J1
        best = np.linalg.norm(J2 @ qd - v2)
        for z in rng.normal(size=(20, 7)):
            assert best <= np.linalg.norm(J2 @ (qd + 0.1 * N1 @ z) - v2) + 1e-12
        assert best > 1e-3  # and it is a real compromise: 6 rows on 4 free joints


def test_several_frames_references_and_targets_in_one_stack():
    """Level 1: two frames' angular velocities in their own axes (one FrameTask with a list of
    frames, "local", 6 rows); level 2: the tool toward a target, position rows in the "world"
    reference (the velocity of the point at the world origin). Against the closed form on
    jk.geometric_jacobian's rows and jk.pose_error."""
    q = ARM_CASES[0]
    W = np.array([[0.1, 0.0, -0.2], [0.0, 0.3, 0.1]])
    T_tool = np.asarray(jk.fk(PANDA, q, frame="tool"))
    T_goal = np.eye(4)
    c, s = np.cos(0.1), np.sin(0.1)
    T_goal[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ T_tool[:3, :3]
    T_goal[:3, 3] = T_tool[:3, 3] + [0.01, 0.0, -0.01]
    tasks = [
        jk.FrameTask(["link4", "tool"], velocity=W, rows="orientation", reference="local"),
        jk.FrameTask("tool", target=T_goal, rows="position", reference="world", gain=0.5),
    ]
    qd = np.asarray(jk.solve_tasks(PANDA, q, tasks, dt=DT, position_limits=False).qd)
    Jl = np.asarray(jk.geometric_jacobian(PANDA, q, frame=["link4", "tool"], reference="local"))
    J1, v1 = np.concatenate([Jl[0, 3:], Jl[1, 3:]]), W.reshape(6)
    J2 = np.asarray(jk.geometric_jacobian(PANDA, q, frame="tool", reference="world"))[:3]
    e = np.asarray(POSE_ERROR(T_tool, T_goal))  # [dp; dw] at the tool, world axes
    v2 = 0.5 * (e[:3] + np.cross(T_tool[:3, 3], e[3:])) / DT  # the same twist, world point
    np.testing.assert_allclose(qd, two_task_closed_form(J1, v1, J2, v2), atol=1e-9)
    np.testing.assert_allclose(J1 @ qd, v1, atol=1e-10)


# ----------------------------------------------------------------------------- hard limits
def position_and_posture(q, v, q_ref, dt, vmax):
    tasks = [jk.FrameTask("tool", velocity=v, rows="position"), jk.PostureTask(q_ref, gain=0.5)]
    return jk.solve_tasks(PANDA, q, tasks, dt=dt, velocity_limits=vmax)


unit = st.floats(0.0, 1.0)


@given(
    st.lists(unit, min_size=7, max_size=7),
    st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
    st.lists(unit, min_size=7, max_size=7),
    st.lists(st.floats(0.05, 3.0), min_size=7, max_size=7),
    st.floats(0.002, 0.2),
)
def test_limits_are_never_exceeded(u, v, u_ref, vmax, dt):
    lo, hi = np.asarray(PANDA.lower), np.asarray(PANDA.upper)
    q = lo + (hi - lo) * np.asarray(u)
    q_ref = lo + (hi - lo) * np.asarray(u_ref)
    vmax = np.asarray(vmax)
    sol = position_and_posture(jnp.asarray(q), jnp.asarray(v), jnp.asarray(q_ref), dt, vmax)
    qd = np.asarray(sol.qd)
    qd_lo, qd_hi = velocity_box(PANDA, q, dt, vmax)
    assert np.all(qd >= qd_lo) and np.all(qd <= qd_hi), (qd, qd_lo, qd_hi)
    q_next = q + dt * qd
    assert np.all(q_next >= lo - 1e-12) and np.all(q_next <= hi + 1e-12)
    s = np.asarray(sol.scale)
    assert np.all((s >= 0.0) & (s <= 1.0))
    # where the primary's minimum-norm solution fits the box, the primary is met exactly
    J1 = np.asarray(jk.geometric_jacobian(PANDA, q))[:3]
    if np.linalg.svd(J1, compute_uv=False).min() >= 0.05:
        qd_min = pinv(J1) @ np.asarray(v)
        if np.all(qd_min > qd_lo) and np.all(qd_min < qd_hi):
            assert s[0] == 1.0
            np.testing.assert_allclose(J1 @ qd, v, atol=1e-9)


ARM_CASES = [
    np.array([0.3, 0.4, -0.2, -1.8, 0.3, 2.0, 0.5]),
    np.array([0.0, -0.3, 0.0, -2.0, 0.0, 1.8, 0.8]),
    np.array([0.5, 0.2, 0.4, -1.5, -0.6, 1.5, 0.0]),
]


def saturating_case():
    """A Panda configuration and tool velocity whose minimum-norm joint velocity leaves the box
    while another one inside it meets the task (the arm is redundant)."""
    q = ARM_CASES[2]
    J1 = np.asarray(jk.geometric_jacobian(PANDA, q))[:3]
    v = np.array([0.0, 0.25, 0.0])
    qd_min = pinv(J1) @ v
    vmax = 0.8 * np.abs(qd_min).max()
    return q, J1, v, vmax, qd_min


def test_saturation_in_the_null_space_meets_a_feasible_task_exactly():
    q, J1, v, vmax, qd_min = saturating_case()
    assert np.abs(qd_min).max() > vmax  # the textbook answer breaks the limit
    clipped = np.clip(qd_min, -vmax, vmax)
    assert np.linalg.norm(J1 @ clipped - v) > 1e-3  # and clipping it breaks the task
    sol = position_and_posture(jnp.asarray(q), jnp.asarray(v), jnp.asarray(q), DT, vmax)
    qd = np.asarray(sol.qd)
    assert float(sol.scale[0]) == 1.0
    np.testing.assert_allclose(J1 @ qd, v, atol=1e-9)
    assert np.abs(qd).max() <= vmax
    assert np.isclose(np.abs(qd).max(), vmax, rtol=0, atol=1e-12)  # a joint at its bound


def test_an_infeasible_task_is_scaled_along_its_direction():
    q, J1, v, vmax, _ = saturating_case()
    v = 20.0 * v  # far beyond what the box allows
    sol = position_and_posture(jnp.asarray(q), jnp.asarray(v), jnp.asarray(q), DT, vmax)
    qd, s = np.asarray(sol.qd), float(sol.scale[0])
    assert 0.0 < s < 1.0
    assert np.abs(qd).max() <= vmax
    np.testing.assert_allclose(J1 @ qd, s * v, atol=1e-9)


def test_the_primary_is_met_exactly_where_a_linear_program_finds_it_feasible():
    """36 boxes around the minimum-norm answer (70-95 % of its largest entry): where scipy's
    linprog finds a velocity in the box with ``J1 qd = v1``, the stack meets the primary
    exactly (scale 1); where it finds none, the stack scales it (scale < 1), along v1."""
    linprog = pytest.importorskip("scipy.optimize").linprog
    for q in ARM_CASES:
        J1 = np.asarray(jk.geometric_jacobian(PANDA, q))[:3]
        for v in 0.25 * np.eye(3):
            qd_min = pinv(J1) @ v
            for ratio in (0.95, 0.9, 0.8, 0.7):
                vmax = ratio * np.abs(qd_min).max()
                lp = linprog(np.zeros(7), A_eq=J1, b_eq=v, bounds=[(-vmax, vmax)] * 7)
                assert lp.status in (0, 2), lp.message  # solved: feasible or not
                sol = position_and_posture(jnp.asarray(q), jnp.asarray(v), jnp.asarray(q), DT, vmax)
                s, qd = float(sol.scale[0]), np.asarray(sol.qd)
                assert np.abs(qd).max() <= vmax
                assert (s == 1.0) == (lp.status == 0), (q, v, ratio, s, lp.status)
                np.testing.assert_allclose(J1 @ qd, s * v, atol=1e-9)


def test_a_configuration_outside_its_limits_is_driven_back():
    q = np.asarray(PANDA.upper) + 0.05  # every joint 0.05 rad past its upper limit
    sol = position_and_posture(jnp.asarray(q), jnp.zeros(3), jnp.asarray(q), DT, 1.0)
    qd = np.asarray(sol.qd)
    np.testing.assert_allclose(qd, -1.0)  # back toward the range at the velocity limit


# ----------------------------------------------------------------------------- resolved rate
def circle(T0, n, radius, axis_a, axis_b):
    t = np.arange(n) / (n - 1)
    Ts = np.repeat(np.asarray(T0)[None], n, axis=0)
    Ts[:, axis_a, 3] += radius * np.sin(2 * np.pi * t)
    Ts[:, axis_b, 3] += radius * (1 - np.cos(2 * np.pi * t))
    return Ts


def test_follow_paths_tracks_a_tool_path_on_an_arm():
    q0 = jnp.array([0.0, -0.3, 0.0, -2.0, 0.0, 1.8, 0.8])
    path = circle(jk.fk(PANDA, q0, frame="tool"), 100, 0.05, 1, 2)  # 5 cm circle in 1 s

    def run(gain):
        return jk.follow_paths(
            PANDA, q0, path, "tool", DT, gain=gain, posture=q0, velocity_limits=PANDA_VMAX
        )

    closed, open_loop = run(1.0), run(0.0)
    assert closed.q.shape == (101, 7) and closed.qd.shape == (100, 7)
    assert closed.position_error.shape == (100, 1)
    assert float(closed.max_position_error) < 1e-4
    assert float(closed.max_orientation_error) < 1e-4
    # feedback: without it the linearisation error accumulates
    assert float(open_loop.max_position_error) > 10 * float(closed.max_position_error)
    # the reported errors are those of an independent forward kinematics
    T_end = np.asarray(jk.fk(PANDA, closed.q[-1], frame="tool"))
    np.testing.assert_allclose(
        np.linalg.norm(T_end[:3, 3] - path[-1][:3, 3]), closed.position_error[-1, 0], atol=1e-12
    )
    qs = np.asarray(closed.q)
    assert np.all(qs >= np.asarray(PANDA.lower)) and np.all(qs <= np.asarray(PANDA.upper))
    assert np.abs(np.asarray(closed.qd)).max() <= PANDA_VMAX


def test_follow_paths_on_a_floating_base_with_a_ball_joint():
    """The foot stays put while the hand draws a circle: the free base and the ball joint move
    (integrated on the manifold); quaternions stay unit, the leg's joints within limits. Two
    starts: the path's own, and one with the knee 0.1 rad off, whose error the feedback
    removes in one step."""
    q0 = hopper_q0()
    frames = ["foot", "hand"]
    T0 = np.asarray(jk.fk(HOPPER, q0, frame=frames))
    n = 50
    targets = np.stack([np.repeat(T0[:1], n, axis=0), circle(T0[1], n, 0.05, 1, 2)], axis=1)
    knee = np.asarray(q0).copy()
    knee[HOPPER.joint_names.index("knee")] += 0.1  # numpy: no eager scatter program
    starts = [q0, knee]
    runs = [
        jk.follow_paths(HOPPER, q, targets, frames, 0.02, rows="position", velocity_limits=3.0)
        for q in starts
    ]
    out = jax.tree_util.tree_map(lambda *a: np.stack(a), *runs)
    assert out.q.shape == (2, n + 1, HOPPER.nq) and out.qd.shape == (2, n, HOPPER.nv)
    assert np.asarray(out.position_error)[:, 1:].max() < 2e-4
    assert np.asarray(out.position_error)[1, 0].max() > 1e-4  # the offset start, after step 0
    np.testing.assert_array_equal(np.asarray(out.orientation_error), 0.0)  # not tracked
    qs = np.asarray(out.q)
    for j in ("root", "shoulder"):
        quat = [HOPPER.joint_names.index(f"{j}.{c}") for c in ("qw", "qx", "qy", "qz")]
        np.testing.assert_allclose(np.linalg.norm(qs[..., quat], axis=-1), 1.0, atol=1e-12)
    assert np.abs(qs[0, :, :3] - qs[0, 0, :3]).max() > 1e-3  # the base moved
    leg = [HOPPER.joint_names.index(n) for n in ("hip_y", "hip_x", "knee")]
    assert np.all(qs[..., leg] >= np.asarray(HOPPER.lower)[leg])
    assert np.all(qs[..., leg] <= np.asarray(HOPPER.upper)[leg])
    # the foot's pose by an independent forward kinematics at the end (the program of T0's)
    for q_end in qs[:, -1]:
        T_foot = np.asarray(jk.fk(HOPPER, q_end, frame=frames))[0]
        assert np.linalg.norm(T_foot[:3, 3] - T0[0, :3, 3]) < 2e-4


def test_centre_of_mass_task_against_the_closed_form():
    """Level 1: the centre of mass' ground projection (x, y) moves; level 2: the hand's
    position. Rows against jk.com_jacobian and jk.geometric_jacobian."""
    q = hopper_q0()
    c = np.asarray(jk.center_of_mass(HOPPER, q))
    vh = np.array([0.0, 0.1, 0.05])

    def solve(target, vc, gain):
        com = jk.ComTask(target=target, velocity=vc, axes="xy", gain=gain)
        hand = jk.FrameTask("hand", velocity=vh, rows="position")
        return jk.solve_tasks(HOPPER, q, [com, hand], dt=DT, position_limits=False)

    Jc = np.asarray(jk.com_jacobian(HOPPER, q))[:2]
    Jh = np.asarray(jk.geometric_jacobian(HOPPER, q, frame="hand"))[:3]
    vc = np.array([0.02, -0.01])
    qd = np.asarray(solve(c, vc, 1.0).qd)  # at the target: the velocity alone
    np.testing.assert_allclose(qd, two_task_closed_form(Jc, vc, Jh, vh), atol=1e-9)
    np.testing.assert_allclose(Jc @ qd, vc, atol=1e-10)
    np.testing.assert_allclose(Jh @ qd, vh, atol=1e-9)  # room for both
    # a target: the centre of mass moves toward it by gain * error / dt (height left free)
    qd = np.asarray(solve(c + np.array([0.01, 0.0, 0.3]), np.zeros(2), 0.5).qd)
    np.testing.assert_allclose(Jc @ qd, [0.5 * 0.01 / DT, 0.0], atol=1e-9)


# ----------------------------------------------------------------------------- float32
def test_float32_keeps_the_limits_and_matches_the_pseudo_inverse():
    robot32 = UR5.astype(np.float32)
    rng = np.random.default_rng(3)
    qs = rng.uniform(-2.0, 2.0, size=(8, 6))
    vs = rng.normal(size=(8, 3)) * np.repeat([0.05, 2.0], 4)[:, None]  # slow, then too fast
    vmax = 0.5

    def one(q, v):
        tasks = [jk.FrameTask(None, velocity=v, rows="position"), jk.PostureTask(q, gain=0.0)]
        return jk.solve_tasks(robot32, q, tasks, dt=DT, velocity_limits=vmax)

    outs = [one(q, v) for q, v in zip(qs.astype(np.float32), vs.astype(np.float32), strict=True)]
    qd32 = np.stack([np.asarray(o.qd) for o in outs])
    assert qd32.dtype == np.float32 and all(o.scale.dtype == np.float32 for o in outs)
    assert np.all(np.abs(qd32) <= np.float32(vmax))
    assert np.any(np.abs(qd32) == np.float32(vmax))  # the limit was reached
    compared = 0
    for q, v, qd in zip(qs, vs, qd32, strict=True):
        J1 = np.asarray(jk.geometric_jacobian(UR5, q))[:3]
        qd_min = pinv(J1) @ v  # a posture gain of 0 pulls toward 0: the minimum norm
        if np.linalg.svd(J1, compute_uv=False).min() >= 0.05 and np.abs(qd_min).max() < vmax:
            np.testing.assert_allclose(qd, qd_min, atol=2e-4)
            compared += 1
    assert compared >= 3


# ----------------------------------------------------------------------------- refusals
def test_refusals_name_the_argument_before_tracing():
    q = jnp.zeros(6)
    v = jnp.zeros(6)
    solve = jk.solve_tasks
    with pytest.raises(jk.ShapeError, match=r"tasks\[0\]\.velocity must have shape \(3,\)"):
        solve(UR5, q, [jk.FrameTask(None, velocity=v, rows="position")], dt=DT)
    with pytest.raises(jk.ModelError, match="has no frame 'tool0'"):
        solve(UR5, q, [jk.FrameTask("tool0", velocity=v)], dt=DT)
    with pytest.raises(jk.JaxkinError, match=r"tasks\[0\]\.rows must be one of"):
        solve(UR5, q, [jk.FrameTask(None, velocity=v, rows="linear")], dt=DT)
    with pytest.raises(jk.JaxkinError, match=r"tasks\[1\]\[0\] must be a task"):
        solve(UR5, q, [jk.FrameTask(None), (v,)], dt=DT)
    with pytest.raises(jk.JaxkinError, match="non-empty list of tasks"):
        solve(UR5, q, [], dt=DT)
    with pytest.raises(jk.JaxkinError, match=r"gain must be in \[0, 1\]"):
        solve(UR5, q, [jk.FrameTask(None, target=np.eye(4), gain=2.0)], dt=DT)
    with pytest.raises(jk.JaxkinError, match="dt must be a positive number"):
        solve(UR5, q, [jk.FrameTask(None, velocity=v)], dt=0.0)
    with pytest.raises(jk.JaxkinError, match="velocity_limits must be >= 0"):
        solve(UR5, q, [jk.FrameTask(None, velocity=v)], dt=DT, velocity_limits=-1.0)
    with pytest.raises(jk.ShapeError, match=r"velocity_limits must be one number or have shape"):
        solve(UR5, q, [jk.FrameTask(None, velocity=v)], dt=DT, velocity_limits=np.ones(5))
    with pytest.raises(jk.JaxkinError, match="damping must be >= 0"):
        solve(UR5, q, [jk.FrameTask(None, velocity=v)], dt=DT, damping=-0.1)
    with pytest.raises(jk.JaxkinError, match=r"tasks\[0\]\.velocity contains NaN or inf"):
        solve(UR5, q, [jk.FrameTask(None, velocity=v.at[0].set(jnp.nan))], dt=DT)
    with pytest.raises(jk.ShapeError, match=r"q must have shape \(6,\).*jax\.vmap"):
        solve(UR5, jnp.zeros((4, 6)), [jk.FrameTask(None, velocity=v)], dt=DT)
    with pytest.raises(jk.ModelError, match="has no inertial data"):
        solve(UR5, q, [jk.ComTask(velocity=np.zeros(3))], dt=DT)
    with pytest.raises(jk.JaxkinError, match=r"axes must be distinct letters of 'xyz'"):
        solve(HOPPER, hopper_q0(), [jk.ComTask(axes="yx")], dt=DT)
    with pytest.raises(jk.ShapeError, match=r"targets must have shape \(N, k, 4, 4\)"):
        jk.follow_paths(UR5, q, np.eye(4)[None], [None, "link3"], DT)
    with pytest.raises(jk.ShapeError, match=r"targets must have shape \(N, 4, 4\)"):
        jk.follow_paths(UR5, q, np.eye(4), None, DT)
    with pytest.raises(jk.JaxkinError, match="is not a rigid transform"):
        jk.follow_paths(UR5, q, 2 * np.eye(4)[None], None, DT)
