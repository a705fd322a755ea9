# %% [markdown]
# # 1. The analytical Jacobian (chapter section 4.1)
#
# Forward kinematics gives the end effector's pose as a function of the joint variables
# $q = (q_1, \dots, q_n)$. Collect its position $p$ and a minimal description of its orientation
# $\phi$ (here roll, pitch and yaw) in one vector $x = f(q) = [p(q); \phi(q)] \in \mathbb{R}^6$.
# The **analytical Jacobian** is the matrix of all first partial derivatives of $f$ (Eq. 4.1):
#
# $$
# J_a(q) = \frac{\partial f}{\partial q} =
# \begin{bmatrix}
# \dfrac{\partial f_1}{\partial q_1} & \cdots & \dfrac{\partial f_1}{\partial q_n} \\
# \vdots & \ddots & \vdots \\
# \dfrac{\partial f_6}{\partial q_1} & \cdots & \dfrac{\partial f_6}{\partial q_n}
# \end{bmatrix} \in \mathbb{R}^{6 \times n},
# $$
#
# and the chain rule turns joint velocities $\dot q$ into the end effector's velocity (Eq. 4.2):
#
# $$\dot x = \frac{d}{dt} f(q(t)) = J_a(q)\, \dot q .$$
#
# Column $k$ of $J_a$ is how fast $x$ changes when joint $k$ alone moves at unit speed.
#
# jaxkin never writes a derivative by hand here: `jk.analytical_jacobian(robot, q, "rpy")` is
# `jax.jacfwd` (forward-mode automatic differentiation) of $q \mapsto [p; \phi]$, exact to rounding.
# Its rows are $[\partial p; \partial \phi]$ with $\phi = $ (roll, pitch, yaw),
# $R = R_z(\text{yaw})\, R_y(\text{pitch})\, R_x(\text{roll})$. Below it is set beside the closed
# forms
# of the chapter's Example 4.1.1 and practice questions 1 and 2, derived again with SymPy.

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

sp.init_printing()


# %% [markdown]
# The chapter's robots are standard (Spong) Denavit-Hartenberg chains:
# $A_i = R_z(\theta_i)\, T_z(d_i)\, T_x(a_i)\, R_x(\alpha_i)$ and $T_n^0 = A_1 A_2 \cdots A_n$.
# For the symbolic side we write $A_i$ once with SymPy (jaxkin itself is numeric).


# %%
def dh(a, alpha, d, theta):
    """Spong's A_i = Rz(theta) Tz(d) Tx(a) Rx(alpha), symbolic."""
    ct, st, ca, sa = sp.cos(theta), sp.sin(theta), sp.cos(alpha), sp.sin(alpha)
    return sp.Matrix(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0, sa, ca, d],
            [0, 0, 0, 1],
        ]
    )


def check(J_closed_form, J_jaxkin, what):
    err = np.max(np.abs(np.asarray(J_closed_form, dtype=float) - np.asarray(J_jaxkin)))
    print(f"{what}: max |closed form - jaxkin| = {err:.1e}")
    assert err < 1e-12


# %% [markdown]
# ## Example 4.1.1: the three-link cylindrical robot
#
# Joint 1 is revolute ($\theta_1$), joints 2 and 3 are prismatic ($d_2$, $d_3$); $d_1$ is a constant
# length. DH table (Spong, Table 3.2):
#
# | link | $a_i$ | $\alpha_i$ | $d_i$ | $\theta_i$ |
# |---|---|---|---|---|
# | 1 | 0 | 0 | $d_1$ | $\theta_1^*$ |
# | 2 | 0 | $-90°$ | $d_2^*$ | 0 |
# | 3 | 0 | 0 | $d_3^*$ | 0 |
#
# $$
# T_3^0 = \begin{bmatrix} c_1 & 0 & -s_1 & -s_1 d_3 \\ s_1 & 0 & c_1 & c_1 d_3 \\
# 0 & -1 & 0 & d_1 + d_2 \\ 0 & 0 & 0 & 1 \end{bmatrix}
# \quad\Rightarrow\quad
# p = \begin{bmatrix} -s_1 d_3 \\ c_1 d_3 \\ d_1 + d_2 \end{bmatrix}
# $$
#
# with $c_1 = \cos\theta_1$, $s_1 = \sin\theta_1$. Differentiating $p$ by $\theta_1$, $d_2$ and
# $d_3$
# gives the three columns, and together
#
# $$
# J_a^{(p)} = \begin{bmatrix} -c_1 d_3 & 0 & -s_1 \\ -s_1 d_3 & 0 & c_1 \\ 0 & 1 & 0 \end{bmatrix},
# \qquad
# \dot p = \begin{bmatrix} -c_1 d_3\, \dot\theta_1 - s_1 \dot d_3 \\
# -s_1 d_3\, \dot\theta_1 + c_1 \dot d_3 \\ \dot d_2 \end{bmatrix}.
# $$
#
# The orientation is $R = R_z(\theta_1) R_x(-90°)$: roll $= -90°$, pitch $= 0$, yaw $= \theta_1$, so
# the orientation rows of $J_a$ are $[0\;0\;0;\; 0\;0\;0;\; 1\;0\;0]$.

