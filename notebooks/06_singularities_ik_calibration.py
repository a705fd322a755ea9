# %% [markdown]
# # 6. Singularities, inverse velocity, inverse kinematics and calibration
#
# The chapter stops at $V = J(q)\,\dot q$. This notebook runs it backwards and uses it: how close a
# configuration is to a singularity (manipulability), which joint velocities produce a desired twist
# (and what goes wrong near a singularity), how to reach a pose (inverse kinematics), and how to
# correct a robot's model from measured poses (calibration). Everything is for the Niryo One.
#
# The functions live in `jaxkin.analysis`, `jaxkin.inverse_velocity`, `jaxkin.ik` and
# `jaxkin.calibration`.

# %%
import jax

jax.config.update("jax_enable_x64", True)  # float64 for this notebook
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import jaxkin as jk
import jaxkin.viz as jv

np.set_printoptions(precision=4, suppress=True, linewidth=110)
rng = np.random.default_rng(0)

from jaxkin import analysis, calibration, ik
from jaxkin import inverse_velocity as iv

robot = jk.robots.load("niryo_one")


def fk_each(robot, qs):
    """(n, 4, 4) poses of the rows of qs, one jk.fk call each: the kernel jk.fk compiles for one
    configuration of a robot serves every row, however many (a jax.vmap over the rows would be
    compiled again for each number of rows)."""
    return np.stack([np.asarray(jk.fk(robot, q)) for q in np.asarray(qs)])


# %% [markdown]
# ## Measures of manipulability
#
# With $\sigma_1 \ge \dots \ge \sigma_m$ the singular values of (rows of) $J$: Yoshikawa's
# $w = \sqrt{\det J J^T} = \prod_i \sigma_i$ (the velocity ellipsoid's volume, up to a constant),
# the
# inverse condition number $\sigma_m / \sigma_1$ and the smallest singular value $\sigma_m$. All
# three vanish at a singularity. Below, joint 5 sweeps through the Niryo's wrist singularity
# $q_5 = 0$ (joints 4 and 6 aligned); the translational measure (rows $v$ only) does not notice it,
# since aligning two wrist axes costs a rotation, not a translation.

# %%
q_ref = np.array([0.0, -0.3, 0.2, 0.4, 0.6, 0.1])
q5 = np.linspace(-0.6, 0.6, 241)
qs = np.tile(q_ref, (q5.size, 1))
qs[:, 4] = q5
CASES = [
    ("yoshikawa", "all"),
    ("inverse_condition", "all"),
    ("min_singular_value", "all"),
    ("yoshikawa", "translation"),
]


def measures(q):
    J = jk.geometric_jacobian(robot, q)
    return jnp.stack([analysis.manipulability(J, m, rows=r) for m, r in CASES])


M = np.asarray(jax.jit(jax.vmap(measures))(qs))
fig, ax = plt.subplots(figsize=(7, 4))
for k, (m, r) in enumerate(CASES):
    ax.plot(q5, M[:, k] / M[:, k].max(), ls=["-", "--", ":", "-"][k], lw=2, label=f"{m} ({r} rows)")
ax.set(
    xlabel="q5 [rad]",
    ylabel="measure / its maximum on the sweep",
    title="Niryo One, wrist singularity at q5 = 0",
)
ax.legend(fontsize=8)

q_sing = q_ref.copy()
q_sing[4] = 0.0
dep = analysis.dependent_columns(jk.geometric_jacobian(robot, q_sing))
print(
    "at q5 = 0: nullity",
    int(dep.nullity),
    "; dependent joints:",
    [n for n, m in zip(robot.joint_names, dep.mask, strict=True) if m],
)
print("null-space joint velocity (moves nothing):", np.round(np.asarray(dep.null_space[:, 0]), 4))

