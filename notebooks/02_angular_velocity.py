# %% [markdown]
# # 2. Angular velocity and skew-symmetric matrices (chapter 4.2 and 4.3.1-4.3.2)
#
# A rigid body's motion at an instant is a linear velocity $v$ of one of its points and an angular
# velocity $\omega$ shared by all of its points. This notebook checks the chapter's tools for
# $\omega$ with jaxkin's `jk.spatial` functions: the skew-symmetric matrix and its four properties,
# $\dot R R^T = S(\omega)$, the velocity of a point on a rotating body, the addition of angular
# velocities across frames, and the difference between pure translation and pure rotation
# (practice question 3).

# %%
import jax

jax.config.update("jax_enable_x64", True)  # float64 for this notebook
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np

import jaxkin as jk

np.set_printoptions(precision=4, suppress=True, linewidth=110)
rng = np.random.default_rng(0)

import sympy as sp

from jaxkin import spatial

# %% [markdown]
# ## Skew-symmetric matrices (Eqs. 4.4-4.6)
#
# A square matrix $S$ is skew-symmetric when $S + S^T = 0$ (Eq. 4.4): its diagonal is zero and
# $s_{ij} = -s_{ji}$ (Eq. 4.5). A $3 \times 3$ skew-symmetric matrix has three independent entries,
# so it stores a 3-vector $a = (a_x, a_y, a_z)$ (Eq. 4.6):
#
# $$
# S(a) = \begin{bmatrix} 0 & -a_z & a_y \\ a_z & 0 & -a_x \\ -a_y & a_x & 0 \end{bmatrix}.
# $$
#
# `spatial.skew(a)` builds it and `spatial.vee(S)` reads the vector back.

# %%
a = jnp.array([1.0, 2.0, 3.0])
S = spatial.skew(a)
print(S)
print("S + S^T = 0:", bool(jnp.all(S + S.T == 0)), "  vee(S) =", spatial.vee(S))

# %% [markdown]
# ### The four properties (Eqs. 4.7-4.10)
#
# 1. **Linear**: $S(\alpha a + \beta b) = \alpha S(a) + \beta S(b)$.
# 2. **Cross product**: $S(a)\, p = a \times p$.
# 3. **Rotation**: $R\, S(a)\, R^T = S(R a)$ for any rotation matrix $R$ (a cross product
#    computed in rotated axes is the rotated cross product).
# 4. **Quadratic form**: $x^T S\, x = 0$ for any skew-symmetric $S$ and vector $x$.
#
# Each is checked below on 10,000 random vectors and rotations (`jax.vmap` over one check),
# then property 3 symbolically with SymPy for a general rotation $R_z(\psi) R_y(\theta)
# R_x(\varphi)$.

# %%
n = 10_000
A, B, P = (jnp.asarray(rng.normal(size=(n, 3))) for _ in range(3))
alpha, beta = jnp.asarray(rng.normal(size=n)), jnp.asarray(rng.normal(size=n))
Rs = jax.jit(jax.vmap(spatial.exp_so3))(rng.normal(size=(n, 3)))  # random rotations


def properties(a, b, p, al, be, R):
    S = spatial.skew
    return jnp.stack(
        [
            jnp.max(jnp.abs(S(al * a + be * b) - (al * S(a) + be * S(b)))),  # 4.7
            jnp.max(jnp.abs(S(a) @ p - jnp.cross(a, p))),  # 4.8
            jnp.max(jnp.abs(R @ S(a) @ R.T - S(R @ a))),  # 4.9
            jnp.abs(p @ S(a) @ p),  # 4.10
        ]
    )


worst = jnp.max(jax.jit(jax.vmap(properties))(A, B, P, alpha, beta, Rs), axis=0)
names = ["linear", "cross product", "R S(a) R^T = S(Ra)", "x^T S x = 0"]
for name, err in zip(names, worst, strict=True):
    print(f"{name:<22} max error {float(err):.1e}")
assert jnp.all(worst < 1e-13)

