"""Derivatives of ``jk.solve_ik`` (the implicit function theorem, jaxkin.ik_gradients) against
central finite differences of re-solved IK, and TRAC-IK's protocol on a few hundred targets.

Every solve in a file goes through one compiled function per robot (``_Solver``): the JVP of a
batched ``solve_ik`` with the default settings except ``tol`` and ``damping`` (arrays, so one
compile serves the tight finite-difference solves and the default protocol) and one lane (the
answers do not depend on the lanes; one compiles cheaper). Finite differences
re-solve the perturbed targets ``T exp(+-h X_j)`` (``X_j`` the six se(3) generators) warm-started
at the solution, to ``tol = 1e-13``, Richardson-extrapolated from h = 1e-5 and 2h: what the
derivative of a redundant arm's solution is defined to be (the solution nearest to the current
one). Tolerance: 1e-6 relative (the issue's target)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _oracle_modules import lazy_module
from _xla import FAST_COMPILE, jaxpr_counts, jaxpr_eqns, sampler
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxkin as jk
from jaxkin.ik_gradients import full_rank

# SciPy (matrix exponential, rotation vectors): imported by the first test that uses it
scipy_linalg = lazy_module("scipy.linalg")
scipy_transform = lazy_module("scipy.spatial.transform")

B = 300  # every call of a solver: one batch shape, one compile
H = 1e-5
FD_TOL = 1e-13
REL = 1e-6


def _panda():
    if "erd/panda" in jk.robots.erd_names():
        return jk.robots.load("erd/panda", tip="panda_hand")
    return jk.robots.load("panda")  # pragma: no cover - example-robot-data is a test dependency


ARMS = {
    "panda": _panda,
    "ur5": lambda: jk.robots.load("ur5"),
    "niryo_one": lambda: jk.robots.load("niryo_one"),
}


def _hat(xi: np.ndarray) -> np.ndarray:
    X = np.zeros((4, 4))
    w = xi[3:]
    X[:3, :3] = [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]
    X[:3, 3] = xi[:3]
    return X


GENERATORS = np.stack([_hat(e) for e in np.eye(6)])  # (6, 4, 4), [v; omega]


@functools.cache
def _steps(h: float) -> np.ndarray:
    """``expm(h X_j)`` (6, 4, 4) for the six generators (scipy), computed once per step."""
    return np.stack([scipy_linalg.expm(h * X) for X in GENERATORS])


class _Solver:
    """``solve(T (B,4,4), q0 (B,dof), T_dot (B,4,4), tol)`` -> (IKSolution, dq), one compile."""

    def __init__(self, robot):
        self.robot = robot

        def run(T, q0, T_dot, tol, damping):
            def solve(T):
                # one lane: the same answers (the first converging start wins, whatever the
                # lanes: test_ik_defaults.py), a third cheaper to compile than 64
                sol = jk.solve_ik(robot, T, q0, tol=tol, damping=damping, lanes=1, throw=False)
                return sol.q, sol

            # only q's tangent is returned: the other fields' tangents are not compiled
            _, dq, sol = jax.jvp(solve, (T,), (T_dot,), has_aux=True)
            return sol, dq

        self.fn = jax.jit(run, compiler_options=FAST_COMPILE)

    def __call__(self, T, q0, T_dot=None, tol=FD_TOL, damping=1e-3):
        T = np.asarray(T)
        n = T.shape[0]
        assert n <= B
        pad = lambda x: np.concatenate([x, np.repeat(x[:1], B - n, 0)], 0)  # noqa: E731
        T_dot = np.zeros_like(T) if T_dot is None else np.asarray(T_dot)
        q0 = np.broadcast_to(np.asarray(q0), (n, self.robot.dof))
        sol, dq = self.fn(pad(T), pad(q0), pad(T_dot), jnp.asarray(tol), jnp.asarray(damping))
        cut = lambda x: np.asarray(x)[:n]  # noqa: E731
        return jax.tree_util.tree_map(cut, sol), cut(dq)


@pytest.fixture(scope="module")
def solvers():
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = _Solver(ARMS[name]())
        return cache[name]

    return get


def _poses(robot, qs) -> np.ndarray:
    return np.stack([np.asarray(jk.fk(robot, q)) for q in np.asarray(qs)])


def _wrap(d: np.ndarray) -> np.ndarray:
    return (d + np.pi) % (2 * np.pi) - np.pi


def _derivatives(solver, T, q0):
    """Per target: (solution, the (6 directions, dof) derivative, its finite differences)."""
    n, dof = T.shape[0], solver.robot.dof
    Tk = np.repeat(T, 6, 0)  # target i, direction j at row 6 i + j
    sol, dq = solver(Tk, np.repeat(q0, 6, 0), Tk @ np.tile(GENERATORS, (n, 1, 1)))
    q = sol.q[::6]
    qs = np.repeat(q, 6, 0)
    ok = np.ones(n, bool)
    fds = []
    for h in (2 * H, H):  # Richardson: (4 D(h) - D(2h)) / 3 cancels the h^2 term
        plus = np.stack([T[i] @ E for i in range(n) for E in _steps(h)])
        minus = np.stack([T[i] @ E for i in range(n) for E in _steps(-h)])
        # Gauss-Newton from the solution (damping at its floor): one smooth path for +h and -h
        both, _ = solver(np.concatenate([plus, minus]), np.concatenate([qs, qs]), damping=1e-12)
        ok &= (both.residual <= FD_TOL).reshape(2, n, 6).all(axis=(0, 2))
        fds.append(_wrap(both.q[: 6 * n] - both.q[6 * n :]) / (2 * h))
    fd = (4 * fds[1] - fds[0]) / 3
    return sol, q, dq.reshape(n, 6, dof), fd.reshape(n, 6, dof), ok


def _random_targets(robot, seed: int, n: int, at_limit: int | None = None):
    rng = np.random.default_rng(seed)
    lo, hi = (np.asarray(b) for b in jk.sampling_bounds(robot))
    q_star = rng.uniform(lo + 0.05, hi - 0.05, (n, robot.dof))
    if at_limit is not None:
        q_star[:, at_limit] = np.asarray(robot.upper)[at_limit]
    return q_star, _poses(robot, q_star)


def _jacobians(robot, qs) -> np.ndarray:
    return np.stack([np.asarray(jk.geometric_jacobian(robot, q)) for q in qs])


def _twists(T: np.ndarray) -> np.ndarray:
    """(n, 6 directions, 6): the world-aligned change of the target's pose, [v; omega], along
    ``T X_j`` (a body twist e_j moves the origin by R v and turns by R omega in world axes)."""
    Ad = np.zeros((T.shape[0], 6, 6))
    Ad[:, :3, :3] = T[:, :3, :3]
    Ad[:, 3:, 3:] = T[:, :3, :3]
    return np.swapaxes(Ad, 1, 2)


WELL_CONDITIONED = 100.0
"""Finite differences (h = 1e-5) are compared where cond(J) <= 100: nearer a singularity the
derivative grows like 1/s_min and the central difference's h^2 term like 1/s_min^3 (a Panda
solution with cond(J) = 700 differs by 7e-3 at h = 1e-5, and J fd != b there while the returned
derivative satisfies J dq = b to 1e-13; a UR5 solution with the elbow at 1e-3 rad from straight
has perturbed targets outside the workspace). Every solution is checked against J dq = b."""


ARM_PARAMS = [
    "panda",
    "ur5",
    "niryo_one",
]


@pytest.mark.parametrize("name", ARM_PARAMS)
@settings(max_examples=2)
@given(seed=st.integers(0, 2**31 - 1))
def test_target_derivative_matches_finite_differences(solvers, name, seed):
    solver = solvers(name)
    robot = solver.robot
    n = B // 12
    q_star, T = _random_targets(robot, seed, n)
    rng = np.random.default_rng(seed + 1)
    q0 = np.clip(q_star + 0.05 * rng.standard_normal(q_star.shape), robot.lower, robot.upper)
    sol, q, dq, fd, fd_ok = _derivatives(solver, T, q0)
    assert np.all(sol.converged) and not np.any(sol.singular)
    J = _jacobians(robot, q)
    b = _twists(T)
    # the implicit function theorem's equation, closed form: J dq = b for each direction
    assert np.max(np.abs(np.einsum("nij,ndj->ndi", J, dq) - b)) <= 1e-9
    if robot.dof > 6:  # minimum norm: dq lies in the row space of J
        P = np.stack([np.linalg.pinv(Ji) @ Ji for Ji in J])
        assert np.max(np.abs(np.einsum("nij,ndj->ndi", P, dq) - dq)) <= 1e-9
    s = np.linalg.svd(J, compute_uv=False)
    good = s[:, 0] / s[:, -1] <= WELL_CONDITIONED
    assert np.sum(good) >= n // 2, np.sum(good)
    assert np.all(fd_ok[good])  # the perturbed targets were all re-solved to 1e-13
    scale = np.max(np.abs(fd), axis=(1, 2), keepdims=True)
    err = np.max(np.abs(dq - fd) / scale, axis=(1, 2))
    assert np.max(err[good]) <= REL, (name, err[good])


def test_active_limit_holds_the_joint(solvers):
    """Panda joint 4 at its upper limit in every solution (started there): its derivative is 0
    and the other six take the reduced Jacobian's inverse; Niryo One joint 5 at its limit (a
    6-dof arm with 5 free joints): the least-squares derivative (numpy lstsq)."""
    for name, k in (("panda", 3), ("niryo_one", 4)):
        solver = solvers(name)
        robot = solver.robot
        q_star, T = _random_targets(robot, 7, 10, at_limit=k)
        sol, q, dq, _ = _derivatives_no_fd(solver, T, q_star)
        assert np.all(q[:, k] == np.asarray(robot.upper)[k])
        assert np.all(sol.converged) and np.all(dq[:, :, k] == 0.0)
        free = np.arange(robot.dof) != k
        for Ji, bi, dqi in zip(_jacobians(robot, q), _twists(T), dq, strict=True):
            ref = np.linalg.lstsq(Ji[:, free], bi.T, rcond=None)[0].T
            np.testing.assert_allclose(dqi[:, free], ref, rtol=0, atol=1e-9 * np.max(abs(ref)))


def _held_newton(robot, T_goal, q, k):
    """The oracle for a joint held at its limit: Gauss-Newton on the other joints (numpy lstsq on
    jk.geometric_jacobian, orientation error from scipy's rotation vector), joint k frozen."""
    q = np.array(q, dtype=np.float64)
    free = np.arange(robot.dof) != k
    for _ in range(20):
        Tq = np.asarray(jk.fk(robot, q))
        e = np.concatenate(
            [
                T_goal[:3, 3] - Tq[:3, 3],
                scipy_transform.Rotation.from_matrix(T_goal[:3, :3] @ Tq[:3, :3].T).as_rotvec(),
            ]
        )
        if np.max(np.abs(e)) <= 1e-14:
            break
        J = np.asarray(jk.geometric_jacobian(robot, q))
        q[free] += np.linalg.lstsq(J[:, free], e, rcond=None)[0]
    return q, np.max(np.abs(e))


def test_active_limit_matches_finite_differences_of_the_held_arm(solvers):
    """Panda joint 1 held at its upper limit: the derivative of the solution equals central
    differences (Richardson, h = 1e-5 and 2h) of the arm re-solved with that joint frozen (an
    independent Gauss-Newton in numpy), joint 1's derivative exactly 0; 1e-6 relative, where
    the six free columns are well conditioned."""
    k = 0  # (joint 4's upper limit, -4 degrees, is a nearly straight elbow: singular)
    solver = solvers("panda")
    robot = solver.robot
    q_star, T = _random_targets(robot, 11, 12, at_limit=k)
    sol, q, dq, _ = _derivatives_no_fd(solver, T, q_star)
    assert np.all(sol.converged) and not np.any(sol.singular)
    assert np.all(q[:, k] == np.asarray(robot.upper)[k]) and np.all(dq[:, :, k] == 0.0)
    free = np.arange(robot.dof) != k
    s = np.linalg.svd(_jacobians(robot, q)[:, :, free], compute_uv=False)
    good = np.flatnonzero(s[:, 0] / s[:, -1] <= WELL_CONDITIONED)[:4]  # see WELL_CONDITIONED
    assert good.size >= 2, s[:, 0] / s[:, -1]
    for i in good:
        fds = []
        for h in (2 * H, H):
            d = []
            for E_plus, E_minus in zip(_steps(h), _steps(-h), strict=True):
                plus, res_p = _held_newton(robot, T[i] @ E_plus, q[i], k)
                minus, res_m = _held_newton(robot, T[i] @ E_minus, q[i], k)
                assert max(res_p, res_m) <= 1e-13
                d.append((plus - minus) / (2 * h))
            fds.append(np.stack(d))
        fd = (4 * fds[1] - fds[0]) / 3
        np.testing.assert_allclose(dq[i], fd, rtol=0, atol=REL * np.max(np.abs(fd)))


def _derivatives_no_fd(solver, T, q0):
    n, dof = T.shape[0], solver.robot.dof
    Tk = np.repeat(T, 6, 0)
    sol, dq = solver(Tk, np.repeat(q0, 6, 0), Tk @ np.tile(GENERATORS, (n, 1, 1)))
    return sol, sol.q[::6], dq.reshape(n, 6, dof), None


def test_singular_and_unconverged_give_finite_derivatives_and_flags(solvers):
    """UR5 at its wrist (q5 = 0) and elbow (q3 = 0) singularities, started exactly there:
    converged, flagged singular, finite derivatives; a target 3 m away: not converged, finite."""
    solver = solvers("ur5")
    robot = solver.robot
    q_wrist = np.array([0.3, -1.0, 1.2, -0.5, 0.0, 0.4])
    q_elbow = np.array([0.3, -1.0, 0.0, -0.5, 1.0, 0.4])
    far = np.eye(4)
    far[:3, 3] = [3.0, 0.0, 0.5]
    T = np.stack([_poses(robot, [q_wrist])[0], _poses(robot, [q_elbow])[0], far])
    q0 = np.stack([q_wrist, q_elbow, q_wrist])
    Tk = np.repeat(T, 6, 0)
    sol, dq = solver(Tk, np.repeat(q0, 6, 0), Tk @ np.tile(GENERATORS, (3, 1, 1)), tol=1e-10)
    assert np.all(np.isfinite(dq)) and np.all(np.isfinite(sol.q))
    np.testing.assert_array_equal(sol.converged, np.repeat([True, True, False], 6))
    np.testing.assert_array_equal(sol.singular[:12], True)
    assert np.all(sol.result[12:] == jk.ik.RESULTS.unreachable)
    # well away from the singularities the flag is off (the random targets above assert it too)
    assert np.max(np.abs(dq[:12])) > 1.0  # the damped derivative is large there, not zero


# ----------------------------------------------------------------------------- TRAC-IK protocol
@pytest.mark.parametrize("name", ARM_PARAMS)
def test_trac_ik_protocol_small(solvers, name):
    """TRAC-IK's protocol on 300 targets: random configurations within the limits -> fk, one
    seed at the middle of the limits, default arguments (tolerance 1e-10 in float64, 64 starts),
    success = every position and orientation component within 1e-5 (checked with numpy on
    jk.fk) and the joints within limits. Asserted: no failure on these 300 fixed targets (the
    full 10,000-target protocol is in bench/). At each solution, derivatives are finite and
    satisfy J dq = b."""
    solver = solvers(name)
    robot = solver.robot
    rng_key = jax.random.key(2024)
    q_star = np.asarray(sampler(robot, B)(rng_key))
    T = _poses(robot, q_star)
    lo, hi = (np.asarray(b) for b in jk.sampling_bounds(robot))
    mid = 0.5 * (lo + hi)
    T_dot = T @ GENERATORS[np.arange(B) % 6]
    sol, dq = solver(T, mid, T_dot, tol=1e-10)
    Tq = _poses(robot, sol.q)
    dp = np.abs(Tq[:, :3, 3] - T[:, :3, 3])
    M = T[:, :3, :3] @ np.swapaxes(Tq[:, :3, :3], 1, 2)
    dw = 0.5 * np.abs(np.stack([M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0],
                                M[:, 1, 0] - M[:, 0, 1]], 1))  # fmt: skip
    angle_ok = np.einsum("nii->n", M) > 1.0  # the rotation angle is below pi / 2
    within = np.all((sol.q >= np.asarray(robot.lower)) & (sol.q <= np.asarray(robot.upper)), 1)
    ok = np.all(dp <= 1e-5, 1) & np.all(dw <= 1e-5, 1) & angle_ok & within
    assert int(np.sum(~ok)) == 0, (name, np.flatnonzero(~ok), sol.result[~ok])
    np.testing.assert_array_equal(sol.converged, ok)
    assert np.all(np.isfinite(dq))
    J = _jacobians(robot, sol.q)
    b = _twists(T)[np.arange(B), np.arange(B) % 6]
    regular = ~sol.singular
    res = np.einsum("nij,nj->ni", J, dq) - b
    assert np.max(np.abs(res[regular])) <= 1e-8 * max(1.0, np.max(np.abs(dq[regular])))


