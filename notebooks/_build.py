"""Writes the chapter notebooks (01-06) with nbformat, outputs cleared.

Run from the repository root: ``python3 notebooks/_build.py [NAME ...]`` (default: all). Edit the
cells here, not in the .ipynb files, then rebuild; tests/test_notebooks.py executes the results.
Not part of the package and not collected by pytest. The written notebooks are formatted with
``ruff format`` when ruff is installed (the cell sources here need not be).
"""

# ruff: noqa: E501  (the cells are long strings; ruff checks the written notebooks instead)

from __future__ import annotations

import pathlib
import shutil
import subprocess
import sys

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = pathlib.Path(__file__).parent


def colab(*extra: str) -> str:
    pkgs = ", ".join(repr(p) for p in ("jaxkin[viz]", *extra))
    return f"""# In Colab, install jaxkin first; elsewhere this cell does nothing.
import sys

if "google.colab" in sys.modules:
    import subprocess

    subprocess.run([sys.executable, "-m", "pip", "install", "-q", {pkgs}], check=True)"""


def notebook(cells: list[tuple[str, str]]) -> nbformat.NotebookNode:
    nb = new_notebook()
    nb.metadata = {
        "colab": {"provenance": []},
        "kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
        "language_info": {"name": "python"},
    }
    for kind, text in cells:
        text = text.strip("\n")
        nb.cells.append(new_markdown_cell(text) if kind == "md" else new_code_cell(text))
    for i, cell in enumerate(nb.cells):  # stable ids keep diffs small
        cell["id"] = f"c{i:02d}"
    return nb


def md(text: str) -> tuple[str, str]:
    return ("md", text)


def code(text: str) -> tuple[str, str]:
    return ("code", text)


def setup(viz: bool = True, jnp: bool = True) -> str:
    """The imports every notebook starts with (float64, numpy printing, a seeded generator)."""
    lines = [
        "import jax",
        "",
        'jax.config.update("jax_enable_x64", True)  # float64 for this notebook',
        "import jax.numpy as jnp" if jnp else None,
        "import matplotlib.pyplot as plt",
        "import numpy as np",
        "",
        "import jaxkin as jk",
        "import jaxkin.viz as jv" if viz else None,
        "",
        "np.set_printoptions(precision=4, suppress=True, linewidth=110)",
        "rng = np.random.default_rng(0)",
        "",
    ]
    return "\n".join(line for line in lines if line is not None) + "\n"


SETUP = setup()

# --------------------------------------------------------------------------------------------
NB01 = [
    md(r"""
# 1. The analytical Jacobian (chapter section 4.1)

Forward kinematics gives the end effector's pose as a function of the joint variables
$q = (q_1, \dots, q_n)$. Collect its position $p$ and a minimal description of its orientation
$\phi$ (here roll, pitch and yaw) in one vector $x = f(q) = [p(q); \phi(q)] \in \mathbb{R}^6$.
The **analytical Jacobian** is the matrix of all first partial derivatives of $f$ (Eq. 4.1):

$$
J_a(q) = \frac{\partial f}{\partial q} =
\begin{bmatrix}
\dfrac{\partial f_1}{\partial q_1} & \cdots & \dfrac{\partial f_1}{\partial q_n} \\
\vdots & \ddots & \vdots \\
\dfrac{\partial f_6}{\partial q_1} & \cdots & \dfrac{\partial f_6}{\partial q_n}
\end{bmatrix} \in \mathbb{R}^{6 \times n},
$$

and the chain rule turns joint velocities $\dot q$ into the end effector's velocity (Eq. 4.2):

$$\dot x = \frac{d}{dt} f(q(t)) = J_a(q)\, \dot q .$$

Column $k$ of $J_a$ is how fast $x$ changes when joint $k$ alone moves at unit speed.

jaxkin never writes a derivative by hand here: `jk.analytical_jacobian(robot, q, "rpy")` is
`jax.jacfwd` (forward-mode automatic differentiation) of $q \mapsto [p; \phi]$, exact to rounding.
Its rows are $[\partial p; \partial \phi]$ with $\phi = $ (roll, pitch, yaw),
$R = R_z(\text{yaw})\, R_y(\text{pitch})\, R_x(\text{roll})$. Below it is set beside the closed forms
of the chapter's Example 4.1.1 and practice questions 1 and 2, derived again with SymPy.
"""),
    code(colab("sympy")),
    code(
        SETUP
        + """import sympy as sp

sp.init_printing()"""
    ),
    md(r"""
The chapter's robots are standard (Spong) Denavit-Hartenberg chains:
$A_i = R_z(\theta_i)\, T_z(d_i)\, T_x(a_i)\, R_x(\alpha_i)$ and $T_n^0 = A_1 A_2 \cdots A_n$.
For the symbolic side we write $A_i$ once with SymPy (jaxkin itself is numeric).
"""),
    code("""
def dh(a, alpha, d, theta):
    \"\"\"Spong's A_i = Rz(theta) Tz(d) Tx(a) Rx(alpha), symbolic.\"\"\"
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
    assert err < 1e-12"""),
    md(r"""
## Example 4.1.1: the three-link cylindrical robot

Joint 1 is revolute ($\theta_1$), joints 2 and 3 are prismatic ($d_2$, $d_3$); $d_1$ is a constant
length. DH table (Spong, Table 3.2):

| link | $a_i$ | $\alpha_i$ | $d_i$ | $\theta_i$ |
|---|---|---|---|---|
| 1 | 0 | 0 | $d_1$ | $\theta_1^*$ |
| 2 | 0 | $-90°$ | $d_2^*$ | 0 |
| 3 | 0 | 0 | $d_3^*$ | 0 |

$$
T_3^0 = \begin{bmatrix} c_1 & 0 & -s_1 & -s_1 d_3 \\ s_1 & 0 & c_1 & c_1 d_3 \\
0 & -1 & 0 & d_1 + d_2 \\ 0 & 0 & 0 & 1 \end{bmatrix}
\quad\Rightarrow\quad
p = \begin{bmatrix} -s_1 d_3 \\ c_1 d_3 \\ d_1 + d_2 \end{bmatrix}
$$

with $c_1 = \cos\theta_1$, $s_1 = \sin\theta_1$. Differentiating $p$ by $\theta_1$, $d_2$ and $d_3$
gives the three columns, and together

$$
J_a^{(p)} = \begin{bmatrix} -c_1 d_3 & 0 & -s_1 \\ -s_1 d_3 & 0 & c_1 \\ 0 & 1 & 0 \end{bmatrix},
\qquad
\dot p = \begin{bmatrix} -c_1 d_3\, \dot\theta_1 - s_1 \dot d_3 \\
-s_1 d_3\, \dot\theta_1 + c_1 \dot d_3 \\ \dot d_2 \end{bmatrix}.
$$

The orientation is $R = R_z(\theta_1) R_x(-90°)$: roll $= -90°$, pitch $= 0$, yaw $= \theta_1$, so
the orientation rows of $J_a$ are $[0\;0\;0;\; 0\;0\;0;\; 1\;0\;0]$.
"""),
    code("""
t1, d1, d2, d3 = sp.symbols("theta1 d1 d2 d3", real=True)
T_cyl = sp.simplify(dh(0, 0, d1, t1) * dh(0, -sp.pi / 2, d2, 0) * dh(0, 0, d3, 0))
T_cyl"""),
    code("""
p_cyl = T_cyl[:3, 3]
J_cyl = p_cyl.jacobian([t1, d2, d3])  # Eq. 4.1, symbolically
J_cyl"""),
    code("""
cyl = jk.robots.load("cylindrical", d1=0.5)  # d1 = 0.5 m; q = (theta1, d2, d3)
q = jnp.array([0.3, 0.4, 0.5])
Ja = jk.analytical_jacobian(cyl, q, "rpy")
print(Ja)
J_cf = J_cyl.subs({t1: 0.3, d1: 0.5, d2: 0.4, d3: 0.5})
check(J_cf, Ja[:3], "position rows at one configuration")
check([[0, 0, 0], [0, 0, 0], [1, 0, 0]], Ja[3:], "orientation rows (yaw = theta1)")"""),
    md(r"""
The same comparison over 10,000 random configurations: `jax.vmap` batches the per-configuration
function, `jax.jit` compiles it once, and SymPy's `lambdify` turns the closed form into numpy.
Then Eq. 4.2: the velocity $\dot p = J_a \dot q$ against the chapter's closed form.
"""),
    code("""
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
check(pdot_chapter, pdot, "velocity (Eq. 4.2), 10,000 configurations")"""),
    md(r"""
## Practice question 1: the two-link planar arm

$$x = a_1 c_1 + a_2 c_{12}, \qquad y = a_1 s_1 + a_2 s_{12}, \qquad z = 0,$$

with $c_{12} = \cos(\theta_1 + \theta_2)$. Differentiating by $\theta_1$ and $\theta_2$:

$$
J_a^{(p)} = \begin{bmatrix} -a_1 s_1 - a_2 s_{12} & -a_2 s_{12} \\
a_1 c_1 + a_2 c_{12} & a_2 c_{12} \\ 0 & 0 \end{bmatrix}.
$$

Its upper $2\times2$ block has determinant $a_1 a_2 \sin\theta_2$: at $\theta_2 = 0$ or $\pi$ (arm
stretched or folded) both columns are parallel and the tip cannot move along the arm, a
*singularity*. The figure draws the two columns as the tip velocities for $\dot\theta_1 = 1$ and
$\dot\theta_2 = 1$ rad/s.
"""),
    code("""
a1, a2, t2 = sp.symbols("a1 a2 theta2", real=True)
T_2r = sp.simplify(dh(a1, 0, 0, t1) * dh(a2, 0, 0, t2))
J_2r = T_2r[:3, 3].jacobian([t1, t2])
display(T_2r[:3, 3], J_2r, sp.factor(sp.simplify(J_2r[:2, :2].det())))

planar = jk.robots.load("two_link_planar", a1=1.0, a2=0.7)
q = jnp.array([0.6, 1.1])
check(J_2r.subs({a1: 1.0, a2: 0.7, t1: 0.6, t2: 1.1}), jk.analytical_jacobian(planar, q)[:3], "PQ1")"""),
    code("""
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
fig.tight_layout()"""),
    md(r"""
## Practice question 2: cylindrical arm with a spherical wrist

The first three links are Example 4.1.1's; the wrist adds three revolute joints
(Spong Table 3.3: $\alpha_4 = -90°$, $\alpha_5 = +90°$, $d_6$ to the tool). The generalised
coordinates are $q = (\theta_1, d_2, d_3, \theta_4, \theta_5, \theta_6)$, and the tool position is

$$
\begin{aligned}
x &= c_1 c_4 s_5 d_6 - s_1 c_5 d_6 - s_1 d_3,\\
y &= s_1 c_4 s_5 d_6 + c_1 c_5 d_6 + c_1 d_3,\\
z &= -s_4 s_5 d_6 + d_1 + d_2 .
\end{aligned}
$$

Its $3 \times 6$ Jacobian (the chapter's answer) is

$$
\begin{bmatrix}
-s_1 c_4 s_5 d_6 - c_1 c_5 d_6 - c_1 d_3 & 0 & -s_1 & -c_1 s_4 s_5 d_6 & (c_1 c_4 c_5 + s_1 s_5) d_6 & 0\\
c_1 c_4 s_5 d_6 - s_1 c_5 d_6 - s_1 d_3 & 0 & c_1 & -s_1 s_4 s_5 d_6 & (s_1 c_4 c_5 - c_1 s_5) d_6 & 0\\
0 & 1 & 0 & -c_4 s_5 d_6 & -s_4 c_5 d_6 & 0
\end{bmatrix}.
$$

The last column is zero: $\theta_6$ spins the tool about its own axis and does not move its
origin. SymPy rederives the position from the DH tables and checks the chapter's expressions.
"""),
    code("""
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
J_pq2"""),
    code("""
wrist = jk.robots.load("cylindrical_spherical_wrist", d1=0.5, d6=0.1)
J_np = sp.lambdify((t1, d2, d3, t4, t5, t6, d1, d6), J_pq2, "numpy")
qs = rng.uniform(np.asarray(wrist.lower), np.asarray(wrist.upper), size=(200, 6))
Ja_all, margin = jax.jit(
    jax.vmap(lambda q: jk.analytical_jacobian(wrist, q, "rpy", return_margin=True))
)(qs)
J_ref = np.stack([np.asarray(J_np(*q, 0.5, 0.1), dtype=float) for q in qs])
check(J_ref, Ja_all[:, :3], "PQ2 position rows, 200 configurations")"""),
    md(r"""
The position rows of $J_a$ are the same whatever orientation representation is used; the
orientation rows are derivatives of roll, pitch and yaw, which are *not* the components of the
angular velocity $\omega$. The geometric Jacobian (notebook 3) has $\omega$ in its lower rows;
the two are related by $J_a = \mathrm{blkdiag}(I, B(\phi)^{-1})\, J_g$, which
fails where $B(\phi)$ is singular (pitch $= \pm 90°$).
"""),
    code("""
q = jnp.asarray(wrist.configurations["reference"])
print("analytical rows 4-6 (d roll, d pitch, d yaw):\\n", jk.analytical_jacobian(wrist, q)[3:])
print("geometric rows 4-6 (omega):\\n", jk.geometric_jacobian(wrist, q)[3:])
fig = jv.plot_robot(wrist, q, frames="all", labels=True, title="PQ2 robot at its reference pose")"""),
]