# %%
t1, d1, d2, d3 = sp.symbols("theta1 d1 d2 d3", real=True)
T_cyl = sp.simplify(dh(0, 0, d1, t1) * dh(0, -sp.pi / 2, d2, 0) * dh(0, 0, d3, 0))
T_cyl

# %%
p_cyl = T_cyl[:3, 3]
J_cyl = p_cyl.jacobian([t1, d2, d3])  # Eq. 4.1, symbolically
J_cyl

# %%
cyl = jk.robots.load("cylindrical", d1=0.5)  # d1 = 0.5 m; q = (theta1, d2, d3)
q = jnp.array([0.3, 0.4, 0.5])
Ja = jk.analytical_jacobian(cyl, q, "rpy")
print(Ja)
J_cf = J_cyl.subs({t1: 0.3, d1: 0.5, d2: 0.4, d3: 0.5})
check(J_cf, Ja[:3], "position rows at one configuration")
check([[0, 0, 0], [0, 0, 0], [1, 0, 0]], Ja[3:], "orientation rows (yaw = theta1)")

# %% [markdown]
# The same comparison over 10,000 random configurations: `jax.vmap` batches the per-configuration
# function, `jax.jit` compiles it once, and SymPy's `lambdify` turns the closed form into numpy.
# Then Eq. 4.2: the velocity $\dot p = J_a \dot q$ against the chapter's closed form.

# %%
n = 10_000
qs = rng.uniform(np.asarray(cyl.lower), np.asarray(cyl.upper), size=(n, 3))
qds = rng.uniform(-1, 1, size=(n, 3))
Jas = jax.jit(jax.vmap(lambda q: jk.analytical_jacobian(cyl, q, "rpy")))(qs)

J_np = sp.lambdify((t1, d1, d2, d3), J_cyl, "numpy")
J_ref = np.stack([np.asarray(J_np(q[0], 0.5, q[1], q[2]), dtype=float) for q in qs[:500]])
check(J_ref, Jas[:500, :3], "position rows, 500 configurations")

c1, s1, d3v = np.cos(qs[:, 0]), np.sin(qs[:, 0]), qs[:, 2]
pdot_chapter = np.stack(
    [-c1 * d3v * qds[:, 0] - s1 * qds[:, 2], -s1 * d3v * qds[:, 0] + c1 * qds[:, 2], qds[:, 1]],
    axis=1,
)
pdot = jnp.einsum("nij,nj->ni", Jas[:, :3], qds)
check(pdot_chapter, pdot, "velocity (Eq. 4.2), 10,000 configurations")

# %% [markdown]
# ## Practice question 1: the two-link planar arm
#
# $$x = a_1 c_1 + a_2 c_{12}, \qquad y = a_1 s_1 + a_2 s_{12}, \qquad z = 0,$$
#
# with $c_{12} = \cos(\theta_1 + \theta_2)$. Differentiating by $\theta_1$ and $\theta_2$:
#
# $$
# J_a^{(p)} = \begin{bmatrix} -a_1 s_1 - a_2 s_{12} & -a_2 s_{12} \\
# a_1 c_1 + a_2 c_{12} & a_2 c_{12} \\ 0 & 0 \end{bmatrix}.
# $$
#
# Its upper $2\times2$ block has determinant $a_1 a_2 \sin\theta_2$: at $\theta_2 = 0$ or $\pi$ (arm
# stretched or folded) both columns are parallel and the tip cannot move along the arm, a
# *singularity*. The figure draws the two columns as the tip velocities for $\dot\theta_1 = 1$ and
# $\dot\theta_2 = 1$ rad/s.

# %%
a1, a2, t2 = sp.symbols("a1 a2 theta2", real=True)
T_2r = sp.simplify(dh(a1, 0, 0, t1) * dh(a2, 0, 0, t2))
J_2r = T_2r[:3, 3].jacobian([t1, t2])
display(T_2r[:3, 3], J_2r, sp.factor(sp.simplify(J_2r[:2, :2].det())))

planar = jk.robots.load("two_link_planar", a1=1.0, a2=0.7)
q = jnp.array([0.6, 1.1])
check(J_2r.subs({a1: 1.0, a2: 0.7, t1: 0.6, t2: 1.1}), jk.analytical_jacobian(planar, q)[:3], "PQ1")

# %%
fig, axes = plt.subplots(1, 3, figsize=(12, 4))
for ax, q in zip(axes, [(0.6, 1.1), (0.3, 0.35), (0.5, 0.0)], strict=True):
    q = jnp.array(q)
    pts = np.asarray(jk.fk_all(planar, q))[:, :2, 3]  # base, elbow, tip
    J = np.asarray(jk.analytical_jacobian(planar, q, "rpy"))
    ax.plot(*pts.T, "-o", color="0.3", lw=4)
    for k, color in enumerate(["C3", "C0"]):
        ax.arrow(*pts[-1], *(0.4 * J[:2, k]), color=color, width=0.015, label=f"column {k + 1}")
    det = 1.0 * 0.7 * np.sin(float(q[1]))
    ax.set(title=f"q = {np.round(np.asarray(q), 2)},  det = {det:.2f}", aspect="equal")
    ax.set(xlim=(-0.5, 2.2), ylim=(-0.6, 2.0))
