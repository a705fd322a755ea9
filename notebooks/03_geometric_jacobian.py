# %% [markdown]
# # 3. The geometric Jacobian (chapter 4.3.3-4.3.4)
#
# The geometric Jacobian $J(q)$ maps joint velocities to the end effector's **twist**, its linear
# velocity $v$ and angular velocity $\omega$ (Eq. 4.21):
#
# $$
# \begin{bmatrix} v \\ \omega \end{bmatrix} = J(q)\, \dot q, \qquad
# J = \begin{bmatrix} J_v \\ J_\omega \end{bmatrix} \in \mathbb{R}^{6 \times n}.
# $$
#
# Unlike the analytical Jacobian, its lower rows are the angular velocity itself, not the rates of
# roll, pitch and yaw. It needs no differentiation at all: each column comes from the geometry of
# one joint (Table 4.1). With $z_{i-1}$ the unit axis of joint $i$ and $o_{i-1}$ a point on that
# axis (the origin of frame $i-1$ in the DH convention), and $o_n$ the end effector's origin, all in
# base coordinates:
#
# | | joint $i$ revolute | joint $i$ prismatic |
# |---|---|---|
# | $J_{v_i}$ | $z_{i-1} \times (o_n - o_{i-1})$ | $z_{i-1}$ |
# | $J_{\omega_i}$ | $z_{i-1}$ | $0$ |
#
# A revolute joint turning at $\dot\theta_i$ adds $\dot\theta_i z_{i-1}$ to $\omega$ (Eq. 4.18) and
# moves $o_n$ on a circle about its axis ($v = \omega \times r$, Eq. 4.3); a prismatic joint slides
# everything after it along $z_{i-1}$ without turning it (Eq. 4.22). The columns stack into
# $J = [J_1 \cdots J_n]$ (Eq. 4.24).

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

import sympy as sp
from IPython.display import display

import jaxkin.testing as jkt
from jaxkin import spatial

# %% [markdown]
# ## Table 4.1 column by column
#
# For the chapter's cylindrical arm with a spherical wrist (practice question 2: joints R, P, P, R,
# R, R), take the frames from forward kinematics, `jk.fk_all` (base first, so row $i-1$ is frame
# $i-1$): $z_{i-1}$ is the third column of $R_{i-1}^0$ and $o_{i-1}$ its translation. Build each
# column from the table and compare with `jk.geometric_jacobian`, which assembles the same table
# from
# one forward pass.

# %%
robot = jk.robots.load("cylindrical_spherical_wrist", d1=0.5, d6=0.1)
q = jnp.asarray(robot.configurations["reference"])
Ts = jk.fk_all(robot, q)  # T_0^0, T_1^0, ..., T_6^0
o_n = Ts[-1, :3, 3]
columns = []
for i, kind in enumerate(robot.joint_kinds, start=1):
    z, o = Ts[i - 1, :3, 2], Ts[i - 1, :3, 3]  # z_{i-1}, o_{i-1}
    if kind == "revolute":
        col = jnp.concatenate([jnp.cross(z, o_n - o), z])
    else:
        col = jnp.concatenate([z, jnp.zeros(3)])
    columns.append(col)
    print(f"joint {i} ({kind:<9}) z_{i - 1} = {np.asarray(z)}  column = {np.asarray(col)}")
J_table = jnp.stack(columns, axis=1)
J = jk.geometric_jacobian(robot, q)
print("max |Table 4.1 - jk.geometric_jacobian| =", float(jnp.max(jnp.abs(J_table - J))))
assert jnp.allclose(J_table, J, atol=1e-15)

# %%
fig = jv.plot_robot(
    robot,
    q,
    frames="all",
    labels=True,
    title="PQ2 robot: frames 0-6; dashed: joint axes z_0 ... z_5",
)

# %% [markdown]
# The same rule, checked three independent ways on the Niryo One (a URDF-style robot whose joint
# axes are not all along the DH z axes): `jkt.assert_jacobian_consistent` compares the hand-built
# Jacobian with `jax.jacfwd` and `jax.jacrev` of forward kinematics (angular rows from
# $\mathrm{vee}(\partial R/\partial q_k\, R^T)$) and with central finite differences on SE(3).
# It raises if any differs. (Its default checks all three references of the next section; one is
# enough here.)

# %%
niryo = jk.robots.load("niryo_one")
q_n = jnp.array([0.2, -0.5, 0.3, 0.1, -0.4, 0.6])
jkt.assert_jacobian_consistent(niryo, q_n, references=("world_aligned",))
print(jk.geometric_jacobian(niryo, q_n))

