"""Makes docs/niryo_one.png, the README's picture, with jaxkin.viz.

Run from the repository root: ``python3 docs/readme_figure.py``.
"""

import pathlib

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jaxkin as jk  # noqa: E402
import jaxkin.viz as jv  # noqa: E402

robot = jk.robots.load("niryo_one")
q = np.array([0.3, -0.6, 0.4, 0.5, -0.8, 0.3])
qd = np.array([0.0, -0.04, -0.04, -0.05, 0.0, 0.0])  # the chapter's joint rates, rad/s

fig = plt.figure(figsize=(11, 4.6), dpi=90)
ax = fig.add_subplot(1, 2, 1, projection="3d")
jv.plot_twist(robot, q, qd, ax=ax, frames="all")
ax.set_title("Niryo One: frames, joint axes (dashed),\ntwist J(q) q̇ of the gripper", fontsize=10)
ax = fig.add_subplot(1, 2, 2, projection="3d")
jv.plot_ellipsoid(robot, q, ax=ax, frames="tip")
ax.set_title(ax.get_title().replace("velocity ellipsoid", "velocity (manipulability) ellipsoid"),
             fontsize=10)  # fmt: skip
fig.tight_layout()
out = pathlib.Path(__file__).with_name("niryo_one.png")
fig.savefig(out)
print(out, out.stat().st_size // 1024, "kB")