axes[0].legend()
fig.suptitle("PQ1: columns of J_a = tip velocity per unit joint rate (x 0.4 s); right: singular")
fig.tight_layout()

# %% [markdown]
# ## Practice question 2: cylindrical arm with a spherical wrist
#
# The first three links are Example 4.1.1's; the wrist adds three revolute joints
# (Spong Table 3.3: $\alpha_4 = -90°$, $\alpha_5 = +90°$, $d_6$ to the tool). The generalised
# coordinates are $q = (\theta_1, d_2, d_3, \theta_4, \theta_5, \theta_6)$, and the tool position is
#
# $$
# \begin{aligned}
# x &= c_1 c_4 s_5 d_6 - s_1 c_5 d_6 - s_1 d_3,\\
# y &= s_1 c_4 s_5 d_6 + c_1 c_5 d_6 + c_1 d_3,\\
# z &= -s_4 s_5 d_6 + d_1 + d_2 .
# \end{aligned}
# $$
#
# Its $3 \times 6$ Jacobian (the chapter's answer) is
#
# $$
# \begin{bmatrix}
# -s_1 c_4 s_5 d_6 - c_1 c_5 d_6 - c_1 d_3 & 0 & -s_1 & -c_1 s_4 s_5 d_6 & (c_1 c_4 c_5 + s_1 s_5)
# d_6 & 0\\
# c_1 c_4 s_5 d_6 - s_1 c_5 d_6 - s_1 d_3 & 0 & c_1 & -s_1 s_4 s_5 d_6 & (s_1 c_4 c_5 - c_1 s_5) d_6
# & 0\\
# 0 & 1 & 0 & -c_4 s_5 d_6 & -s_4 c_5 d_6 & 0
# \end{bmatrix}.
# $$
#
# The last column is zero: $\theta_6$ spins the tool about its own axis and does not move its
# origin. SymPy rederives the position from the DH tables and checks the chapter's expressions.

# %%
t4, t5, t6, d6 = sp.symbols("theta4 theta5 theta6 d6", real=True)
T_pq2 = (
    dh(0, 0, d1, t1) * dh(0, -sp.pi / 2, d2, 0) * dh(0, 0, d3, 0)
    * dh(0, -sp.pi / 2, 0, t4) * dh(0, sp.pi / 2, 0, t5) * dh(0, 0, d6, t6)
)  # fmt: skip
p_pq2 = sp.simplify(T_pq2[:3, 3])
c, s = sp.cos, sp.sin
p_chapter = sp.Matrix(
    [
        c(t1) * c(t4) * s(t5) * d6 - s(t1) * c(t5) * d6 - s(t1) * d3,
        s(t1) * c(t4) * s(t5) * d6 + c(t1) * c(t5) * d6 + c(t1) * d3,
        -s(t4) * s(t5) * d6 + d1 + d2,
    ]
)
assert sp.simplify(p_pq2 - p_chapter) == sp.zeros(3, 1)
J_pq2 = p_chapter.jacobian([t1, d2, d3, t4, t5, t6])
J_pq2

# %%
wrist = jk.robots.load("cylindrical_spherical_wrist", d1=0.5, d6=0.1)
J_np = sp.lambdify((t1, d2, d3, t4, t5, t6, d1, d6), J_pq2, "numpy")
qs = rng.uniform(np.asarray(wrist.lower), np.asarray(wrist.upper), size=(200, 6))
Ja_all, margin = jax.jit(
    jax.vmap(lambda q: jk.analytical_jacobian(wrist, q, "rpy", return_margin=True))
)(qs)
J_ref = np.stack([np.asarray(J_np(*q, 0.5, 0.1), dtype=float) for q in qs])
check(J_ref, Ja_all[:, :3], "PQ2 position rows, 200 configurations")

# %% [markdown]
# The position rows of $J_a$ are the same whatever orientation representation is used; the
# orientation rows are derivatives of roll, pitch and yaw, which are *not* the components of the
# angular velocity $\omega$. The geometric Jacobian (notebook 3) has $\omega$ in its lower rows;
# the two are related by $J_a = \mathrm{blkdiag}(I, B(\phi)^{-1})\, J_g$, which
# fails where $B(\phi)$ is singular (pitch $= \pm 90°$).

# %%
q = jnp.asarray(wrist.configurations["reference"])
print("analytical rows 4-6 (d roll, d pitch, d yaw):\n", jk.analytical_jacobian(wrist, q)[3:])
print("geometric rows 4-6 (omega):\n", jk.geometric_jacobian(wrist, q)[3:])
fig = jv.plot_robot(wrist, q, frames="all", labels=True, title="PQ2 robot at its reference pose")