# --------------------------------------------------------------------------------------------
NB02 = [
    md(r"""
# 2. Angular velocity and skew-symmetric matrices (chapter 4.2 and 4.3.1-4.3.2)

A rigid body's motion at an instant is a linear velocity $v$ of one of its points and an angular
velocity $\omega$ shared by all of its points. This notebook checks the chapter's tools for
$\omega$ with jaxkin's `jk.spatial` functions: the skew-symmetric matrix and its four properties,
$\dot R R^T = S(\omega)$, the velocity of a point on a rotating body, the addition of angular
velocities across frames, and the difference between pure translation and pure rotation
(practice question 3).
"""),
    code(colab("sympy")),
    code(
        setup(viz=False)
        + """import sympy as sp

from jaxkin import spatial"""
    ),
    md(r"""
## Skew-symmetric matrices (Eqs. 4.4-4.6)

A square matrix $S$ is skew-symmetric when $S + S^T = 0$ (Eq. 4.4): its diagonal is zero and
$s_{ij} = -s_{ji}$ (Eq. 4.5). A $3 \times 3$ skew-symmetric matrix has three independent entries,
so it stores a 3-vector $a = (a_x, a_y, a_z)$ (Eq. 4.6):

$$
S(a) = \begin{bmatrix} 0 & -a_z & a_y \\ a_z & 0 & -a_x \\ -a_y & a_x & 0 \end{bmatrix}.
$$

`spatial.skew(a)` builds it and `spatial.vee(S)` reads the vector back.
"""),
    code("""
a = jnp.array([1.0, 2.0, 3.0])
S = spatial.skew(a)
print(S)
print("S + S^T = 0:", bool(jnp.all(S + S.T == 0)), "  vee(S) =", spatial.vee(S))"""),
    md(r"""
### The four properties (Eqs. 4.7-4.10)

1. **Linear**: $S(\alpha a + \beta b) = \alpha S(a) + \beta S(b)$.
2. **Cross product**: $S(a)\, p = a \times p$.
3. **Rotation**: $R\, S(a)\, R^T = S(R a)$ for any rotation matrix $R$ (a cross product
   computed in rotated axes is the rotated cross product).
4. **Quadratic form**: $x^T S\, x = 0$ for any skew-symmetric $S$ and vector $x$.

Each is checked below on 10,000 random vectors and rotations (`jax.vmap` over one check),
then property 3 symbolically with SymPy for a general rotation $R_z(\psi) R_y(\theta) R_x(\varphi)$.
"""),
    code("""
n = 10_000
A, B, P = (jnp.asarray(rng.normal(size=(n, 3))) for _ in range(3))
alpha, beta = jnp.asarray(rng.normal(size=n)), jnp.asarray(rng.normal(size=n))
Rs = jax.vmap(spatial.exp_so3)(jnp.asarray(rng.normal(size=(n, 3))))  # random rotations


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
assert jnp.all(worst < 1e-13)"""),
    code("""
phi, th, psi = sp.symbols("varphi theta psi", real=True)
ax_, ay_, az_ = sp.symbols("a_x a_y a_z", real=True)


def S_sym(v):
    return sp.Matrix([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


Rz = sp.Matrix([[sp.cos(psi), -sp.sin(psi), 0], [sp.sin(psi), sp.cos(psi), 0], [0, 0, 1]])
Ry = sp.Matrix([[sp.cos(th), 0, sp.sin(th)], [0, 1, 0], [-sp.sin(th), 0, sp.cos(th)]])
Rx = sp.Matrix([[1, 0, 0], [0, sp.cos(phi), -sp.sin(phi)], [0, sp.sin(phi), sp.cos(phi)]])
R = Rz * Ry * Rx
a_sym = sp.Matrix([ax_, ay_, az_])
diff = sp.simplify(R * S_sym(a_sym) * R.T - S_sym(R * a_sym))
print("R S(a) R^T - S(R a) =", diff)
assert diff == sp.zeros(3, 3)"""),
    md(r"""
## Angular velocity: $\dot R R^T = S(\omega)$ (Eqs. 4.11-4.12)

Differentiate $R(t) R(t)^T = I$: $\dot R R^T + R \dot R^T = 0$, so $\dot R R^T$ is skew-symmetric.
The vector it stores is the **angular velocity** $\omega(t)$, in the fixed frame's axes:

$$\dot R(t) R(t)^T = S(\omega(t)), \qquad \dot R(t) = S(\omega(t))\, R(t).$$

For a rotation about a fixed axis, $R = R_z(\theta(t))$, this gives
$\omega = \dot\theta\, k$. `spatial.angular_velocity(R_of_t, t)` forms $\dot R$ exactly with
`jax.jvp` and returns $\mathrm{vee}(\dot R R^T)$; below it is checked against a central finite
difference of the rotation, $\log(R(t+h) R(t-h)^T)/2h$, which uses no derivative at all.
"""),
    code("""
def R_of_t(t):
    # an arbitrary tumbling motion: three rotations with time-varying angles
    return spatial.rot_z(t) @ spatial.rot_y(0.5 * t**2) @ spatial.rot_x(jnp.sin(3 * t))


t, h = 0.7, 1e-6
R, Rdot = jax.jvp(R_of_t, (t,), (1.0,))
print("Rdot R^T =\\n", Rdot @ R.T)  # skew-symmetric
omega = spatial.angular_velocity(R_of_t, t)
omega_fd = spatial.log_so3(R_of_t(t + h) @ R_of_t(t - h).T) / (2 * h)
print("omega (jvp)        =", omega)
print("omega (finite diff)=", omega_fd, f"  difference {float(jnp.max(jnp.abs(omega - omega_fd))):.1e}")
assert jnp.allclose(omega, omega_fd, atol=1e-8)
theta_dot = 1.7
w_axis = spatial.angular_velocity(lambda t: spatial.rot_z(theta_dot * t), 0.3)
print("R = Rz(theta(t)):  omega =", w_axis, " = theta_dot * k")"""),
    md(r"""
### The velocity of a point on a rotating body (Eqs. 4.13-4.17 and 4.3)

A point fixed in the body has constant coordinates $p^1$ in the body frame and
$p^0(t) = R(t)\, p^1$ in the fixed frame (Eq. 4.13). Differentiating (Eq. 4.14) and using
Eq. 4.12:

$$\dot p^0 = \dot R\, p^1 = S(\omega) R\, p^1 = \omega \times p^0 ,$$

the tangential velocity of Eq. 4.3, $v = \omega \times r$: perpendicular to both $\omega$ and the
lever arm $r$, of size $|\omega|\,|r|$ when they are perpendicular.
"""),
    code("""
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
print("elbow: v =", V[:3], " omega x r =", jnp.cross(V[3:], r), " |v| =", jnp.linalg.norm(V[:3]))"""),
    md(r"""
## Adding angular velocities across frames (Eq. 4.18)

With $R_2^0 = R_1^0 R_2^1$ (frame 2 seen from frame 0 through frame 1), the product rule and
property 3 give

$$\omega_{0,2}^0 = \omega_{0,1}^0 + R_1^0\, \omega_{1,2}^1 ,$$

and for a chain of $n$ frames
$\omega_{0,n}^0 = \omega_{0,1}^0 + R_1^0 \omega_{1,2}^1 + R_2^0 \omega_{2,3}^2 + \dots
+ R_{n-1}^0 \omega_{n-1,n}^{n-1}$: angular velocities add once they are expressed in the same
frame. (Superscript: the frame the vector is expressed in; subscripts: from which frame to which.)
`spatial.compose_angular_velocities` implements the sum; below it is compared with
differentiating the whole product $R_1^0(t) R_2^1(t) R_3^2(t)$ directly.
"""),
    code("""
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
assert jnp.allclose(w_sum, w_direct, atol=1e-14)"""),
    md(r"""
For a robot this is why the angular rows of the geometric Jacobian are so simple: joint $i$ adds
$\dot\theta_i z_{i-1}$ (its axis in base coordinates), and the end effector's angular velocity is
the sum. The same $\omega$ comes out of differentiating the forward kinematics along $\dot q$:
"""),
    code("""
niryo = jk.robots.load("niryo_one")
q = jnp.array([0.2, -0.5, 0.3, 0.1, -0.4, 0.6])
qd = jnp.array([0.0, -0.04, -0.04, -0.05, 0.0, 0.0])  # the chapter's joint rates
T, T_dot = jax.jvp(lambda q: jk.fk(niryo, q), (q,), (qd,))
print("vee(Rdot R^T)  =", spatial.vee(T_dot[:3, :3] @ T[:3, :3].T))
print("jk.twist omega =", jk.twist(niryo, q, qd)[3:])"""),
    md(r"""
## Pure translation, pure rotation, or both? (section 4.2, practice question 3)

* **Pure translation** (4.2.1): the orientation never changes, so every point of the body
  follows the same path, shifted (a straight line, or a curve, as a Ferris-wheel cabin).
  $\omega = 0$.
* **Pure rotation** (4.2.2): one point of the body (the centre of rotation) stays still, and every
  other point moves on an arc about it.
* **Both** (4.2.3): in general a body turns and its reference point moves: $v \neq 0$,
  $\omega \neq 0$, e.g. a rolling wheel.

`jk.classify_motion(Ts)` decides from a sequence of poses: same orientation throughout means pure
translation; a body point that stays fixed in space (found by least squares) means pure rotation;
otherwise general. The three bodies of practice question 3:
"""),
    code("""
ts = np.linspace(0.0, 2.0, 9)


def poses(R_of_t, p_of_t):
    return np.stack([np.asarray(spatial.make_transform(R_of_t(t), p_of_t(t))) for t in ts])


r, L = 0.5, 2.0
cases = {
    "(a) spinning about its centre": poses(lambda t: spatial.rot_z(t), lambda t: jnp.array([1.0, 1.0, 0.0])),
    "(b) wheel rolling along the ground": poses(lambda t: spatial.rot_z(-t), lambda t: jnp.array([r * t, r, 0.0])),
    "(c) Ferris-wheel cabin": poses(
        lambda t: jnp.eye(3), lambda t: jnp.array([L * np.cos(0.6 * t), L * np.sin(0.6 * t), 0.0])
    ),
}
for name, Ts in cases.items():
    print(f"{name:<36} -> {jk.classify_motion(Ts)}")"""),
    code("""
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
    ax.set(title=f"{name}\\n{jk.classify_motion(Ts)}", aspect="equal")
axes[1].axhline(0, color="0.5", lw=1)
fig.suptitle("PQ3: the body at 9 instants (light to dark) and the paths of three points on it")
fig.tight_layout()"""),
    md(r"""
The rolling wheel is subtle: over a finite time it both turns and moves, yet at each *instant*
its contact point with the ground is at rest, so its instantaneous motion is a pure rotation about
that point. `jk.classify_twist` classifies the instantaneous twist $[v; \omega]$: pure rotation
when some point is momentarily at rest, i.e. $v \cdot \omega = 0$ with $\omega \neq 0$; general
(a screw motion) otherwise.
"""),
    code("""
w = 1.0  # rad/s; the wheel's centre moves at v = r w
V_centre = np.array([r * w, 0, 0, 0, 0, -w])
contact = np.array([0.0, -r, 0.0])  # from the centre
print("twist at the centre:", jk.classify_twist(V_centre))
print("velocity of the contact point:", V_centre[:3] + np.cross(V_centre[3:], contact))
print("a screw (v along omega):", jk.classify_twist(np.array([0, 0, 0.1, 0, 0, 1.0])))"""),
]