# ----------------------------------------------------------------------------- robot parameters
def _ur5_with_tool(offset) -> jk.Robot:
    """The UR5's DH table (jaxkin.robots.industrial.ur5) with a tool T_flange_tool = Tz(offset)."""
    rows = [
        dict(a=0.0, alpha=np.pi / 2, d=0.089159, theta=0.0, joint="revolute"),
        dict(a=-0.425, alpha=0.0, d=0.0, theta=0.0, joint="revolute"),
        dict(a=-0.39225, alpha=0.0, d=0.0, theta=0.0, joint="revolute"),
        dict(a=0.0, alpha=np.pi / 2, d=0.10915, theta=0.0, joint="revolute"),
        dict(a=0.0, alpha=-np.pi / 2, d=0.09465, theta=0.0, joint="revolute"),
        dict(a=0.0, alpha=0.0, d=0.0823, theta=0.0, joint="revolute"),
    ]
    for r in rows:
        r.update(lower=-2 * np.pi, upper=2 * np.pi)
    tool = np.eye(4)
    tool[:3, 3] = offset
    return jk.Robot.from_dh(rows, convention="standard", tool=tool)


def _calibration_loss(robot, T, q_measured):
    """Sum of squared differences between IK solutions (warm-started at the measured angles)
    and the measured angles; robot traced: derivatives by the implicit function theorem. One
    lane, as ``_Solver``'s: the same answers, about a sixth cheaper to compile than 8."""
    sol = jk.solve_ik(
        robot, T, q_measured, num_seeds=1, max_steps=100, tol=FD_TOL, lanes=1, throw=False
    )
    return jnp.sum((sol.q - q_measured) ** 2), sol.converged