# %%
phi, th, psi = sp.symbols("varphi theta psi", real=True)
ax_, ay_, az_ = sp.symbols("a_x a_y a_z", real=True)


def S_sym(v):
    return sp.Matrix([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


Rz = sp.Matrix([[sp.cos(psi), -sp.sin(psi), 0], [sp.sin(psi), sp.cos(psi), 0], [0, 0, 1]])
Ry = sp.Matrix([[sp.cos(th), 0, sp.sin(th)], [0, 1, 0], [-sp.sin(th), 0, sp.cos(th)]])
Rx = sp.Matrix([[1, 0, 0], [0, sp.cos(phi), -sp.sin(phi)], [0, sp.sin(phi), sp.cos(phi)]])
R = Rz * Ry * Rx
a_sym = sp.Matrix([ax_, ay_, az_])
# expanded, with sin^2 = 1 - cos^2 for each angle, every entry cancels (sp.simplify finds the same
# in seconds rather than milliseconds)
pythagoras = {sp.sin(x) ** 2: 1 - sp.cos(x) ** 2 for x in (phi, th, psi)}
diff = (R * S_sym(a_sym) * R.T - S_sym(R * a_sym)).expand().subs(pythagoras).expand()
print("R S(a) R^T - S(R a) =", diff)
assert diff == sp.zeros(3, 3)


# %% [markdown]
# ## Angular velocity: $\dot R R^T = S(\omega)$ (Eqs. 4.11-4.12)
#
# Differentiate $R(t) R(t)^T = I$: $\dot R R^T + R \dot R^T = 0$, so $\dot R R^T$ is skew-symmetric.
# The vector it stores is the **angular velocity** $\omega(t)$, in the fixed frame's axes:
#
# $$\dot R(t) R(t)^T = S(\omega(t)), \qquad \dot R(t) = S(\omega(t))\, R(t).$$
#
# For a rotation about a fixed axis, $R = R_z(\theta(t))$, this gives
# $\omega = \dot\theta\, k$. `spatial.angular_velocity(R_of_t, t)` forms $\dot R$ exactly with
# `jax.jvp` and returns $\mathrm{vee}(\dot R R^T)$; below it is checked against a central finite
# difference of the rotation, $\log(R(t+h) R(t-h)^T)/2h$, which uses no derivative at all.


# %%
def R_of_t(t):
    # an arbitrary tumbling motion: three rotations with time-varying angles
    return spatial.rot_z(t) @ spatial.rot_y(0.5 * t**2) @ spatial.rot_x(jnp.sin(3 * t))


t, h = 0.7, 1e-6
R, Rdot = jax.jvp(R_of_t, (t,), (1.0,))
print("Rdot R^T =\n", Rdot @ R.T)  # skew-symmetric
omega = spatial.angular_velocity(R_of_t, t)
omega_fd = spatial.log_so3(R_of_t(t + h) @ R_of_t(t - h).T) / (2 * h)
print("omega (jvp)        =", omega)
print(
    "omega (finite diff)=",
    omega_fd,
    f"  difference {float(jnp.max(jnp.abs(omega - omega_fd))):.1e}",
)
assert jnp.allclose(omega, omega_fd, atol=1e-8)
theta_dot = 1.7
w_axis = spatial.angular_velocity(lambda t: spatial.rot_z(theta_dot * t), 0.3)
print("R = Rz(theta(t)):  omega =", w_axis, " = theta_dot * k")

# %% [markdown]
# ### The velocity of a point on a rotating body (Eqs. 4.13-4.17 and 4.3)
#
# A point fixed in the body has constant coordinates $p^1$ in the body frame and
# $p^0(t) = R(t)\, p^1$ in the fixed frame (Eq. 4.13). Differentiating (Eq. 4.14) and using
# Eq. 4.12:
#
# $$\dot p^0 = \dot R\, p^1 = S(\omega) R\, p^1 = \omega \times p^0 ,$$
#
# the tangential velocity of Eq. 4.3, $v = \omega \times r$: perpendicular to both $\omega$ and the
# lever arm $r$, of size $|\omega|\,|r|$ when they are perpendicular.

# %%
p1 = jnp.array([0.3, -0.2, 0.5])
p0, p0_dot = jax.jvp(lambda t: R_of_t(t) @ p1, (t,), (1.0,))
print("d/dt (R p1) =", p0_dot)
print("omega x p0  =", jnp.cross(omega, p0))
assert jnp.allclose(p0_dot, jnp.cross(omega, p0), atol=1e-14)

# the same on a robot link: the elbow of the two-link arm when only joint 1 turns
planar = jk.robots.load("two_link_planar", a1=1.0, a2=0.7)
q, qd = jnp.array([0.4, 0.9]), jnp.array([2.0, 0.0])
V = jk.twist(planar, q, qd, frame="link1")  # [v; omega] of the elbow frame
r = jk.fk(planar, q, frame="link1")[:3, 3]
print("elbow: v =", V[:3], " omega x r =", jnp.cross(V[3:], r), " |v| =", jnp.linalg.norm(V[:3]))

# %% [markdown]
# ## Adding angular velocities across frames (Eq. 4.18)
#
# With $R_2^0 = R_1^0 R_2^1$ (frame 2 seen from frame 0 through frame 1), the product rule and
# property 3 give
#
# $$\omega_{0,2}^0 = \omega_{0,1}^0 + R_1^0\, \omega_{1,2}^1 ,$$
#
# and for a chain of $n$ frames
# $\omega_{0,n}^0 = \omega_{0,1}^0 + R_1^0 \omega_{1,2}^1 + R_2^0 \omega_{2,3}^2 + \dots +
# R_{n-1}^0 \omega_{n-1,n}^{n-1}$: angular velocities add once they are expressed in the same
# frame. (Superscript: the frame the vector is expressed in; subscripts: from which frame to which.)
# `spatial.compose_angular_velocities` implements the sum; below it is compared with
# differentiating the whole product $R_1^0(t) R_2^1(t) R_3^2(t)$ directly.

# %%
rel = [  # R_{i}^{i-1}(t): each frame turns relative to the previous one about its own axis
    lambda t: spatial.rotation_about_axis(jnp.array([0.0, 0.0, 1.0]), 0.8 * t),
    lambda t: spatial.rotation_about_axis(jnp.array([0.0, 0.6, 0.8]), -1.3 * t),
    lambda t: spatial.rotation_about_axis(jnp.array([1.0, 0.0, 0.0]), 0.5 * t**2),
]
t = 0.9
R_rel = jnp.stack([f(t) for f in rel])
# omega_{i-1,i}^{i-1}: the angular velocity of each relative rotation, in its own parent frame
w_rel = jnp.stack([spatial.angular_velocity(f, t) for f in rel])
w_sum = spatial.compose_angular_velocities(R_rel, w_rel)
w_direct = spatial.angular_velocity(lambda t: rel[0](t) @ rel[1](t) @ rel[2](t), t)
print("sum of Eq. 4.18:", w_sum)
print("d/dt of product:", w_direct)
assert jnp.allclose(w_sum, w_direct, atol=1e-14)

# %% [markdown]
# For a robot this is why the angular rows of the geometric Jacobian are so simple: joint $i$ adds
# $\dot\theta_i z_{i-1}$ (its axis in base coordinates), and the end effector's angular velocity is
# the sum. The same $\omega$ comes out of differentiating the forward kinematics along $\dot q$:

# %%
niryo = jk.robots.load("niryo_one")
q = jnp.array([0.2, -0.5, 0.3, 0.1, -0.4, 0.6])
qd = jnp.array([0.0, -0.04, -0.04, -0.05, 0.0, 0.0])  # the chapter's joint rates
T, T_dot = jax.jvp(lambda q: jk.fk(niryo, q), (q,), (qd,))
print("vee(Rdot R^T)  =", spatial.vee(T_dot[:3, :3] @ T[:3, :3].T))
print("jk.twist omega =", jk.twist(niryo, q, qd)[3:])

# %% [markdown]
# ## Pure translation, pure rotation, or both? (section 4.2, practice question 3)
#
# * **Pure translation** (4.2.1): the orientation never changes, so every point of the body
#   follows the same path, shifted (a straight line, or a curve, as a Ferris-wheel cabin).
#   $\omega = 0$.
# * **Pure rotation** (4.2.2): one point of the body (the centre of rotation) stays still, and every
#   other point moves on an arc about it.
# * **Both** (4.2.3): in general a body turns and its reference point moves: $v \neq 0$,
#   $\omega \neq 0$, e.g. a rolling wheel.
#
# `jk.classify_motion(Ts)` decides from a sequence of poses: same orientation throughout means pure
# translation; a body point that stays fixed in space (found by least squares) means pure rotation;
# otherwise general. The three bodies of practice question 3:

# %%
ts = np.linspace(0.0, 2.0, 9)


def poses(R_of_t, p_of_t):
    return np.stack([np.asarray(spatial.make_transform(R_of_t(t), p_of_t(t))) for t in ts])


r, L = 0.5, 2.0
cases = {
    "(a) spinning about its centre": poses(
        lambda t: spatial.rot_z(t), lambda t: jnp.array([1.0, 1.0, 0.0])
    ),
    "(b) wheel rolling along the ground": poses(
        lambda t: spatial.rot_z(-t), lambda t: jnp.array([r * t, r, 0.0])
    ),
    "(c) Ferris-wheel cabin": poses(
        lambda t: jnp.eye(3), lambda t: jnp.array([L * np.cos(0.6 * t), L * np.sin(0.6 * t), 0.0])
    ),
}
for name, Ts in cases.items():
    print(f"{name:<36} -> {jk.classify_motion(Ts)}")

# %%
square = np.array([[-0.3, -0.3], [0.3, -0.3], [0.3, 0.3], [-0.3, 0.3], [-0.3, -0.3]])
angles = np.linspace(0, 2 * np.pi, 60)
wheel = np.concatenate([r * np.stack([np.cos(angles), np.sin(angles)], 1), [[0.0, 0.0]]])
outlines = [square, wheel, square]  # the wheel's outline ends with a spoke, to see it turn
markers = np.array([[0.3, 0.3], [-0.3, 0.0], [0.0, -0.15]])  # three points painted on the body
fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
for ax, outline, (name, Ts) in zip(axes, outlines, cases.items(), strict=True):
    for k, T in enumerate(Ts):
        body = outline @ T[:2, :2].T + T[:2, 3]
        ax.plot(*body.T, color="0.2", alpha=0.2 + 0.8 * k / (len(Ts) - 1), lw=1)
    for m, color in zip(markers, ["C3", "C0", "C2"], strict=True):
        path = np.stack([T[:2, :2] @ m + T[:2, 3] for T in Ts])
        ax.plot(*path.T, "o-", color=color, ms=3, lw=1.2)
    ax.set(title=f"{name}\n{jk.classify_motion(Ts)}", aspect="equal")
axes[1].axhline(0, color="0.5", lw=1)
fig.suptitle("PQ3: the body at 9 instants (light to dark) and the paths of three points on it")
fig.tight_layout()

# %% [markdown]
# The rolling wheel is subtle: over a finite time it both turns and moves, yet at each *instant*
# its contact point with the ground is at rest, so its instantaneous motion is a pure rotation about
# that point. `jk.classify_twist` classifies the instantaneous twist $[v; \omega]$: pure rotation
# when some point is momentarily at rest, i.e. $v \cdot \omega = 0$ with $\omega \neq 0$; general
# (a screw motion) otherwise.

# %%
w = 1.0  # rad/s; the wheel's centre moves at v = r w
V_centre = np.array([r * w, 0, 0, 0, 0, -w])
contact = np.array([0.0, -r, 0.0])  # from the centre
print("twist at the centre:", jk.classify_twist(V_centre))
print("velocity of the contact point:", V_centre[:3] + np.cross(V_centre[3:], contact))
print("a screw (v along omega):", jk.classify_twist(np.array([0, 0, 0.1, 0, 0, 1.0])))