# --------------------------------------------------------------------------------------------
NB03 = [
    md(r"""
# 3. The geometric Jacobian (chapter 4.3.3-4.3.4)

The geometric Jacobian $J(q)$ maps joint velocities to the end effector's **twist**, its linear
velocity $v$ and angular velocity $\omega$ (Eq. 4.21):

$$
\begin{bmatrix} v \\ \omega \end{bmatrix} = J(q)\, \dot q, \qquad
J = \begin{bmatrix} J_v \\ J_\omega \end{bmatrix} \in \mathbb{R}^{6 \times n}.
$$

Unlike the analytical Jacobian, its lower rows are the angular velocity itself, not the rates of
roll, pitch and yaw. It needs no differentiation at all: each column comes from the geometry of
one joint (Table 4.1). With $z_{i-1}$ the unit axis of joint $i$ and $o_{i-1}$ a point on that
axis (the origin of frame $i-1$ in the DH convention), and $o_n$ the end effector's origin, all in
base coordinates:

| | joint $i$ revolute | joint $i$ prismatic |
|---|---|---|
| $J_{v_i}$ | $z_{i-1} \times (o_n - o_{i-1})$ | $z_{i-1}$ |
| $J_{\omega_i}$ | $z_{i-1}$ | $0$ |

A revolute joint turning at $\dot\theta_i$ adds $\dot\theta_i z_{i-1}$ to $\omega$ (Eq. 4.18) and
moves $o_n$ on a circle about its axis ($v = \omega \times r$, Eq. 4.3); a prismatic joint slides
everything after it along $z_{i-1}$ without turning it (Eq. 4.22). The columns stack into
$J = [J_1 \cdots J_n]$ (Eq. 4.24).
"""),
    code(colab("sympy")),
    code(
        SETUP
        + """import sympy as sp

import jaxkin.testing as jkt
from jaxkin import spatial"""
    ),
    md(r"""
## Table 4.1 column by column

For the chapter's cylindrical arm with a spherical wrist (practice question 2: joints R, P, P, R,
R, R), take the frames from forward kinematics, `jk.fk_all` (base first, so row $i-1$ is frame
$i-1$): $z_{i-1}$ is the third column of $R_{i-1}^0$ and $o_{i-1}$ its translation. Build each
column from the table and compare with `jk.geometric_jacobian`, which assembles the same table from
one forward pass.
"""),
    code("""
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
assert jnp.allclose(J_table, J, atol=1e-15)"""),
    code("""
fig = jv.plot_robot(robot, q, frames="all", labels=True, title="PQ2 robot: frames 0-6; dashed: joint axes z_0 ... z_5")"""),
    md(r"""
The same rule, checked three independent ways on the Niryo One (a URDF-style robot whose joint
axes are not all along the DH z axes): `jkt.assert_jacobian_consistent` compares the hand-built
Jacobian with `jax.jacfwd` and `jax.jacrev` of forward kinematics (angular rows from
$\mathrm{vee}(\partial R/\partial q_k\, R^T)$) and with central finite differences on SE(3).
It raises if any differs. (Its default checks all three references of the next section; one is
enough here.)
"""),
    code("""
niryo = jk.robots.load("niryo_one")
q_n = jnp.array([0.2, -0.5, 0.3, 0.1, -0.4, 0.6])
jkt.assert_jacobian_consistent(niryo, q_n, references=("world_aligned",))
print(jk.geometric_jacobian(niryo, q_n))"""),
    md(r"""
## Practice question 4: a revolute-prismatic arm

Joint 1 turns about the base $z$ axis at the base origin; joint 2 slides along an axis
perpendicular to it. (The chapter's figure for this arm was lost; jaxkin's `rp_arm` takes the
prismatic axis perpendicular to $z_0$, via $\alpha_1 = 90°$.) Then $z_0 = (0, 0, 1)$, $o_0 = 0$,
$z_1 = (s_1, -c_1, 0)$ and $o_2 = (s_1 d_2, -c_1 d_2, d_1)$, and Table 4.1 gives

$$
J = \begin{bmatrix} z_0 \times (o_2 - o_0) & z_1 \\ z_0 & 0 \end{bmatrix} =
\begin{bmatrix} c_1 d_2 & s_1 \\ s_1 d_2 & -c_1 \\ 0 & 0 \\ 0 & 0 \\ 0 & 0 \\ 1 & 0 \end{bmatrix}.
$$

SymPy applies the table to the symbolic frames, and jaxkin is compared with the closed form at
random configurations.
"""),
    code("""
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
Js = jax.jit(jax.vmap(lambda q: jk.geometric_jacobian(rp, q)))(qs)
err = max(np.max(np.abs(np.asarray(J_np(q[0], 0.3, q[1]), dtype=float) - J)) for q, J in zip(qs, Js, strict=True))
print(f"PQ4: max |closed form - jaxkin| over 1000 configurations = {err:.1e}")
assert err < 1e-14"""),
    md(r"""
## Which point, which axes: the three references

A twist is the velocity of *a point* expressed in *some axes*. jaxkin's `reference=` names both
(rows are always $[v; \omega]$):

| `reference` | $v$ is the velocity of | expressed in | also called |
|---|---|---|---|
| `"world_aligned"` (default) | the frame's origin | world (base) axes | the textbook's $J$; Pinocchio `LOCAL_WORLD_ALIGNED`; RTB `jacob0` |
| `"local"` | the frame's origin | the frame's own axes | Pinocchio `LOCAL`; RTB `jacobe` |
| `"world"` | the body point now at the world origin | world axes | Pinocchio `WORLD` (spatial velocity) |

With $R$, $p$ the frame's orientation and position:
$J_\text{local} = \mathrm{blkdiag}(R^T, R^T)\, J_\text{world\_aligned}$ and
$J_\text{world} = \begin{bmatrix} J_v + S(p) J_\omega \\ J_\omega \end{bmatrix}$,
since the body point at the origin moves at $v - \omega \times p$.
"""),
    code("""
qd = jnp.array([0.0, -0.04, -0.04, -0.05, 0.0, 0.0])  # the chapter's joint rates, rad/s
T = jk.fk(niryo, q_n)
R, p = T[:3, :3], T[:3, 3]
J_wa, J_loc, J_w = (jk.geometric_jacobian(niryo, q_n, reference=r) for r in ("world_aligned", "local", "world"))
Z = jnp.zeros((3, 3))
assert jnp.allclose(J_loc, jnp.block([[R.T, Z], [Z, R.T]]) @ J_wa, atol=1e-15)
assert jnp.allclose(J_w[:3], J_wa[:3] + spatial.skew(p) @ J_wa[3:], atol=1e-15)
for name, Jr in [("world_aligned", J_wa), ("local", J_loc), ("world", J_w)]:
    print(f"{name:<14} twist = {np.asarray(Jr @ qd)}")
V = J_wa @ qd
print("world linear part = v - omega x p:", np.asarray(V[:3] - jnp.cross(V[3:], p)))"""),
    code("""
fig = jv.plot_twist(niryo, q_n, qd, frames="all")
fig.axes[0].set_title("Niryo One, chapter joint rates: v and omega of the gripper (world_aligned)")"""),
    md(r"""
## Analytical versus geometric Jacobian

If $\phi$ = (roll, pitch, yaw) describes the orientation, its rates are not $\omega$ but are
linearly related to it: $\omega = B(\phi)\, \dot\phi$ with, for
$R = R_z(\psi) R_y(\theta) R_x(\varphi)$,

$$
B(\phi) = \begin{bmatrix} R_z(\psi) R_y(\theta) e_x & R_z(\psi) e_y & e_z \end{bmatrix} =
\begin{bmatrix} c_\psi c_\theta & -s_\psi & 0 \\ s_\psi c_\theta & c_\psi & 0 \\ -s_\theta & 0 & 1
\end{bmatrix}, \qquad \det B = \cos\theta .
$$

Hence $J = \mathrm{blkdiag}(I, B(\phi))\, J_a$, and where $B$ is invertible
$J_a = \mathrm{blkdiag}(I, B(\phi)^{-1})\, J$. At pitch $\theta = \pm 90°$, $B$ is singular: roll
and yaw turn about the same axis, so some angular velocities need infinite roll and yaw rates. This
is a **representation singularity**: the robot moves normally; only the description of its
orientation fails. jaxkin's closed-form $B$ is checked against $B$ by automatic differentiation
($\mathrm{vee}(\partial R/\partial\phi_k R^T)$), then $J_a$ against $B^{-1} J$:
"""),
    code("""
phi = jk.representations.from_matrix(R, "rpy")
B = jk.rate_matrix(phi, "rpy")
print("B(phi) =\\n", B, "\\ndet B =", float(jnp.linalg.det(B)), " cos(pitch) =", float(jnp.cos(phi[1])))
assert jnp.allclose(B, jk.representations.rate_matrix_autodiff(phi, "rpy"), atol=1e-15)
Ja = jk.analytical_jacobian(niryo, q_n, "rpy")
print("max |J_a - blkdiag(I, B^-1) J| =", float(jnp.max(jnp.abs(Ja - jk.analytical_from_geometric(J_wa, phi)))))"""),
    md(r"""
Now drive the Niryo's wrist (joint 5) through the pose where the gripper's $x$ axis points
straight up: there the gripper's pitch is $-90°$. The geometric Jacobian stays bounded; the
analytical one grows like $1/\cos(\text{pitch})$. (`return_margin=True` returns the raw values
with the margin $|\cos(\text{pitch})|$; by default, under `jit`/`vmap` such configurations come out
as NaN, and an eager call raises.)
"""),
    code("""
q5 = np.linspace(0.9, 2.2, 2001)  # rad; joint 5 alone, all other joints at zero
qs = np.zeros((q5.size, 6))
qs[:, 4] = q5


def both(q):
    Ja, margin = jk.analytical_jacobian(niryo, q, "rpy", return_margin=True)
    return jnp.max(jnp.abs(Ja)), jnp.max(jnp.abs(jk.geometric_jacobian(niryo, q))), margin


ja_max, j_max, margin = jax.jit(jax.vmap(both))(qs)
k = int(jnp.argmin(margin))
print(f"closest to the singularity: q5 = {q5[k]:.4f} rad,", f"margin |cos(pitch)| = {float(margin[k]):.1e}")
fig, ax = plt.subplots(figsize=(7, 4))
ax.semilogy(q5, ja_max, label="max |analytical J_a| (rpy)")
ax.semilogy(q5, j_max, label="max |geometric J|")
ax.semilogy(q5, 1 / margin, "--", color="0.5", label="1 / |cos(pitch)|")
ax.set(xlabel="q5 [rad]", ylabel="largest entry", title="rpy representation singularity of the Niryo One gripper")
ax.legend()"""),
    code("""
q_sing = np.zeros(6)
q_sing[4] = np.pi / 2
try:
    jk.analytical_jacobian(niryo, q_sing, "rpy")
except jk.RepresentationSingularityError as e:
    print("RepresentationSingularityError:", e)
print("the geometric Jacobian there is fine:\\n", jk.geometric_jacobian(niryo, q_sing))
fig = jv.plot_robot(niryo, q_sing, frames="tip", title="q5 = pi/2: gripper x axis vertical, pitch = -90 deg")"""),
]