@pytest.fixture(scope="module")
def calibration():
    """A UR5 whose true tool offset is (0.01, -0.02, 0.12) m, 8 measured configurations, their
    poses (what a tracker measures) and the compiled value-and-gradient over the robot."""
    true = _ur5_with_tool([0.01, -0.02, 0.12])
    rng = np.random.default_rng(5)
    q_measured = rng.uniform(-2.5, 2.5, (8, 6))
    q_measured[:, 1] = rng.uniform(-2.0, -1.0, 8)  # upper arm up: targets well within reach
    q_measured[:, 2] = rng.uniform(0.5, 2.0, 8) * rng.choice([-1, 1], 8)  # away from the elbow
    q_measured[:, 4] = rng.uniform(0.5, 2.5, 8) * rng.choice([-1, 1], 8)  # and wrist singularity
    T = _poses(true, q_measured)
    loss_and_grad = jax.value_and_grad(_calibration_loss, has_aux=True)
    vg = jax.jit(loss_and_grad, compiler_options=FAST_COMPILE)
    return true, T, q_measured, vg


def test_gradient_with_respect_to_the_robot_matches_finite_differences(calibration):
    _, T, q_measured, vg = calibration
    robot = _ur5_with_tool([0.0, 0.0, 0.1])
    # values on the host and perturbed robots built from numpy leaves: each eager JAX operation
    # (an .at[].add, a difference of two results) compiled a program of its own
    (value, conv), g = jax.device_get(vg(robot, T, q_measured))
    assert np.all(conv) and np.isfinite(value) and value > 0
    assert isinstance(g, jk.Robot)  # jax.grad(loss)(robot): a robot of gradients
    leaves = jax.tree_util.tree_leaves(g)
    assert all(np.all(np.isfinite(x)) for x in leaves)

    def central(change):  # Richardson-extrapolated central differences, h = 1e-5 and 2e-5
        d = []
        for h in (2 * H, H):
            (vp, cp), _ = jax.device_get(vg(change(h), T, q_measured))
            (vm, cm), _ = jax.device_get(vg(change(-h), T, q_measured))
            assert np.all(cp) and np.all(cm)
            d.append((vp - vm) / (2 * h))
        return (4 * d[1] - d[0]) / 3

    def added(x, index, h):  # x + h at index, a numpy leaf of x's dtype
        x = np.array(x)
        x[index] += h
        return x

    for k in range(3):  # the tool offset
        fd = central(lambda h, k=k: robot.replace(tool=added(robot.tool, (k, 3), h)))
        assert abs(g.tool[k, 3] - fd) <= REL * abs(fd), (k, g.tool[k, 3], fd)
    d = robot.params["d"]  # a DH parameter: d of joint 1
    fd = central(lambda h: robot.replace(params={**robot.params, "d": added(d, 0, h)}))
    assert abs(g.params["d"][0] - fd) <= REL * abs(fd), (g.params["d"][0], fd)


