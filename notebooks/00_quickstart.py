# %% [markdown]
# # jaxkin quick start: how fast does the end effector move?
#
# Given a manipulator and its joint velocities $\dot q$, the end effector's twist is $V = [v;
# \omega] = J(q)\,\dot q$. This notebook computes $J$ for the Niryo One two ways (the hand-built
# geometric Jacobian of the chapter's Table 4.1, and `jax.jacfwd` of forward kinematics), checks
# they agree, and batches the computation over many configurations.

# %%
import jax

jax.config.update("jax_enable_x64", True)  # float64 for this notebook
import jax.numpy as jnp
import numpy as np

import jaxkin as jk

np.set_printoptions(precision=4, suppress=True)
robot = jk.robots.load("niryo_one")
robot

# %% [markdown]
# ## Pose and Jacobian of one configuration
#
# `jk.fk` returns $T_{world,tip}$ (4x4). `jk.geometric_jacobian` returns the 6 x dof Jacobian, rows
# $[v; \omega]$, for the tip's origin in world axes (`reference="world_aligned"`).

# %%
q = jnp.array([0.2, -0.5, 0.3, 0.1, -0.4, 0.6])
qd = jnp.array([0.0, -0.04, -0.04, -0.05, 0.0, 0.0])  # the chapter's joint rates, rad/s
print(jk.fk(robot, q))
J = jk.geometric_jacobian(robot, q)
print(J)
print("twist [v; omega] =", jk.twist(robot, q, qd))

# %% [markdown]
# ## Hand-built versus autodiff
#
# The two constructions share no Jacobian code; they agree to rounding error.

# %%
J_ad = jk.jacobian_fwd(robot, q)
print("max |J - J_jacfwd| =", float(jnp.max(jnp.abs(J - J_ad))))
assert jnp.allclose(J, J_ad, atol=1e-12)

# %% [markdown]
# ## The three references
#
# | reference | point | axes |
# |---|---|---|
# | `world_aligned` | frame origin | world |
# | `local` | frame origin | frame |
# | `world` | point at the world origin | world |

# %%
for ref in ("world_aligned", "local", "world"):
    print(ref, jk.twist(robot, q, qd, reference=ref))

# %% [markdown]
# ## Analytical Jacobian (roll-pitch-yaw rates)
#
# $J_a = \mathrm{blkdiag}(I, B(\phi)^{-1})\,J_g$.

# %%
Ja = jk.analytical_jacobian(robot, q, "rpy")
phi = jk.representations.from_matrix(jk.fk(robot, q)[:3, :3], "rpy")
print(jnp.max(jnp.abs(Ja - jk.analytical_from_geometric(J, phi, "rpy"))))

# %% [markdown]
# ## Many configurations at once
#
# Write for one configuration, batch with `jax.vmap`.

# %%
rng = np.random.default_rng(0)
lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
qs = jnp.asarray(rng.uniform(lo, hi, size=(10_000, robot.dof)))
qds = jnp.asarray(rng.uniform(-1, 1, size=(10_000, robot.dof)))
twists = jax.jit(jax.vmap(lambda q, qd: jk.twist(robot, q, qd)))(qs, qds)
speed = jnp.linalg.norm(twists[:, :3], axis=1)
print(twists.shape, "mean |v| =", float(speed.mean()), "m/s")