# --------------------------------------------------------------------------------------------
CSV_URL = (
    "https://raw.githubusercontent.com/jaxkin-dev/jaxkin/main/notebooks/data/"
    "niryo_one_velocity_comparison.csv"
)
NB04 = [
    md(r"""
# 4. The Niryo One experiment, done again

The chapter closes with a simulation of the Niryo One desktop arm: joints 2, 3 and 4 turn at
$-0.04$, $-0.04$ and $-0.05$ rad/s while joints 1, 5 and 6 stay still, and after 0.1, 0.2, ...,
0.5 s the end effector's velocity reported by the simulator ("actual") is set beside the
geometric Jacobian's prediction $J(q)\,\dot q$ ("derived"). They differed by about
$10^{-3}$ m/s and $10^{-2}$ rad/s.

Here the experiment is repeated so that each side is independent of the other:

* **simulator**: MuJoCo, with a model written from the robot's published kinematic numbers (the
  same numbers jaxkin's zoo entry holds, but none of jaxkin's code);
* **measured twist**: the simulated end-effector pose, differentiated in time by central
  differences (MuJoCo's own rotation functions; no Jacobian anywhere);
* **predicted twist**: `jk.twist(robot, q, qd)` $= J(q)\,\dot q$ at the simulator's joint values.

Then we look at where a gap of the chapter's size can come from.
"""),
    code(
        colab("mujoco")
        + f"""
    import os
    import urllib.request

    os.makedirs("data", exist_ok=True)
    urllib.request.urlretrieve("{CSV_URL}", "data/niryo_one_velocity_comparison.csv")"""
    ),
    code(
        setup(jnp=False)
        + """import csv

import mujoco
from IPython.display import HTML, Markdown, display"""
    ),
    md(r"""
## The chapter's results

The chapter's table (the companion repository's simulation output), with its gap
$|\text{actual} - \text{derived}|$ per component. Units: m/s for $v$, rad/s for $\omega$, world
axes.
"""),
    code("""
with open("data/niryo_one_velocity_comparison.csv") as f:
    rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
times = np.array([float(c[1:]) for c in rows[0][1:]])  # "t0.1" -> 0.1 s
chapter = {r[0]: np.array(r[1:], dtype=float) for r in rows[1:]}
NAMES = ["vx", "vy", "vz", "wx", "wy", "wz"]
chapter_actual = np.stack([chapter[f"{n}_actual"] for n in NAMES], axis=1)  # (5 times, 6)
chapter_gap = np.abs(chapter_actual - np.stack([chapter[f"{n}_derived"] for n in NAMES], axis=1))
print("times [s]:", times)
print("chapter's largest gap: v", chapter_gap[:, :3].max(), "m/s, omega", chapter_gap[:, 3:].max(), "rad/s")"""),
    md(r"""
## The robot and its start pose

jaxkin's Niryo One (`jk.robots.load("niryo_one")`) is built from the manufacturer's description:
six revolute joints, each turning about the $z$ axis of its child frame, placed by URDF
`xyz`/`rpy` offsets. The chapter does not say where its simulation started. We start from **all
joints at zero**, the description's reference pose, which is where a simulator that loads the
description without further instructions puts the robot: arm upright, forearm horizontal.
(It happens to be a wrist singularity, joints 4 and 6 aligned; joints 5 and 6 do not move in this
experiment, and the twist $J\dot q$ is well defined at any pose.)
"""),
    code("""
robot = jk.robots.load("niryo_one")
q0 = np.zeros(6)  # start pose, rad
qd = np.array([0.0, -0.04, -0.04, -0.05, 0.0, 0.0])  # joints 2, 3, 4 driven, rad/s
print(robot)
fig = jv.plot_robot(robot, q0, frames="all", labels=True, title="Niryo One, start pose (all joints 0)")"""),
    md(r"""
## A MuJoCo model from the published numbers

A few lines turn the robot's joint list into MJCF: one nested `<body>` per link at the joint's
`xyz` offset, rotated by its `rpy` angles (MuJoCo `eulerseq="XYZ"`: fixed-axis roll, pitch, yaw,
the URDF convention), and a `<joint>` about the joint's axis. The links get small illustrative
masses; the first experiment moves the joints kinematically and does not use them. MuJoCo then
computes forward kinematics with its own code; it agrees with jaxkin's to rounding.
"""),
    code("""
def mjcf_from_robot(robot, mass=0.3, velocity_gain=None):
    \"\"\"MJCF text for a URDF-style jaxkin robot (placements xyz/rpy, joints about `axis`).

    Every link gets a point mass `mass` (kg). With `velocity_gain`, each joint gets a velocity
    actuator (torque = gain * (ctrl - qvel)).
    \"\"\"
    xyz, rpy = np.asarray(robot.params["xyz"]), np.asarray(robot.params["rpy"])
    axis, lower, upper = np.asarray(robot.axis), np.asarray(robot.lower), np.asarray(robot.upper)
    children = {}
    for j, parent in enumerate(robot.parents):
        children.setdefault(parent, []).append(j)

    def fmt(v):
        return " ".join(repr(float(x)) for x in v)

    def body(j, pad):
        name = robot.frame_names[j + 1]
        s = f'{pad}<body name="{name}" pos="{fmt(xyz[j])}" euler="{fmt(rpy[j])}">\\n'
        s += f'{pad}  <inertial pos="0 0 0" mass="{mass}" diaginertia="1e-4 1e-4 1e-4"/>\\n'
        if robot.kinds[j] != "fixed":
            i = robot.q_index[j]
            kind = "hinge" if robot.kinds[j] == "revolute" else "slide"
            s += (
                f'{pad}  <joint name="{robot.joint_names[i]}" type="{kind}" axis="{fmt(axis[j])}"'
                f' range="{float(lower[i])!r} {float(upper[i])!r}"'
                ' damping="0.05" armature="0.01"/>\\n'
            )
        s += "".join(body(k, pad + "  ") for k in children.get(j + 1, []))
        return s + f"{pad}</body>\\n"

    actuators = ""
    if velocity_gain is not None:
        actuators = "".join(f'    <velocity joint="{n}" kv="{velocity_gain}"/>\\n' for n in robot.joint_names)
    return f\"\"\"<mujoco model="{robot.name}">
  <compiler angle="radian" eulerseq="XYZ" autolimits="true"/>
  <option timestep="0.001" integrator="implicitfast"/>
  <worldbody>
{"".join(body(j, "    ") for j in children.get(0, []))}  </worldbody>
  <actuator>
{actuators}  </actuator>
</mujoco>\"\"\"


xml = mjcf_from_robot(robot)
print(xml)
model = mujoco.MjModel.from_xml_string(xml)
data = mujoco.MjData(model)
tip = model.body("gripper_link").id  # the end effector: jaxkin's tip frame

worst = 0.0
for q in rng.uniform(np.asarray(robot.lower), np.asarray(robot.upper), size=(100, 6)):
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    T = np.asarray(jk.fk(robot, q))
    worst = max(worst, np.abs(T[:3, 3] - data.xpos[tip]).max(), np.abs(T[:3, :3] - data.xmat[tip].reshape(3, 3)).max())
print(f"MuJoCo vs jaxkin forward kinematics, 100 random poses: max difference {worst:.1e}")
assert worst < 1e-14"""),
    md(r"""
## Simulate, measure, predict

The joints are integrated with a 1 ms step ($q \leftarrow q + \dot q\, \Delta t$), and after each
step MuJoCo places the links (`mj_kinematics`). The measured twist at sample $k$ is the central
difference of the recorded end-effector pose,

$$
v_k = \frac{p_{k+1} - p_{k-1}}{2\Delta t}, \qquad
\omega_k = \frac{\log\!\left(R_{k+1} R_{k-1}^T\right)^\vee}{2\Delta t},
$$

accurate to $O(\Delta t^2)$; the prediction is $J(q_k)\,\dot q$ with jaxkin.
"""),
    code("""
dt, steps = 1e-3, 600
qs = np.zeros((steps + 1, 6))
ps, Rs = np.zeros((steps + 1, 3)), np.zeros((steps + 1, 3, 3))
data.qpos[:] = q0
for k in range(steps + 1):
    mujoco.mj_kinematics(model, data)
    qs[k], ps[k], Rs[k] = data.qpos, data.xpos[tip], data.xmat[tip].reshape(3, 3)
    data.qpos[:] += qd * dt


def rotation_vector(R):
    \"\"\"log(R) as a vector, with MuJoCo's quaternion functions.\"\"\"
    quat, w = np.zeros(4), np.zeros(3)
    mujoco.mju_mat2Quat(quat, R.ravel())
    mujoco.mju_quat2Vel(w, quat, 1.0)
    return w


def measured_twist(k, back=1, ahead=1):
    \"\"\"Finite-difference twist from the recorded poses k - back and k + ahead.\"\"\"
    h = (back + ahead) * dt
    v = (ps[k + ahead] - ps[k - back]) / h
    w = rotation_vector(Rs[k + ahead] @ Rs[k - back].T) / h
    return np.concatenate([v, w])


ks = np.rint(times / dt).astype(int)
measured = np.stack([measured_twist(k) for k in ks])
twists = jax.jit(jax.vmap(lambda q, qd: jk.twist(robot, q, qd)))
predicted = np.asarray(twists(qs[ks], np.broadcast_to(qd, (len(ks), 6))))
gap = np.abs(measured - predicted)
print("our largest gap: v", gap[:, :3].max(), "m/s, omega", gap[:, 3:].max(), "rad/s")"""),
    md(r"""
## The comparison, shaped like the chapter's table

For each component: the measured and predicted values after 0.1 ... 0.5 s, our gap, and the
chapter's gap at the same times (its simulation started elsewhere, so its values differ from
ours; the gaps are what compare).
"""),
    code("""
header = "| quantity | " + " | ".join(f"t = {t:.1f} s" for t in times) + " |"
lines = [header, "|---" * (len(times) + 1) + "|"]
for c, name in enumerate(NAMES):
    unit = "m/s" if c < 3 else "rad/s"
    for label, values in [
        (f"{name}_measured (MuJoCo pose, differentiated) [{unit}]", measured[:, c]),
        (f"{name}_predicted (jaxkin J q̇) [{unit}]", predicted[:, c]),
        (f"**{name} gap, ours**", gap[:, c]),
        (f"**{name} gap, chapter**", chapter_gap[:, c]),
    ]:
        lines.append(f"| {label} | " + " | ".join(f"{x:.3e}" for x in values) + " |")
display(Markdown("\\n".join(lines)))"""),
    code("""
fig, ax = plt.subplots(figsize=(8, 4))
for c, name in enumerate(NAMES):
    ax.semilogy(times, gap[:, c], "o-", color=f"C{c}", label=f"{name}, ours")
    ax.semilogy(times, chapter_gap[:, c], "x--", color=f"C{c}", alpha=0.6, label=f"{name}, chapter")
ax.set(xlabel="time [s]", ylabel="|measured - predicted|  [m/s or rad/s]")
ax.set_title("Gap between measured and predicted twist: ours (o) and the chapter's (x)")
ax.legend(ncol=4, fontsize=7)
ratio = chapter_gap.max() / gap.max()
print(f"ours: {gap.max():.1e}, chapter: {chapter_gap.max():.1e}, ratio {ratio:.0e}")"""),
    md(r"""
Our gap is at the level of the finite-difference error ($\approx 10^{-11}$), eight orders of
magnitude below the chapter's: when the simulator, the measurement and the prediction describe the
same robot, frame and instant, $J(q)\,\dot q$ *is* the end-effector velocity.

## Where can a gap of $10^{-3}$ come from?

**The chapter's joints were not turning at constant rates.** With constant joint rates the angular
velocity $\omega = \sum_i \dot q_i z_i$ changes only because the axes turn: $\dot z_i$ is
$\omega_{i-1} \times z_i$, so

$$
\dot\omega = \sum_{j < i} \dot q_j \dot q_i \,(z_j \times z_i), \qquad
|\dot\omega| \le \sum_{j<i} |\dot q_j \dot q_i| = 0.0056 \text{ rad/s}^2
$$

for the chapter's rates, whatever the pose. Between 0.1 and 0.5 s, $\omega$ can therefore change
by at most $0.0022$ rad/s. The chapter's "actual" $\omega$ changed ten times more: its joint
velocities were still changing (actuators accelerating the arm against gravity), so the
commanded rates $-0.04, -0.04, -0.05$ were not what the joints did.
"""),
    code("""
bound = sum(abs(qd[i] * qd[j]) for i in range(6) for j in range(i)) * (times[-1] - times[0])
change_chapter = np.linalg.norm(chapter_actual[-1, 3:] - chapter_actual[0, 3:])
change_ours = np.linalg.norm(measured[-1, 3:] - measured[0, 3:])
print(f"bound on |omega(0.5) - omega(0.1)| at constant rates: {bound:.4f} rad/s")
print(f"ours: {change_ours:.4f} rad/s      the chapter's 'actual': {change_chapter:.4f} rad/s")"""),
    md(r"""
**A dynamic simulation shows the mechanism.** Give each joint a MuJoCo velocity actuator
(torque $= k_v(\dot q_\text{cmd} - \dot q)$, $k_v = 100$ N·m·s/rad), switch gravity on, and start
from rest. The joints now lag the commanded rates. Compare the measured twist with $J(q)$ times
the *commanded* rates and times the *measured* joint velocities, and difference the pose over
1 ms (central) or over 50 ms (backward: a coarse simulation step):
"""),
    code("""
dyn = mujoco.MjModel.from_xml_string(mjcf_from_robot(robot, velocity_gain=100.0))
dd = mujoco.MjData(dyn)
dd.qpos[:], dd.ctrl[:] = q0, qd
mujoco.mj_forward(dyn, dd)
qs_d, qds_d = np.zeros((steps + 1, 6)), np.zeros((steps + 1, 6))
for k in range(steps + 1):
    qs_d[k], qds_d[k], ps[k], Rs[k] = dd.qpos, dd.qvel, dd.xpos[tip], dd.xmat[tip].reshape(3, 3)
    mujoco.mj_step(dyn, dd)
print("joint velocities at 0.5 s:", qds_d[ks[-1]], "(commanded:", qd, ")")

lines = ["| prediction | differencing | max gap v [m/s] | max gap ω [rad/s] |", "|---|---|---|---|"]
for label, rates in [("J(q) q̇ commanded", np.broadcast_to(qd, (len(ks), 6))), ("J(q) q̇ measured", qds_d[ks])]:
    pred = np.asarray(twists(qs_d[ks], rates))
    for how, back, ahead in [("central, 1 ms", 1, 1), ("backward, 50 ms", 50, 0)]:
        meas = np.stack([measured_twist(k, back, ahead) for k in ks])
        g = np.abs(meas - pred)
        lines.append(f"| {label} | {how} | {g[:, :3].max():.1e} | {g[:, 3:].max():.1e} |")
lines.append(f"| the chapter | ? | {chapter_gap[:, :3].max():.1e} | {chapter_gap[:, 3:].max():.1e} |")
display(Markdown("\\n".join(lines)))"""),
    md(r"""
With the joints' measured velocities, $J(q)\dot q$ again matches the differentiated pose (to the
differencing error, larger now because the joints accelerate). With the commanded rates the gap is
$10^{-3}$ to $10^{-2}$, the chapter's size; coarse backward differences add more. Our guess is
that the chapter's gap came from such a mismatch of rates or instants, not from the Jacobian. The
link masses and gains here are illustrative, so only the orders of magnitude mean something.

## The motion

The experiment's motion lasts half a second and is too small to see, so the animation runs the
same joint rates for 10 s (frames every 0.4 s, played 4x faster than real time); the red arrow is
the tip's linear velocity (scaled), the purple line its path.
"""),
    code("""
t_anim = np.arange(0.0, 10.0 + 1e-9, 0.4)
q_anim = q0 + t_anim[:, None] * qd
fig = plt.figure(figsize=(4.5, 4.5), dpi=72)  # a small figure keeps the embedded frames small
anim = jv.animate(
    robot, q_anim, dt=0.4, qds=np.broadcast_to(qd, q_anim.shape), speed=4.0,
    ax=fig.add_subplot(projection="3d"), title="Niryo One",
)  # fmt: skip
plt.close(fig)  # show the animation only, not its last frame as a still
HTML(anim.to_jshtml())"""),
]