# %% [markdown]
# ## Inverse velocity: which $\dot q$ gives a desired twist?
#
# For a square, invertible $J$ the answer is $\dot q = J^{-1} V$; in general the pseudo-inverse
# $\dot q = J^+ V$ gives the least-squares, minimum-norm solution. Near a singularity $J^+$ has a
# huge singular value $1/\sigma_6$, so a twist with any component along the lost direction asks for
# enormous joint speeds. **Damped least squares**,
# $\dot q = J^T (J J^T + \lambda^2 I)^{-1} V$, trades a small twist error for bounded speeds
# ($|\dot q| \le |V| / 2\lambda$). The desired twist here turns the gripper about world $x$ at
# 0.1 rad/s, a direction the wrist loses at $q_5 = 0$. (Exactly at $q_5 = 0$ the pseudo-inverse
# drops the lost direction, its singular value being below `rcond`, so its speed falls back:
# the pseudo-inverse is discontinuous at the singularity; damped least squares is smooth.)

# %%
V = jnp.array([0.0, 0.0, 0.0, 0.1, 0.0, 0.0])


def inverse(q):
    J = jk.geometric_jacobian(robot, q)
    qd_pinv = iv.pinv_velocity(J, V, rcond=1e-12)
    qd_dls = iv.damped_least_squares(J, V, damping=0.02)
    return jnp.linalg.norm(qd_pinv), jnp.linalg.norm(qd_dls), jnp.linalg.norm(J @ qd_dls - V)


n_pinv, n_dls, err_dls = (np.asarray(x) for x in jax.jit(jax.vmap(inverse))(qs))
fig, ax = plt.subplots(figsize=(7, 4))
ax.semilogy(q5, n_pinv, label="|q̇|, pseudo-inverse")
ax.semilogy(q5, n_dls, label="|q̇|, damped least squares (λ = 0.02)")
ax.semilogy(q5, err_dls, "--", label="twist error of damped least squares")
ax.set(
    xlabel="q5 [rad]",
    ylabel="rad/s",
    title="Joint speeds for ω = 0.1 rad/s about x, near the wrist singularity",
)
ax.legend(fontsize=8)
plt.show()

# %% [markdown]
# **Resolved-rate control** integrates this: at each step, $\dot q = J^{\#}(V_\text{path} + K e)$
# with $e$ the pose error, then $q \leftarrow q + \dot q\, \Delta t$. The gripper follows a 10 cm
# straight line in 2 s:

# %%
T_start = np.asarray(jk.fk(robot, q_ref))
s = np.linspace(0.0, 1.0, 201)
T_path = np.repeat(T_start[None], s.size, axis=0)
T_path[:, 1, 3] += 0.1 * s  # 10 cm along y
T_path[:, 2, 3] -= 0.05 * s  # and 5 cm down
run = iv.resolved_rate_control(robot, q_ref, T_path, dt=0.01)
tip = fk_each(robot, run.q)[:, :3, 3]
print(f"largest tracking error: {float(run.max_position_error) * 1e3:.3f} mm,",
      f"{float(run.max_orientation_error):.1e} rad")  # fmt: skip
fig = plt.figure(figsize=(10, 4.5))
ax = fig.add_subplot(1, 2, 1, projection="3d")
jv.plot_robot(
    robot, run.q[-1], ax=ax, frames=None, title="resolved-rate control: path and final pose"
)
ax.plot(*T_path[:, :3, 3].T, "k--", lw=2, label="desired path")
ax.plot(*tip.T, color="C4", lw=1.5, label="reached")
ax.legend(fontsize=8)
ax = fig.add_subplot(1, 2, 2)
ax.plot(s * 2.0, np.asarray(run.qd))
ax.set(xlabel="t [s]", ylabel="q̇ [rad/s]", title="joint velocities")
ax.legend(robot.joint_names, fontsize=7)
fig.tight_layout()