def test_calibration_through_ik_recovers_the_tool_offset(calibration):
    """The example of jaxkin.ik_gradients: fit the tool offset from measured joint angles at
    known poses, gradients through solve_ik, optax's L-BFGS directions (steps capped at 2 mm);
    the true offset comes back to 1e-6 m and the loss to ~0."""
    import optax

    true, T, q_measured, vg = calibration
    p = jnp.array([0.0, 0.0, 0.1])  # nominal offset, 3 cm from the true one
    opt = optax.chain(optax.scale_by_lbfgs(), optax.clip_by_global_norm(2e-3), optax.scale(-1.0))
    state = opt.init(p)

    @jax.jit  # one compile (optax's L-BFGS update called eagerly traces its scans every step)
    def lbfgs_step(g, state, p):
        updates, state = opt.update(g.tool[:3, 3], state, p)
        return optax.apply_updates(p, updates), state

    for _ in range(60):
        robot = true.replace(tool=true.tool.at[:3, 3].set(p))
        (value, conv), g = vg(robot, T, q_measured)
        p, state = lbfgs_step(g, state, p)
    assert np.all(conv), (p, value, conv)
    np.testing.assert_allclose(p, true.tool[:3, 3], rtol=0, atol=1e-6)
    assert value < 1e-10


# ----------------------------------------------------------------------------- float32, jit, vmap
def test_float32_jacrev_under_jit_and_vmap(solvers):
    """``jit(vmap(jacrev(solve_ik(...).q)))`` on a float32 UR5: float32 derivatives, equal to the
    float64 ones within what a float32 solution allows (residual <= 1e-5, the float32 default
    tol: q is off by up to about 1e-5 / s_min, and dq by that times its own derivative)."""
    solver = solvers("ur5")
    r64 = solver.robot
    r32 = jk.robots.load("ur5", dtype=np.float32)
    q_star, T = _random_targets(r64, 11, 8)
    J = _jacobians(r64, q_star)
    s = np.linalg.svd(J, compute_uv=False)
    keep = s[:, 0] / s[:, -1] <= 30.0
    q_star, T = q_star[keep][:4], T[keep][:4]
    n = len(T)
    assert n >= 2
    q0 = q_star + 0.05
    jac = jax.jit(
        jax.vmap(jax.jacrev(lambda T, q0: jk.solve_ik(r32, T, q0, throw=False).q)),
        compiler_options=FAST_COMPILE,
    )
    D = jac(T.astype(np.float32), q0.astype(np.float32))  # (n, 6, 4, 4)
    assert D.dtype == jnp.float32 and D.shape == (n, 6, 4, 4)
    T_dot = T[:, None] @ GENERATORS[None]  # (n, 6 directions, 4, 4)
    dq32 = np.einsum("nkab,ndab->ndk", np.asarray(D, np.float64), T_dot)
    sol, dq64 = solver(np.repeat(T, 6, 0), np.repeat(q0, 6, 0), T_dot.reshape(-1, 4, 4))
    dq64 = dq64.reshape(n, 6, 6)
    assert np.all(sol.converged)
    scale = np.max(np.abs(dq64))
    np.testing.assert_allclose(dq32, dq64, rtol=0, atol=1e-3 * scale)