# --------------------------------------------------------------------------------------------
NB05 = [
    md(r"""
# 5. Velocities and manipulability over the whole workspace

The Jacobian changes with the configuration, and so does what the end effector can do: how fast it
can move, in which directions easily, and where it loses a direction altogether (a singularity).
This notebook samples **a million configurations** of the Niryo One and, for each, computes the
geometric Jacobian, the twist for random joint velocities, the singular values of $J$, and the
fastest the tip can move within the joint speed limits, then maps them over the workspace.

jaxkin's kernels are written for one configuration; `jax.vmap` batches them, and
`jaxkin.batch.chunked_map` streams the million rows through one compiled function in chunks and
collects the results in numpy arrays.
"""),
    code(colab()),
    code(
        SETUP
        + """import itertools

from jaxkin.batch import chunked_map"""
    ),
    md(r"""
## What is computed per configuration

* the tip's position, and the wrist centre's (for the singularity study below);
* $J(q)$, world-aligned, rows $[v; \omega]$, and the twist $J(q)\,\dot q$ for a random
  $\dot q$ with each joint rate uniform in $[-1, 1]$ rad/s (the Niryo's speed limit);
* the singular values $\sigma_1 \ge \dots \ge \sigma_6$ of $J$ and $\sigma^v_1 \ge \sigma^v_2 \ge
  \sigma^v_3$ of its translational block $J_v$ (m/s per rad/s). The unit joint-speed ball maps to
  an ellipsoid of tip velocities with these semi-axes; its volume is proportional to Yoshikawa's
  **manipulability** $w_v = \sqrt{\det J_v J_v^T} = \sigma^v_1 \sigma^v_2 \sigma^v_3$. The ratio
  $\sigma_6 / \sigma_1$ (inverse condition number) goes to 0 at a singularity. ($J$ mixes m/s and
  rad/s rows, so $\sigma_6/\sigma_1$ depends on the unit of length; $w_v$ does not mix units.)
* the fastest tip speed allowed by the joint limits $|\dot q_i| \le 1$ rad/s:
  $\max_{|\dot q_i| \le 1} |J_v \dot q|$. A convex function's maximum over a box is at a corner,
  so it is the largest $|J_v s|$ over the $2^6 = 64$ sign vectors $s$.
"""),
    code("""
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


N = 1_000_000
lower, upper = np.asarray(robot.lower), np.asarray(robot.upper)
qs = rng.uniform(lower, upper, size=(N, robot.dof))
qds = rng.uniform(-1.0, 1.0, size=(N, robot.dof))
res, stats = chunked_map(per_configuration, qs, qds, return_stats=True)
print(f"{N:,} configurations: compile {stats.compile_seconds:.1f} s, "
      f"run {stats.run_seconds:.1f} s ({stats.rate:,.0f} configurations/s)")  # fmt: skip
sigma, sigma_v = res["sigma"], res["sigma_v"]
w_v = np.prod(sigma_v, axis=1)  # translational manipulability
inv_cond = sigma[:, -1] / sigma[:, 0]
speed, turn = np.linalg.norm(res["twist"][:, :3], axis=1), np.linalg.norm(res["twist"][:, 3:], axis=1)"""),
    md(r"""
A spot check of the batched results against single calls and numpy's SVD, and of the corner rule
against the speeds actually reached by the random $\dot q$ (none may exceed $v_\text{max}$):
"""),
    code("""
idx = rng.choice(N, size=200, replace=False)
J_spot = jax.jit(jax.vmap(lambda q: jk.geometric_jacobian(robot, q)))(qs[idx])
assert np.allclose(np.linalg.svd(np.asarray(J_spot), compute_uv=False), sigma[idx], atol=1e-12)
assert np.allclose(np.einsum("nij,nj->ni", J_spot, qds[idx]), res["twist"][idx], atol=1e-14)
assert np.all(speed <= res["v_max"] + 1e-12)
print("spot checks passed; the random rates reach on average", f"{np.mean(speed / res['v_max']):.0%} of v_max")"""),
    md(r"""
## Distributions
"""),
    code("""
fig, axes = plt.subplots(2, 2, figsize=(11, 7))
axes[0, 0].hist(speed, bins=200, color="C3", alpha=0.8, label="|v|, random q̇")
axes[0, 0].hist(res["v_max"], bins=200, color="0.4", alpha=0.6, label="v_max (|q̇_i| ≤ 1)")
axes[0, 0].set(xlabel="tip speed [m/s]", ylabel="configurations", title="linear speed")
axes[0, 0].legend()
axes[0, 1].hist(turn, bins=200, color="C0")
axes[0, 1].set(xlabel="|ω| [rad/s]", title="angular speed, random q̇")
axes[1, 0].hist(w_v, bins=200, color="C4")
axes[1, 0].set(xlabel="w_v = σ1 σ2 σ3 of J_v  [(m/s)³ per (rad/s)³]", title="translational manipulability")
axes[1, 1].hist(np.log10(inv_cond), bins=200, color="C2")
axes[1, 1].set(xlabel="log10(σ6 / σ1) of J", title="distance from singularity (inverse condition number)")
fig.suptitle(f"Niryo One, {N:,} configurations uniform within the joint limits")
fig.tight_layout()"""),
    md(r"""
## Maps over the workspace

Joint 1 turns the whole arm about the base's vertical axis, so none of these quantities depends on
$q_1$ or on the direction of the tip around that axis: the workspace is fully described by the
tip's distance from the axis, $r = \sqrt{x^2 + y^2}$, and its height $z$. Each map bins the million
tip positions in $(r, z)$ and shows the mean of a quantity per bin.
"""),
    code("""
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
fig.tight_layout()"""),
    md(r"""
## Where the singularities are

Within the joint limits two families show up. **Wrist**: at $q_5 = 0$ the axes of joints 4 and 6
line up and the wrist loses a rotation, whatever the other joints do. **Shoulder**: when the wrist
centre (where the axes of joints 4 and 5 meet, the origin of `wrist_link`) is on the base axis,
turning joint 1 only spins it in place. The **elbow** singularities, upper arm and forearm in line
(stretched or folded back), lie outside the Niryo's joint-3 limits: the third panel sweeps $q_3$
over a full turn and shows the arm's smallest singular value (joints 2 and 3 moving the wrist
centre) reaching zero only beyond the limits.
"""),
    code("""
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
axes[2].set(xlabel="q3 [rad]", ylabel="smallest singular value [m/s per rad/s]", title="elbow: stretched / folded")
axes[2].legend()
fig.tight_layout()
print("elbow singular near q3 =", np.round(q3[s_arm < 1e-3], 3), "; limits:", lower[2], upper[2])
worst = int(np.argmin(inv_cond))
print("most singular sample: q =", qs[worst], " σ =", sigma[worst], " wrist centre r =", r_wrist[worst])"""),
    code("""
best = int(np.argmax(w_v))
fig = plt.figure(figsize=(11, 5))
for i, (k, title) in enumerate([(best, "largest manipulability w_v"), (worst, "most singular sample")]):
    ax = fig.add_subplot(1, 2, i + 1, projection="3d")
    jv.plot_ellipsoid(robot, qs[k], ax=ax, frames=None)
    ax.set_title(f"{title}\\nσ(J_v) = {np.round(sigma_v[k], 3)} m/s per rad/s")"""),
]


