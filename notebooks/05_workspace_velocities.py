# %% [markdown]
# # 5. Velocities and manipulability over the whole workspace
#
# The Jacobian changes with the configuration, and so does what the end effector can do: how fast it
# can move, in which directions easily, and where it loses a direction altogether (a singularity).
# This notebook samples **100,000 configurations** of the Niryo One and, for each, computes the
# geometric Jacobian, the twist for random joint velocities, the singular values of $J$, and the
# fastest the tip can move within the joint speed limits, then maps them over the workspace.
#
# jaxkin's kernels are written for one configuration; `jax.vmap` batches them, and
# `jaxkin.batch.chunked_map` streams the rows through one compiled function in chunks and
# collects the results in numpy arrays.

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

import itertools

from jaxkin.batch import chunked_map

# %% [markdown]
# ## What is computed per configuration
#
# * the tip's position, and the wrist centre's (for the singularity study below);
# * $J(q)$, world-aligned, rows $[v; \omega]$, and the twist $J(q)\,\dot q$ for a random
#   $\dot q$ with each joint rate uniform in $[-1, 1]$ rad/s (the Niryo's speed limit);
# * the singular values $\sigma_1 \ge \dots \ge \sigma_6$ of $J$ and $\sigma^v_1 \ge \sigma^v_2 \ge
#   \sigma^v_3$ of its translational block $J_v$ (m/s per rad/s). The unit joint-speed ball maps to
#   an ellipsoid of tip velocities with these semi-axes; its volume is proportional to Yoshikawa's
#   **manipulability** $w_v = \sqrt{\det J_v J_v^T} = \sigma^v_1 \sigma^v_2 \sigma^v_3$. The ratio
#   $\sigma_6 / \sigma_1$ (inverse condition number) goes to 0 at a singularity. ($J$ mixes m/s and
#   rad/s rows, so $\sigma_6/\sigma_1$ depends on the unit of length; $w_v$ does not mix units.)
# * the fastest tip speed allowed by the joint limits $|\dot q_i| \le 1$ rad/s:
#   $\max_{|\dot q_i| \le 1} |J_v \dot q|$. A convex function's maximum over a box is at a corner,
#   so it is the largest $|J_v s|$ over the $2^6 = 64$ sign vectors $s$.

# %%
robot = jk.robots.load("niryo_one")
corners = jnp.asarray(list(itertools.product([-1.0, 1.0], repeat=robot.dof)))  # (64, 6)


def per_configuration(q, qd):
    J = jk.geometric_jacobian(robot, q)
    return {
        "p": jk.fk(robot, q)[:3, 3],
        "p_wrist": jk.fk(robot, q, frame="wrist_link")[:3, 3],
        "twist": J @ qd,
        "sigma": jnp.linalg.svd(J, compute_uv=False),
        "sigma_v": jnp.linalg.svd(J[:3], compute_uv=False),
        "v_max": jnp.max(jnp.linalg.norm(corners @ J[:3].T, axis=1)),
    }


N = 100_000  # a million or more run the same way, only longer
lower, upper = np.asarray(robot.lower), np.asarray(robot.upper)
qs = rng.uniform(lower, upper, size=(N, robot.dof))
qds = rng.uniform(-1.0, 1.0, size=(N, robot.dof))
res, stats = chunked_map(per_configuration, qs, qds, return_stats=True)
print(f"{N:,} configurations: compile {stats.compile_seconds:.1f} s, "
      f"run {stats.run_seconds:.1f} s ({stats.rate:,.0f} configurations/s)")  # fmt: skip
sigma, sigma_v = res["sigma"], res["sigma_v"]
w_v = np.prod(sigma_v, axis=1)  # translational manipulability
inv_cond = sigma[:, -1] / sigma[:, 0]
speed, turn = (
    np.linalg.norm(res["twist"][:, :3], axis=1),
    np.linalg.norm(res["twist"][:, 3:], axis=1),
)

# %% [markdown]
# A spot check of the batched results against single calls and numpy's SVD, and of the corner rule
# against the speeds actually reached by the random $\dot q$ (none may exceed $v_\text{max}$):

# %%
idx = rng.choice(N, size=200, replace=False)
J_spot = np.stack([jk.geometric_jacobian(robot, q) for q in qs[idx]])  # single calls
assert np.allclose(np.linalg.svd(np.asarray(J_spot), compute_uv=False), sigma[idx], atol=1e-12)
assert np.allclose(np.einsum("nij,nj->ni", J_spot, qds[idx]), res["twist"][idx], atol=1e-14)
assert np.all(speed <= res["v_max"] + 1e-12)
print(
    "spot checks passed; the random rates reach on average",
    f"{np.mean(speed / res['v_max']):.0%} of v_max",
)

# %% [markdown]
# ## Distributions

# %%
# histtype="stepfilled": each histogram one filled outline (cheaper to draw than 200 bars)
fig, axes = plt.subplots(2, 2, figsize=(11, 7))
axes[0, 0].hist(
    speed, bins=200, histtype="stepfilled", color="C3", alpha=0.8, label="|v|, random q̇"
)
axes[0, 0].hist(
    res["v_max"], bins=200, histtype="stepfilled", color="0.4", alpha=0.6, label="v_max (|q̇_i| ≤ 1)"
)
axes[0, 0].set(xlabel="tip speed [m/s]", ylabel="configurations", title="linear speed")
axes[0, 0].legend()
axes[0, 1].hist(turn, bins=200, histtype="stepfilled", color="C0")
axes[0, 1].set(xlabel="|ω| [rad/s]", title="angular speed, random q̇")
axes[1, 0].hist(w_v, bins=200, histtype="stepfilled", color="C4")
axes[1, 0].set(
    xlabel="w_v = σ1 σ2 σ3 of J_v  [(m/s)³ per (rad/s)³]", title="translational manipulability"
)
axes[1, 1].hist(np.log10(inv_cond), bins=200, histtype="stepfilled", color="C2")
axes[1, 1].set(
    xlabel="log10(σ6 / σ1) of J", title="distance from singularity (inverse condition number)"
)
fig.suptitle(f"Niryo One, {N:,} configurations uniform within the joint limits")
fig.tight_layout()

