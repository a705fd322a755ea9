# %% [markdown]
# # 7. Whole-body kinematics: a humanoid's centre of mass, whole-body IK, a retargeted motion
#
# The earlier notebooks treat arms: one chain, one end effector. A humanoid has a floating base
# (six velocities more, the base's pose a unit quaternion in $q$), several end effectors at once
# (feet and hands), and a centre of mass that must stay over its feet. This notebook uses
# Unitree's G1 (29 joints, from `example-robot-data`):
#
# 1. the centre of mass $c(q)$, its Jacobian, and the support polygon of the feet;
# 2. whole-body inverse kinematics: both feet held where they are, a hand moved, the centre of
#    mass kept over the feet;
# 3. a motion: the hand follows a path, solved step by step (`jk.motion.retarget`, each step
#    warm-started from the previous one), drawn as a strip of stills.
#
# Everything is float64; one forward pass serves all the frames of a step.

# %%
import jax

jax.config.update("jax_enable_x64", True)  # float64 for this notebook
import matplotlib.pyplot as plt
import numpy as np

import jaxkin as jk
import jaxkin.viz as jv
from jaxkin import motion

np.set_printoptions(precision=4, suppress=True, linewidth=110)

robot = jk.robots.load("erd/g1_29dof_rev_1_0", floating_base=True)
FEET = ["left_ankle_roll_link", "right_ankle_roll_link"]
HAND = "right_rubber_hand"
q0 = jk.neutral(robot)  # the base at the origin, every joint at 0
print(f"{robot.name}: nq = {robot.nq} (7 for the base), nv = {robot.nv}, mass {robot.mass:.2f} kg")

# %% [markdown]
# ## The centre of mass over the support polygon
#
# $c(q) = \sum_i m_i c_i(q) / \sum_i m_i$ over the links' masses $m_i$ and centres $c_i$ (from the
# URDF's `<inertial>` elements); `jk.com_jacobian` gives $J_c = \partial \dot c / \partial v$
# (3, nv), in the same velocity convention as the frame Jacobians. Standing still, the robot is
# statically balanced when the ground projection of $c$ lies inside the support polygon, the
# convex hull of the feet's contact area. The feet outlines below are rectangles of about the
# G1's sole (0.20 m by 0.07 m, 0.03 m ahead of the ankle and 0.03 m below the ankle roll link
# origin): an approximation for the picture, not the URDF's collision geometry.

# %%
FOOT_LENGTH, FOOT_WIDTH, FOOT_AHEAD, FOOT_DROP = 0.20, 0.07, 0.03, 0.03


def foot_corners(T):
    """(4, 3) corners of a foot's sole, for the foot frame's pose T (4, 4)."""
    x = np.array([-0.5, 0.5, 0.5, -0.5]) * FOOT_LENGTH + FOOT_AHEAD
    y = np.array([-0.5, -0.5, 0.5, 0.5]) * FOOT_WIDTH
    local = np.stack([x, y, np.full(4, -FOOT_DROP), np.ones(4)])
    return (np.asarray(T) @ local)[:3].T