# %% [markdown]
# ## Practice question 4: a revolute-prismatic arm
#
# Joint 1 turns about the base $z$ axis at the base origin; joint 2 slides along an axis
# perpendicular to it. (The chapter's figure for this arm was lost; jaxkin's `rp_arm` takes the
# prismatic axis perpendicular to $z_0$, via $\alpha_1 = 90°$.) Then $z_0 = (0, 0, 1)$, $o_0 = 0$,
# $z_1 = (s_1, -c_1, 0)$ and $o_2 = (s_1 d_2, -c_1 d_2, d_1)$, and Table 4.1 gives
#
# $$
# J = \begin{bmatrix} z_0 \times (o_2 - o_0) & z_1 \\ z_0 & 0 \end{bmatrix} =
# \begin{bmatrix} c_1 d_2 & s_1 \\ s_1 d_2 & -c_1 \\ 0 & 0 \\ 0 & 0 \\ 0 & 0 \\ 1 & 0 \end{bmatrix}.
# $$
#
# SymPy applies the table to the symbolic frames, and jaxkin is compared with the closed form at
# random configurations.

# %%
t1, d1, d2 = sp.symbols("theta1 d1 d2", real=True)
z0, o0 = sp.Matrix([0, 0, 1]), sp.zeros(3, 1)
z1 = sp.Matrix([sp.sin(t1), -sp.cos(t1), 0])
o2 = sp.Matrix([sp.sin(t1) * d2, -sp.cos(t1) * d2, d1])
J_pq4 = sp.Matrix.vstack(
    sp.Matrix.hstack(z0.cross(o2 - o0), z1), sp.Matrix.hstack(z0, sp.zeros(3, 1))
)
display(J_pq4)

rp = jk.robots.load("rp_arm", d1=0.3)
J_np = sp.lambdify((t1, d1, d2), J_pq4, "numpy")
qs = rng.uniform(np.asarray(rp.lower), np.asarray(rp.upper), size=(1000, 2))
Js = np.asarray(jax.jit(jax.vmap(lambda q: jk.geometric_jacobian(rp, q)))(qs))  # numpy rows
err = max(
    np.max(np.abs(np.asarray(J_np(q[0], 0.3, q[1]), dtype=float) - J))
    for q, J in zip(qs, Js, strict=True)
)
print(f"PQ4: max |closed form - jaxkin| over 1000 configurations = {err:.1e}")
assert err < 1e-14

# %% [markdown]
# ## Which point, which axes: the three references
#
# A twist is the velocity of *a point* expressed in *some axes*. jaxkin's `reference=` names both
# (rows are always $[v; \omega]$):
#
# | `reference` | $v$ is the velocity of | expressed in | Pinocchio | RTB |
# |---|---|---|---|---|
# | `"world_aligned"` | the frame's origin | world axes | `LOCAL_WORLD_ALIGNED` | `jacob0` |
# | `"local"` | the frame's origin | the frame's own axes | `LOCAL` | `jacobe` |
# | `"world"` | the body point now at the world origin | world axes | `WORLD` | |
#
# `"world_aligned"` (the default) is the textbook's $J$; `"world"` gives the spatial velocity.
#
# With $R$, $p$ the frame's orientation and position:
# $J_\text{local} = \mathrm{blkdiag}(R^T, R^T)\, J_\text{world\_aligned}$ and
# $J_\text{world} = \begin{bmatrix} J_v + S(p) J_\omega \\ J_\omega \end{bmatrix}$,
# since the body point at the origin moves at $v - \omega \times p$.

# %%
qd = jnp.array([0.0, -0.04, -0.04, -0.05, 0.0, 0.0])  # the chapter's joint rates, rad/s
T = jk.fk(niryo, q_n)
R, p = T[:3, :3], T[:3, 3]
J_wa, J_loc, J_w = (
    jk.geometric_jacobian(niryo, q_n, reference=r) for r in ("world_aligned", "local", "world")
)
Z = jnp.zeros((3, 3))
assert jnp.allclose(J_loc, jnp.block([[R.T, Z], [Z, R.T]]) @ J_wa, atol=1e-15)
assert jnp.allclose(J_w[:3], J_wa[:3] + spatial.skew(p) @ J_wa[3:], atol=1e-15)
for name, Jr in [("world_aligned", J_wa), ("local", J_loc), ("world", J_w)]:
    print(f"{name:<14} twist = {np.asarray(Jr @ qd)}")
V = J_wa @ qd
print("world linear part = v - omega x p:", np.asarray(V[:3] - jnp.cross(V[3:], p)))