def test_a_derivative_traces_the_loops_once(monkeypatch):
    """The solver's loops are traced once under ``jvp`` (and ``grad``): the derivative rule
    reuses the loops' answer instead of tracing the solve a second time (a whole-body build
    spent a third of its tracing there). Tracing only, no compile; a robot of this test's own
    (no cached trace)."""
    arm, T = _two_link("traced_once")
    calls = []
    queue = jk.ik._lm_queue
    monkeypatch.setattr(jk.ik, "_lm_queue", lambda *a, **k: calls.append(1) or queue(*a, **k))

    def q_of(T):
        return jk.solve_ik(arm, T, jnp.zeros(2), num_seeds=1, throw=False).q

    jaxpr = jax.make_jaxpr(lambda T: jax.jvp(q_of, (T,), (T,)))(T)
    assert len(calls) == 1
    # inside the caller's trace the solve is traced inline: a nested jit of it would be traced
    # again by jvp for its tangents (every operation of the loops a second time)
    assert not [e for e in jaxpr.jaxpr.eqns if e.params.get("name") == "_solve_batch_impl"]
    jax.make_jaxpr(jax.grad(lambda T: jnp.sum(q_of(T))))(np.stack([T, T]))  # a new shape
    assert len(calls) == 2


def _two_link(name: str):
    """A planar two-link DH arm of its own name (no cached trace) and the pose of its tip at
    q = (0.3, -0.5), written out (no kernel compiled)."""
    rows = [dict(a=0.4, alpha=0.0, d=0.0, theta=0.0, joint="revolute", lower=-3, upper=3)] * 2
    arm = jk.Robot.from_dh(rows, name=name, dtype=np.float64)
    T = np.eye(4)
    c, s = np.cos(-0.2), np.sin(-0.2)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = 0.4 * np.array([np.cos(0.3) + c, np.sin(0.3) + s])
    return arm, T