# --------------------------------------------------------------------------------------------
NB06 = [
    md(r"""
# 6. Singularities, inverse velocity, inverse kinematics and calibration

The chapter stops at $V = J(q)\,\dot q$. This notebook runs it backwards and uses it: how close a
configuration is to a singularity (manipulability), which joint velocities produce a desired twist
(and what goes wrong near a singularity), how to reach a pose (inverse kinematics), and how to
correct a robot's model from measured poses (calibration). Everything is for the Niryo One.

The functions live in `jaxkin.analysis`, `jaxkin.inverse_velocity`, `jaxkin.ik` and
`jaxkin.calibration`.
"""),
    code(colab()),
    code(
        SETUP
        + """from jaxkin import analysis, calibration, ik
from jaxkin import inverse_velocity as iv

robot = jk.robots.load("niryo_one")"""
    ),
    md(r"""
## Measures of manipulability

With $\sigma_1 \ge \dots \ge \sigma_m$ the singular values of (rows of) $J$: Yoshikawa's
$w = \sqrt{\det J J^T} = \prod_i \sigma_i$ (the velocity ellipsoid's volume, up to a constant), the
inverse condition number $\sigma_m / \sigma_1$ and the smallest singular value $\sigma_m$. All
three vanish at a singularity. Below, joint 5 sweeps through the Niryo's wrist singularity
$q_5 = 0$ (joints 4 and 6 aligned); the translational measure (rows $v$ only) does not notice it,
since aligning two wrist axes costs a rotation, not a translation.
"""),
    code("""
q_ref = np.array([0.0, -0.3, 0.2, 0.4, 0.6, 0.1])
q5 = np.linspace(-0.6, 0.6, 241)
qs = np.tile(q_ref, (q5.size, 1))
qs[:, 4] = q5
CASES = [("yoshikawa", "all"), ("inverse_condition", "all"), ("min_singular_value", "all"), ("yoshikawa", "translation")]


def measures(q):
    J = jk.geometric_jacobian(robot, q)
    return jnp.stack([analysis.manipulability(J, m, rows=r) for m, r in CASES])


M = np.asarray(jax.jit(jax.vmap(measures))(qs))
fig, ax = plt.subplots(figsize=(7, 4))
for k, (m, r) in enumerate(CASES):
    ax.plot(q5, M[:, k] / M[:, k].max(), ls=["-", "--", ":", "-"][k], lw=2, label=f"{m} ({r} rows)")
ax.set(xlabel="q5 [rad]", ylabel="measure / its maximum on the sweep", title="Niryo One, wrist singularity at q5 = 0")
ax.legend(fontsize=8)

q_sing = q_ref.copy()
q_sing[4] = 0.0
dep = analysis.dependent_columns(jk.geometric_jacobian(robot, q_sing))
print("at q5 = 0: nullity", int(dep.nullity), "; dependent joints:", [n for n, m in zip(robot.joint_names, dep.mask, strict=True) if m])
print("null-space joint velocity (moves nothing):", np.round(np.asarray(dep.null_space[:, 0]), 4))"""),
    md(r"""
## Inverse velocity: which $\dot q$ gives a desired twist?

For a square, invertible $J$ the answer is $\dot q = J^{-1} V$; in general the pseudo-inverse
$\dot q = J^+ V$ gives the least-squares, minimum-norm solution. Near a singularity $J^+$ has a
huge singular value $1/\sigma_6$, so a twist with any component along the lost direction asks for
enormous joint speeds. **Damped least squares**,
$\dot q = J^T (J J^T + \lambda^2 I)^{-1} V$, trades a small twist error for bounded speeds
($|\dot q| \le |V| / 2\lambda$). The desired twist here turns the gripper about world $x$ at
0.1 rad/s, a direction the wrist loses at $q_5 = 0$. (Exactly at $q_5 = 0$ the pseudo-inverse
drops the lost direction, its singular value being below `rcond`, so its speed falls back:
the pseudo-inverse is discontinuous at the singularity; damped least squares is smooth.)
"""),
    code("""
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
ax.set(xlabel="q5 [rad]", ylabel="rad/s", title="Joint speeds for ω = 0.1 rad/s about x, near the wrist singularity")
ax.legend(fontsize=8)"""),
    md(r"""
**Resolved-rate control** integrates this: at each step, $\dot q = J^{\#}(V_\text{path} + K e)$
with $e$ the pose error, then $q \leftarrow q + \dot q\, \Delta t$. The gripper follows a 10 cm
straight line in 2 s:
"""),
    code("""
T_start = np.asarray(jk.fk(robot, q_ref))
s = np.linspace(0.0, 1.0, 201)
T_path = np.repeat(T_start[None], s.size, axis=0)
T_path[:, 1, 3] += 0.1 * s  # 10 cm along y
T_path[:, 2, 3] -= 0.05 * s  # and 5 cm down
run = iv.resolved_rate_control(robot, q_ref, T_path, dt=0.01)
tip = np.asarray(jax.vmap(lambda q: jk.fk(robot, q)[:3, 3])(run.q))
print(f"largest tracking error: {float(run.max_position_error) * 1e3:.3f} mm,",
      f"{float(run.max_orientation_error):.1e} rad")  # fmt: skip
fig = plt.figure(figsize=(10, 4.5))
ax = fig.add_subplot(1, 2, 1, projection="3d")
jv.plot_robot(robot, run.q[-1], ax=ax, frames=None, title="resolved-rate control: path and final pose")
ax.plot(*T_path[:, :3, 3].T, "k--", lw=2, label="desired path")
ax.plot(*tip.T, color="C4", lw=1.5, label="reached")
ax.legend(fontsize=8)
ax = fig.add_subplot(1, 2, 2)
ax.plot(s * 2.0, np.asarray(run.qd))
ax.set(xlabel="t [s]", ylabel="q̇ [rad/s]", title="joint velocities")
ax.legend(robot.joint_names, fontsize=7)
fig.tight_layout()"""),
    md(r"""
## Inverse kinematics

`ik.solve_ik` finds $q$ with $\mathrm{fk}(q) = T_\text{target}$ within the joint limits
(Levenberg-Marquardt steps $\Delta q = (J^T J + \lambda I)^{-1} J^T e$, restarted from random seeds
when one stalls), for one target or a batch in one compiled loop. Targets here are poses of random
reachable configurations; the solver starts from all joints at zero and is checked by forward
kinematics.
"""),
    code("""
q_true = rng.uniform(0.8 * np.asarray(robot.lower), 0.8 * np.asarray(robot.upper), size=(50, 6))
targets = jax.vmap(lambda q: jk.fk(robot, q))(q_true)
sol = ik.solve_ik(robot, targets, np.zeros(6), num_seeds=8, throw=False)
converged = np.asarray(sol.converged)
reached = jax.vmap(lambda q: jk.fk(robot, q))(sol.q)
pos_err = np.linalg.norm(np.asarray(reached[:, :3, 3] - targets[:, :3, 3]), axis=1)
print(f"converged: {converged.sum()} of {len(converged)};",
      f"position error of those: max {pos_err[converged].max():.1e} m")  # fmt: skip
print("result codes of the others:", [ik.RESULTS(int(r)).name for r in np.asarray(sol.result)[~converged]])
same = np.all(np.abs(np.asarray(sol.q) - q_true) < 1e-6, axis=1)
print(f"solutions equal to the configuration the target came from: {same.sum()}",
      "(the others are other branches: elbow, wrist flips)")  # fmt: skip"""),
    md(r"""
## Calibration

A real robot differs from its drawing by fractions of a millimetre. Calibration measures the
gripper's pose at several configurations (with a laser tracker, say) and fits the model's
parameters to the measurements, differentiating straight through forward kinematics (the model's
numbers are leaves of a JAX pytree). First `calibration.identifiability` asks which parameters
the measurements can determine at all: offsets along a joint's own axis, for example, cannot be
told apart from offsets of the next link. Then we make a "true" robot by perturbing only the
identifiable link offsets by about a millimetre, measure it at 40 configurations with 20 µm of
noise, and fit:
"""),
    code("""
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
T_meas = np.array(jax.vmap(lambda q: jk.fk(true_robot, q))(q_meas))  # a writable copy
T_meas[:, :3, 3] += rng.normal(0.0, 20e-6, (40, 3))  # tracker noise, 20 um

fit = calibration.calibrate(robot, q_meas, T_meas, {"xyz": free}, position_sigma=20e-6, orientation_sigma=1e-3)
err_before = np.abs(np.asarray(robot.params["xyz"]) - xyz_true)[free]
err_after = np.abs(np.asarray(fit.params["xyz"]) - xyz_true)[free]
print(f"converged {bool(fit.converged)} in {int(fit.steps)} steps")
before, after = float(fit.rms_position_before) * 1e3, float(fit.rms_position_after) * 1e3
print(f"rms position error: {before:.3f} mm -> {after:.4f} mm",
      f"(the noise alone: {20e-3 * np.sqrt(3):.4f} mm in 3-D)")  # fmt: skip
print(f"parameter error: max {err_before.max() * 1e3:.3f} mm -> {err_after.max() * 1e3:.4f} mm; "
      f"predicted std up to {np.asarray(fit.std['xyz'])[free].max() * 1e3:.4f} mm")  # fmt: skip"""),
]


# --------------------------------------------------------------------------------------------
NOTEBOOKS = {
    "01_analytical_jacobian": NB01,
    "02_angular_velocity": NB02,
    "03_geometric_jacobian": NB03,
    "04_niryo_one_experiment": NB04,
    "05_workspace_velocities": NB05,
    "06_singularities_ik_calibration": NB06,
}


def main(names: list[str]) -> None:
    paths = []
    for name in names or list(NOTEBOOKS):
        path = HERE / f"{name}.ipynb"
        nbformat.write(notebook(NOTEBOOKS[name]), path)
        paths.append(str(path))
        print("wrote", path.relative_to(HERE.parent))
    ruff = shutil.which("ruff")
    if ruff is None:
        print("ruff not found: the notebooks are not formatted")
        return
    subprocess.run([ruff, "format", "--quiet", *paths], check=True)


if __name__ == "__main__":
    main(sys.argv[1:])