# %% [markdown]
# ## Inverse kinematics
#
# `ik.solve_ik` finds $q$ with $\mathrm{fk}(q) = T_\text{target}$ within the joint limits
# (Levenberg-Marquardt steps $\Delta q = (J^T J + \lambda I)^{-1} J^T e$, restarted from random
# seeds
# when one stalls), for one target or a batch in one compiled loop. Targets here are poses of random
# reachable configurations; the solver starts from all joints at zero and is checked by forward
# kinematics.

# %%
q_true = rng.uniform(0.8 * np.asarray(robot.lower), 0.8 * np.asarray(robot.upper), size=(50, 6))
targets = fk_each(robot, q_true)
sol = ik.solve_ik(robot, targets, np.zeros(6), num_seeds=8, throw=False)
converged = np.asarray(sol.converged)
reached = fk_each(robot, sol.q)
pos_err = np.linalg.norm(reached[:, :3, 3] - targets[:, :3, 3], axis=1)
print(f"converged: {converged.sum()} of {len(converged)};",
      f"position error of those: max {pos_err[converged].max():.1e} m")  # fmt: skip
print(
    "result codes of the others:",
    [ik.RESULTS(int(r)).name for r in np.asarray(sol.result)[~converged]],
)
same = np.all(np.abs(np.asarray(sol.q) - q_true) < 1e-6, axis=1)
print(f"solutions equal to the configuration the target came from: {same.sum()}",
      "(the others are other branches: elbow, wrist flips)")  # fmt: skip

# %% [markdown]
# ## Calibration
#
# A real robot differs from its drawing by fractions of a millimetre. Calibration measures the
# gripper's pose at several configurations (with a laser tracker, say) and fits the model's
# parameters to the measurements, differentiating straight through forward kinematics (the model's
# numbers are leaves of a JAX pytree). First `calibration.identifiability` asks which parameters
# the measurements can determine at all: offsets along a joint's own axis, for example, cannot be
# told apart from offsets of the next link. Then we make a "true" robot by perturbing only the
# identifiable link offsets by about a millimetre, measure it at 40 configurations with 20 µm of
# noise, and fit:

# %%
q_meas = rng.uniform(np.asarray(robot.lower), np.asarray(robot.upper), size=(40, 6))
ident = calibration.identifiability(robot, q_meas, ["xyz"])
print(f"link offsets xyz: {len(ident.names)} numbers, rank {ident.rank};",
      f"not identifiable: {ident.unidentifiable}")  # fmt: skip
free = np.ones(np.shape(robot.params["xyz"]), dtype=bool)
for name in ident.unidentifiable:  # e.g. "xyz[1, 2]"
    i, j = (int(x) for x in name[4:-1].split(","))
    free[i, j] = False

xyz_true = np.asarray(robot.params["xyz"]) + np.where(free, rng.normal(0.0, 1e-3, free.shape), 0.0)
true_robot = robot.replace(params={**robot.params, "xyz": jnp.asarray(xyz_true)})
T_meas = fk_each(true_robot, q_meas)
T_meas[:, :3, 3] += rng.normal(0.0, 20e-6, (40, 3))  # tracker noise, 20 um

fit = calibration.calibrate(
    robot, q_meas, T_meas, {"xyz": free}, position_sigma=20e-6, orientation_sigma=1e-3
)
err_before = np.abs(np.asarray(robot.params["xyz"]) - xyz_true)[free]
err_after = np.abs(np.asarray(fit.params["xyz"]) - xyz_true)[free]
print(f"converged {bool(fit.converged)} in {int(fit.steps)} steps")
before, after = float(fit.rms_position_before) * 1e3, float(fit.rms_position_after) * 1e3
print(f"rms position error: {before:.3f} mm -> {after:.4f} mm",
      f"(the noise alone: {20e-3 * np.sqrt(3):.4f} mm in 3-D)")  # fmt: skip
print(f"parameter error: max {err_before.max() * 1e3:.3f} mm -> {err_after.max() * 1e3:.4f} mm; "
      f"predicted std up to {np.asarray(fit.std['xyz'])[free].max() * 1e3:.4f} mm")  # fmt: skip