def cross2(a, b):
    """The z component of the cross product of 2-D vectors (stacked on the last axis)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def support_polygon(T_feet):
    """The convex hull (counter-clockwise, (n, 2)) of both soles' corners in the ground plane
    (Andrew's monotone chain)."""
    pts = np.concatenate([foot_corners(T)[:, :2] for T in T_feet])
    pts = pts[np.lexsort((pts[:, 1], pts[:, 0]))]

    def chain(points):
        hull = []
        for p in points:
            while len(hull) >= 2 and cross2(hull[-1] - hull[-2], p - hull[-1]) <= 0:
                hull.pop()
            hull.append(p)
        return hull[:-1]

    return np.array(chain(pts) + chain(pts[::-1]))


def inside(polygon, point):
    """Whether a 2-D point lies inside a counter-clockwise convex polygon."""
    edges = np.roll(polygon, -1, axis=0) - polygon
    return bool(np.all(cross2(edges, point - polygon) >= 0))


T0 = np.asarray(jk.fk(robot, q0, frame=[*FEET, HAND]))  # (3, 4, 4): three frames, one pass
T_feet, T_hand0 = T0[:2], T0[2]  # the feet's poses (2, 4, 4), the hand's (4, 4)
c0 = np.asarray(jk.center_of_mass(robot, q0))
Jc = jk.com_jacobian(robot, q0)
hull = support_polygon(T_feet)
print("centre of mass:", c0, " inside the support polygon:", inside(hull, c0[:2]))
print("com Jacobian:", Jc.shape, "; base columns (the base's linear velocity moves c with it):")
print(np.asarray(Jc[:, :3]))

# %% [markdown]
# The first three columns of $J_c$ are the base's linear velocity (in the base's axes, here the
# world's): moving the whole robot moves its centre of mass by as much, so they form the identity.

# %% [markdown]
# ## Whole-body inverse kinematics, and a motion
#
# The target: both feet stay where they are (full poses, six rows each), the right hand's
# position follows a path (three rows: weights 0 on its orientation rows), and the centre of
# mass keeps its ground projection (`com=` with `com_weight=[1, 1, 0]`: its height is free). At
# step 0 the hand's target jumps 25 cm forward and 15 cm up: a whole-body IK from the neutral
# configuration. Then it draws a circle of 10 cm radius in 30 steps. The base and all 29 joints
# are unknowns: 35 velocities for 17 rows.
#
# `jk.motion.retarget` solves step $t$ from step $t-1$'s answer by a few damped Gauss-Newton
# steps on the manifold (the base's quaternion stays unit), with a pull toward the previous
# configuration and toward a reference posture (`posture=`) in the targets' null space, and the
# joint limits enforced; the first step is a plain whole-body IK from the neutral configuration.
# For one target from scratch, with restarts, the solver to use is
# `jk.solve_ik(robot, T, q0, frame=[...], weights=..., com=...)`; a long sequence (mocap data)
# streams through `retarget` in bounded memory, optionally to disk (`out="motion.npz"`).

# %%
frames = [*FEET, HAND]
reach = np.array([0.25, 0.0, 0.15])  # step 0: a jump of 29 cm from where the hand is
angle = np.linspace(0, 2 * np.pi, 31)[1:, None]  # steps 1-30: a circle back to the same point
circle = 0.1 * np.hstack([0 * angle, np.sin(angle), 1 - np.cos(angle)])
hand_path = T_hand0[:3, 3] + reach + np.concatenate([np.zeros((1, 3)), circle])  # (31, 3)
n = len(hand_path)

T_targets = np.broadcast_to(np.concatenate([T_feet, T_hand0[None]]), (n, 3, 4, 4)).copy()
T_targets[:, 2, :3, 3] = hand_path
weights = np.ones((3, 6))
weights[2, 3:] = 0.0  # the hand's position only
com_targets = np.broadcast_to(c0, (n, 3))

res = motion.retarget(
    robot, T_targets, q0, frames, weights=weights, com=com_targets, com_weight=[1.0, 1.0, 0.0],
    posture=q0,  # the free directions (left arm, waist...) pulled toward the neutral posture
)  # fmt: skip
print(f"{res.converged.sum()} of {n} steps converged; largest residual {res.residual.max():.1e}")
print("iterations per step:", res.iterations)
print("largest foot error: position", res.position_error[:, :2].max(), "m, orientation",
      res.orientation_error[:, :2].max(), "rad")  # fmt: skip
print("largest hand position error:", res.position_error[:, 2].max(), "m; centre of mass:",
      res.com_error.max(), "m")  # fmt: skip

# %% [markdown]
# The first step (from the neutral configuration, a 29 cm jump of the hand's target) takes more
# iterations; after it each step starts next to its answer. The results come from an
# independent forward kinematics at the returned configuration, not from the solver's Jacobian
# pass. Below: the centre of mass stays put over the support polygon (its ground projection is a
# target) while the hand draws its path.

# %%
qs = res.q
# one call per step: the kernels compiled above for one configuration (jk.center_of_mass for
# c0, jk.fk of the three frames for T0) serve every step, with no new compile
coms = np.stack([np.asarray(jk.center_of_mass(robot, q)) for q in qs])
hands = np.stack([np.asarray(jk.fk(robot, q, frame=frames))[2, :3, 3] for q in qs])

fig, (top, side) = plt.subplots(1, 2, figsize=(11, 4), width_ratios=(1.4, 1))
for T in T_feet:
    top.fill(*foot_corners(T)[:, :2].T, color="0.85", ec="0.5")
top.fill(*hull.T, fill=False, ls="--", ec="k", label="support polygon")
top.plot(*coms[:, :2].T, "o", color="C3", ms=4, label="centre of mass (ground projection)")
top.plot(*hands[:, :2].T, color="C0", label="hand path")
top.set(xlabel="x [m]", ylabel="y [m]", title="seen from above", aspect="equal")
top.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
side.plot(hands[:, 0], hands[:, 2], color="C0", label="hand (x, z)")
side.plot(hand_path[:, 0], hand_path[:, 2], "k:", label="hand target")
side.plot(coms[:, 0], coms[:, 2], "o", color="C3", ms=4, label="centre of mass (x, z)")
side.set(xlabel="x [m]", ylabel="z [m]", title="seen from the side", aspect="equal")
side.legend(fontsize=8)
plt.tight_layout()
print("centre of mass inside the support polygon at every step:",
      all(inside(hull, c[:2]) for c in coms))  # fmt: skip

# %% [markdown]
# ## The motion, as a strip of stills
#
# Four instants of the motion (`jaxkin.viz.plot_robot`); `jaxkin.viz.animate(robot, res.q)` makes
# it a `matplotlib` animation (`IPython.display.HTML(anim.to_jshtml())` in a notebook, or
# `jaxkin.viz.save_animation` to a GIF or MP4).

# %%
stills = [0, 8, 15, 23]
fig = plt.figure(figsize=(12, 4))
for i, k in enumerate(stills):
    ax = fig.add_subplot(1, len(stills), i + 1, projection="3d")
    jv.plot_robot(robot, qs[k], ax=ax, frames=None, joint_axes=False, view=(10, -60),
                  title=f"step {k}")  # fmt: skip
    ax.plot(*hand_path.T, "k:", lw=1)
    ax.plot(*hand_path[k], "o", color="C0")
plt.tight_layout()