def test_a_robot_gradient_sums_the_targets_once_per_leaf():
    """The gradient with respect to a traced robot over a batch of targets sums the targets'
    cotangents once per leaf of the robot, not once per scalar that the kinematics reads (97
    sums of two targets for this arm, each of which XLA fused with its own copy of the pass: a
    UR5's gradient over 8 targets compiled in 10.2 s instead of 5.8). Tracing only."""
    arm, T = _two_link("summed_per_leaf")

    def loss(robot):
        sol = jk.solve_ik(robot, np.stack([T, T]), jnp.zeros(2), num_seeds=1, throw=False)
        return jnp.sum(sol.q)

    sums = [
        (e.invars[0].aval.shape, e.outvars[0].aval.shape)
        for e in jaxpr_eqns(jax.grad(loss), arm)
        if e.primitive.name == "reduce_sum"
    ]
    assert sums.count(((2,), ())) < 20, sums


# ----------------------------------------------------------------------------- the rank test
def test_full_rank_factorises_one_gram_matrix():
    """``full_rank`` (the ``singular`` flag of every solve) factorises one Gram matrix, padded
    to max(m, n): it unrolled both the 6 x 6 and the n x n Cholesky (13 square roots for a 6 x 7
    Jacobian instead of 7), about half a CPU second of every solver's build. The decisions, on both
    sides of the switch between the two (5 or 7 free columns), match the singular values'."""
    rng = np.random.default_rng(3)
    J = rng.normal(size=(6, 7))
    none, two = np.zeros(7, bool), np.arange(7) >= 5
    assert jaxpr_counts(full_rank, J, none)["sqrt"] == 7
    equal_cols = J.copy()
    equal_cols[:, 1] = equal_cols[:, 0]
    equal_rows = J.copy()
    equal_rows[5] = equal_rows[4]
    cases = [(J, none), (J, two), (equal_cols, none), (equal_cols, two)]
    cases += [(equal_rows, none), (equal_rows, two)]
    rank = jax.jit(jax.vmap(full_rank), compiler_options=FAST_COMPILE)
    got = np.asarray(rank(np.stack([c[0] for c in cases]), np.stack([c[1] for c in cases])))
    for (Ji, held), ok in zip(cases, got, strict=True):
        s = np.linalg.svd(Ji[:, ~held], compute_uv=False)
        r = min(6, int(np.sum(~held)))
        want = s[r - 1] ** 2 > np.finfo(float).eps * np.sum(Ji[:, ~held] ** 2)
        assert ok == want, (held, s)
    np.testing.assert_array_equal(got, [True, True, True, False, False, True])