# %%
fig = jv.plot_twist(niryo, q_n, qd, frames="all")
fig.axes[0].set_title("Niryo One, chapter joint rates: v and omega of the gripper (world_aligned)")
plt.show()

# %% [markdown]
# ## Analytical versus geometric Jacobian
#
# If $\phi$ = (roll, pitch, yaw) describes the orientation, its rates are not $\omega$ but are
# linearly related to it: $\omega = B(\phi)\, \dot\phi$ with, for
# $R = R_z(\psi) R_y(\theta) R_x(\varphi)$,
#
# $$
# B(\phi) = \begin{bmatrix} R_z(\psi) R_y(\theta) e_x & R_z(\psi) e_y & e_z \end{bmatrix} =
# \begin{bmatrix} c_\psi c_\theta & -s_\psi & 0 \\ s_\psi c_\theta & c_\psi & 0 \\ -s_\theta & 0 & 1
# \end{bmatrix}, \qquad \det B = \cos\theta .
# $$
#
# Hence $J = \mathrm{blkdiag}(I, B(\phi))\, J_a$, and where $B$ is invertible
# $J_a = \mathrm{blkdiag}(I, B(\phi)^{-1})\, J$. At pitch $\theta = \pm 90°$, $B$ is singular: roll
# and yaw turn about the same axis, so some angular velocities need infinite roll and yaw rates.
# This
# is a **representation singularity**: the robot moves normally; only the description of its
# orientation fails. jaxkin's closed-form $B$ is checked against $B$ by automatic differentiation
# ($\mathrm{vee}(\partial R/\partial\phi_k R^T)$), then $J_a$ against $B^{-1} J$:

# %%
phi = jk.representations.from_matrix(R, "rpy")
B = jk.rate_matrix(phi, "rpy")
print(
    "B(phi) =\n", B, "\ndet B =", float(jnp.linalg.det(B)), " cos(pitch) =", float(jnp.cos(phi[1]))
)
assert jnp.allclose(B, jk.representations.rate_matrix_autodiff(phi, "rpy"), atol=1e-15)
Ja = jk.analytical_jacobian(niryo, q_n, "rpy")
print(
    "max |J_a - blkdiag(I, B^-1) J| =",
    float(jnp.max(jnp.abs(Ja - jk.analytical_from_geometric(J_wa, phi)))),
)

# %% [markdown]
# Now drive the Niryo's wrist (joint 5) through the pose where the gripper's $x$ axis points
# straight up: there the gripper's pitch is $-90°$. The geometric Jacobian stays bounded; the
# analytical one grows like $1/\cos(\text{pitch})$. (`return_margin=True` returns the raw values
# with the margin $|\cos(\text{pitch})|$; by default, under `jit`/`vmap` such configurations come
# out
# as NaN, and an eager call raises.)

# %%
q5 = np.linspace(0.9, 2.2, 2001)  # rad; joint 5 alone, all other joints at zero
qs = np.zeros((q5.size, 6))
qs[:, 4] = q5


def both(q):
    Ja, margin = jk.analytical_jacobian(niryo, q, "rpy", return_margin=True)
    return jnp.max(jnp.abs(Ja)), jnp.max(jnp.abs(jk.geometric_jacobian(niryo, q))), margin


ja_max, j_max, margin = jax.jit(jax.vmap(both))(qs)
k = int(jnp.argmin(margin))
print(
    f"closest to the singularity: q5 = {q5[k]:.4f} rad,",
    f"margin |cos(pitch)| = {float(margin[k]):.1e}",
)
fig, ax = plt.subplots(figsize=(7, 4))
ax.semilogy(q5, ja_max, label="max |analytical J_a| (rpy)")
ax.semilogy(q5, j_max, label="max |geometric J|")
ax.semilogy(q5, 1 / margin, "--", color="0.5", label="1 / |cos(pitch)|")
ax.set(
    xlabel="q5 [rad]",
    ylabel="largest entry",
    title="rpy representation singularity of the Niryo One gripper",
)
ax.legend()
plt.show()

# %%
q_sing = np.zeros(6)
q_sing[4] = np.pi / 2
try:
    jk.analytical_jacobian(niryo, q_sing, "rpy")
except jk.RepresentationSingularityError as e:
    print("RepresentationSingularityError:", e)
print("the geometric Jacobian there is fine:\n", jk.geometric_jacobian(niryo, q_sing))
fig = jv.plot_robot(
    niryo, q_sing, frames="tip", title="q5 = pi/2: gripper x axis vertical, pitch = -90 deg"
)