# %% [markdown]
# ## Maps over the workspace
#
# Joint 1 turns the whole arm about the base's vertical axis, so none of these quantities depends on
# $q_1$ or on the direction of the tip around that axis: the workspace is fully described by the
# tip's distance from the axis, $r = \sqrt{x^2 + y^2}$, and its height $z$. Each map bins the
# tip positions in $(r, z)$ and shows the mean of a quantity per bin.

# %%
p = res["p"]
r, z = np.hypot(p[:, 0], p[:, 1]), p[:, 2]
bins = [np.linspace(0, r.max(), 90), np.linspace(z.min(), z.max(), 90)]
count, re, ze = np.histogram2d(r, z, bins=bins)


def binned_mean(values):
    total, _, _ = np.histogram2d(r, z, bins=bins, weights=values)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan).T


maps = [
    (np.where(count > 0, count, np.nan).T, "configurations per bin", "viridis"),
    (binned_mean(w_v), "mean manipulability w_v", "magma"),
    (binned_mean(res["v_max"]), "mean v_max [m/s]", "plasma"),
    (binned_mean((inv_cond < 1e-2).astype(float)), "fraction near-singular (σ6/σ1 < 0.01)", "Reds"),
]
fig, axes = plt.subplots(1, 4, figsize=(16, 4.3), sharey=True)
for ax, (m, title, cmap) in zip(axes, maps, strict=True):
    im = ax.pcolormesh(re, ze, m, cmap=cmap, shading="flat")
    fig.colorbar(im, ax=ax, shrink=0.85)
    ax.set(title=title, xlabel="r = √(x² + y²) [m]", aspect="equal")
axes[0].set_ylabel("z [m]")
fig.suptitle("Niryo One workspace, half-plane through the base axis")
fig.tight_layout()

# %% [markdown]
# ## Where the singularities are
#
# Within the joint limits two families show up. **Wrist**: at $q_5 = 0$ the axes of joints 4 and 6
# line up and the wrist loses a rotation, whatever the other joints do. **Shoulder**: when the wrist
# centre (where the axes of joints 4 and 5 meet, the origin of `wrist_link`) is on the base axis,
# turning joint 1 only spins it in place. The **elbow** singularities, upper arm and forearm in line
# (stretched or folded back), lie outside the Niryo's joint-3 limits: the third panel sweeps $q_3$
# over a full turn and shows the arm's smallest singular value (joints 2 and 3 moving the wrist
# centre) reaching zero only beyond the limits.

# %%
r_wrist = np.hypot(res["p_wrist"][:, 0], res["p_wrist"][:, 1])
fig, axes = plt.subplots(1, 3, figsize=(16, 4))
for ax, x, label, title in [
    (axes[0], qs[:, 4], "q5 [rad]", "wrist singularity at q5 = 0"),
    (axes[1], r_wrist, "wrist centre's distance from the base axis [m]", "shoulder singularity"),
]:
    hb = ax.hexbin(x, np.log10(inv_cond), gridsize=80, bins="log", cmap="Greys")
    ax.set(xlabel=label, ylabel="log10(σ6 / σ1)", title=title)
    fig.colorbar(hb, ax=ax, label="configurations")

q3 = np.linspace(-np.pi, np.pi, 2001)
sweep = np.zeros((q3.size, 6))
sweep[:, 2] = q3


def arm_sigma_min(q):  # joints 2 and 3 moving the wrist centre: a 3 x 2 block
    J = jk.geometric_jacobian(robot, q, frame="wrist_link")
    return jnp.linalg.svd(J[:3, 1:3], compute_uv=False)[-1]


s_arm = jax.jit(jax.vmap(arm_sigma_min))(sweep)
axes[2].plot(q3, s_arm)
axes[2].axvspan(lower[2], upper[2], color="C2", alpha=0.15, label="joint-3 limits")
for k in np.flatnonzero(s_arm < 1e-3):
    axes[2].axvline(q3[k], color="C3", lw=0.8)
axes[2].set(
    xlabel="q3 [rad]",
    ylabel="smallest singular value [m/s per rad/s]",
    title="elbow: stretched / folded",
)
axes[2].legend()
fig.tight_layout()
print("elbow singular near q3 =", np.round(q3[s_arm < 1e-3], 3), "; limits:", lower[2], upper[2])
worst = int(np.argmin(inv_cond))
print(
    "most singular sample: q =",
    qs[worst],
    " σ =",
    sigma[worst],
    " wrist centre r =",
    r_wrist[worst],
)

# %%
best = int(np.argmax(w_v))
fig = plt.figure(figsize=(11, 5))
for i, (k, title) in enumerate(
    [(best, "largest manipulability w_v"), (worst, "most singular sample")]
):
    ax = fig.add_subplot(1, 2, i + 1, projection="3d")
    jv.plot_ellipsoid(robot, qs[k], ax=ax, frames=None)
    ax.set_title(f"{title}\nσ(J_v) = {np.round(sigma_v[k], 3)} m/s per rad/s")
