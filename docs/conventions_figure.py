"""The conventions page's figure: one twist of a two-link arm in the three references.

Drawn when the site is built (Sphinx's ``plot`` directive runs this file); also runs on its own:
``python3 docs/conventions_figure.py`` shows it. Every arrow is computed by jaxkin: the frames by
``jk.fk_all`` (``T_world_link``), the velocities by ``jk.twist(..., reference=...)``.
"""

import matplotlib.pyplot as plt
import numpy as np

import jaxkin as jk

robot = jk.robots.load("two_link_planar")
q = np.array([0.5, 0.9])
qd = np.array([0.6, -0.3])
Ts = np.asarray(jk.fk_all(robot, q))  # (3, 4, 4): T_world_base, T_world_link1, T_world_link2
T = Ts[-1]  # T_world_tip
p, R = T[:3, 3], T[:3, :3]
V = {ref: np.asarray(jk.twist(robot, q, qd, reference=ref)) for ref in jk.jacobians.REFERENCES}

fig, ax = plt.subplots(figsize=(7.5, 6.0))
ax.plot(Ts[:, 0, 3], Ts[:, 1, 3], "o-", color="0.35", lw=5, ms=9, zorder=1)


def frame(T_world_frame, label, length=0.3):
    """The frame's x (red) and y (green) axes at its origin, and its name."""
    o = T_world_frame[:2, 3]
    for axis, color in ((0, "tab:red"), (1, "tab:green")):
        d = T_world_frame[:2, axis] * length
        ax.annotate("", o + d, o, arrowprops={"arrowstyle": "-|>", "color": color, "lw": 1.5})
    ax.text(*(o + np.array([-0.1, -0.18])), label, fontsize=10)


def arrow(start, vec, color, text, offset):
    ax.annotate("", start + vec, start, arrowprops={"arrowstyle": "-|>", "color": color, "lw": 2.5})
    ax.text(*(start + vec + offset), text, color=color, fontsize=9.5)


frame(Ts[0], "world (base)")
frame(T, "tip: T_world_tip")
v_wa, v_local, v_world = V["world_aligned"][:2], V["local"][:2], V["world"][:2]
arrow(p[:2], v_wa, "tab:blue", f"world_aligned: v = {np.round(v_wa, 2)}\n(tip origin, world axes)",
      np.array([-1.1, 0.1]))  # fmt: skip
for k in range(2):  # the local components: the same arrow measured along the tip's own axes
    ax.plot(*np.stack([p[:2], p[:2] + v_local[k] * R[:2, k]]).T, "--", color="tab:purple", lw=1.5)
ax.text(*(p[:2] + np.array([0.15, 0.55])),
        f"local: v = R^T v = {np.round(v_local, 2)}\n(same arrow, tip axes: dashed)",
        color="tab:purple", fontsize=9.5)  # fmt: skip
arrow(np.zeros(2), v_world, "tab:orange",
      f"world: v - ω × p = {np.round(v_world, 2)}\n(point at the world origin, world axes)",
      np.array([-1.2, 0.12]))  # fmt: skip
omega = V["world_aligned"][5]
ax.set_title(
    f"One twist [v; ω] = J(q) q̇ of a two-link arm, ω_z = {omega:.2f} rad/s in every reference\n"
    "red/green: x/y axes of each frame; rows [v; ω], linear first",
    fontsize=10,
)
ax.set_aspect("equal")
ax.set_xlim(-1.4, 2.6)
ax.set_ylim(-0.6, 2.6)
ax.set_xlabel("x_world (m)")
ax.set_ylabel("y_world (m)")
ax.grid(alpha=0.3)

if __name__ == "__main__":
    plt.show()
