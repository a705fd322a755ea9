"""jaxkin.viz: every figure is drawn from a test, checked against the kinematics it shows, and
saved (under pytest's tmp dir and, for people to look at, in /tmp/jaxkin_figures/)."""

import pathlib
import shutil
import sys

import numpy as np
import pytest
from _oracle_modules import lazy_module

import jaxkin as jk
import jaxkin.viz as jv

LOOK = pathlib.Path("/tmp/jaxkin_figures")
NIRYO_Q = np.array([0.3, -0.6, 0.4, 0.5, -0.8, 0.3])
plt = lazy_module("matplotlib.pyplot")  # imported by this file's first test, not at collection


@pytest.fixture(scope="module", autouse=True)
def _agg_backend():
    """Figures drawn off screen (before pyplot is first imported)."""
    import matplotlib

    matplotlib.use("Agg")


@pytest.fixture
def save(tmp_path):
    """Save a figure as PNG in tmp_path and copy it to /tmp/jaxkin_figures/; closes it."""
    made = []

    def _save(fig, name):
        path = tmp_path / f"{name}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        assert path.stat().st_size > 10_000  # a real picture, not an empty canvas
        LOOK.mkdir(exist_ok=True)
        shutil.copy(path, LOOK / path.name)
        made.append(path)
        return path

    yield _save
    plt.close("all")


def _lines(fig):
    return [np.array(line.get_data_3d()).T for line in fig.axes[0].get_lines()]


def test_plot_robot_draws_links_through_every_frame_origin(save):
    robot = jk.robots.load("niryo_one")
    fig = jv.plot_robot(robot, NIRYO_Q, frames="all", labels=True)
    origins = np.asarray(jk.fk_all(robot, NIRYO_Q))[:, :3, 3]
    vertices = np.concatenate(_lines(fig))
    for p in origins:  # every frame origin is a vertex of some drawn line
        assert np.min(np.linalg.norm(vertices - p, axis=1)) < 1e-12
    assert "niryo_one" in fig.axes[0].get_title()
    save(fig, "robot_niryo_one")


def test_plot_robot_standard_dh_joint_axes_are_z_of_the_previous_frame(save):
    robot = jk.robots.load("puma560")
    q = robot.configurations["qn"]
    fig = jv.plot_robot(robot, q, frames="all")
    T = np.asarray(jk.fk_all(robot, q))
    dashed = [line for line in fig.axes[0].get_lines() if line.get_linestyle() == "--"]
    assert len(dashed) == robot.dof
    for i, line in enumerate(dashed):  # Table 4.1: joint i+1 turns about z_i through o_i
        a, b = np.array(line.get_data_3d()).T
        np.testing.assert_allclose((a + b) / 2, T[i, :3, 3], atol=1e-12)
        d = (b - a) / np.linalg.norm(b - a)
        np.testing.assert_allclose(d, T[i, :3, 2], atol=1e-12)
    save(fig, "robot_puma560_qn")


def test_plot_robot_prismatic_and_tool(save):
    fig = jv.plot_robot(jk.robots.load("stanford"), [0.3, -0.8, 0.4, 0.5, 0.6, 0.2], frames="all")
    save(fig, "robot_stanford")
    panda = jk.robots.load("panda")
    fig = jv.plot_robot(panda, panda.configurations["qr"], frames=["tool"], view=(20, -60))
    tool = np.asarray(jk.fk(panda, panda.configurations["qr"]))[:3, 3]
    assert np.min(np.linalg.norm(np.concatenate(_lines(fig)) - tool, axis=1)) < 1e-12
    save(fig, "robot_panda_qr")


def test_plot_twist_arrows_are_v_and_omega(save):
    robot = jk.robots.load("niryo_one")
    qd = np.array([0.2, -0.4, -0.4, -0.5, 0.3, 0.1])
    V = np.asarray(jk.twist(robot, NIRYO_Q, qd))
    fig = jv.plot_twist(robot, NIRYO_Q, qd, scale=0.5, angular_scale=0.2)
    ax = fig.axes[0]
    labels = ax.get_legend_handles_labels()[1]
    assert f"v = {np.linalg.norm(V[:3]):.4g} m/s" in labels
    assert f"ω = {np.linalg.norm(V[3:]):.4g} rad/s" in labels
    # the screw axis: every point c on it moves along omega (v_c = v + omega x (c - p) || omega)
    screw = next(line for line in ax.get_lines() if line.get_label() == "screw axis")
    c = np.array(screw.get_data_3d()).T.mean(axis=0)
    p = np.asarray(jk.fk(robot, NIRYO_Q))[:3, 3]
    v_c = V[:3] + np.cross(V[3:], c - p)
    np.testing.assert_allclose(np.cross(v_c, V[3:]), 0.0, atol=1e-12)
    save(fig, "twist_niryo_one")
    # a twist given directly: the chapter's pure rotation of a wrist (v = 0)
    fig = jv.plot_twist(robot, NIRYO_Q, twist=[0, 0, 0, 0, 0, 1.0])
    save(fig, "twist_pure_rotation")


@pytest.mark.parametrize(
    ("rows", "kind"),
    [("translation", "velocity"), ("rotation", "velocity"), ("translation", "force")],
)
def test_plot_ellipsoid_semi_axes_are_the_singular_values(save, rows, kind):
    robot = jk.robots.load("niryo_one")
    fig = jv.plot_ellipsoid(robot, NIRYO_Q, rows=rows, kind=kind, scale=0.1)
    J = np.asarray(jk.geometric_jacobian(robot, NIRYO_Q))
    sigma = np.linalg.svd(J[:3] if rows == "translation" else J[3:], compute_uv=False)
    semi = sigma if kind == "velocity" else 1 / sigma
    # the three principal-axis segments come last; their half-lengths are scale * semi-axes
    axes = _lines(fig)[-3:]
    half = sorted(np.linalg.norm(seg[1] - seg[0]) / 2 / 0.1 for seg in axes)
    np.testing.assert_allclose(half, sorted(semi), rtol=1e-12)
    save(fig, f"ellipsoid_{kind}_{rows}")


def test_force_ellipsoid_at_a_singularity_is_an_error():
    robot = jk.robots.load("two_link_planar")
    with pytest.raises(jk.JaxkinError, match="unbounded"):
        jv.plot_ellipsoid(robot, [0.3, 0.0], kind="force")
    plt.close("all")


def test_animation_gif(tmp_path):
    robot = jk.robots.load("niryo_one")
    t = np.arange(0, 2.0, 0.4)  # five frames: enough to count them and see the robot move
    qd = np.array([0.4, -0.3, -0.3, -0.5, 0.0, 0.0])
    qs = np.zeros(6) + t[:, None] * qd
    anim = jv.animate(robot, qs, dt=0.4, qds=np.broadcast_to(qd, qs.shape), title="niryo_one")
    path = jv.save_animation(anim, tmp_path / "motion.gif")
    plt.close("all")
    from PIL import Image

    with Image.open(path) as im:
        assert im.n_frames == len(t)
        first = np.asarray(im.convert("RGB"))
        im.seek(len(t) - 1)
        last = np.asarray(im.convert("RGB"))
    assert not np.array_equal(first, last)  # the robot moved
    LOOK.mkdir(exist_ok=True)
    shutil.copy(path, LOOK / "animation_niryo_one.gif")
    with Image.open(path) as im:  # a still of the last frame, to look at
        im.seek(len(t) - 1)
        im.convert("RGB").save(LOOK / "animation_niryo_one_last_frame.png")


def test_animation_mp4_needs_ffmpeg(tmp_path):
    from matplotlib import animation

    robot = jk.robots.load("two_link_planar")
    anim = jv.animate(robot, np.linspace([0, 0], [1, 1], 3), dt=0.5)
    if animation.writers.is_available("ffmpeg"):
        assert jv.save_animation(anim, tmp_path / "m.mp4").stat().st_size > 0
    else:
        with pytest.raises(jk.JaxkinError, match="needs ffmpeg"):
            jv.save_animation(anim, tmp_path / "m.mp4")
        jv.save_animation(anim, tmp_path / "m.gif")  # render it: no "deleted unrendered" warning
    with pytest.raises(jk.JaxkinError, match=r"\.gif or \.mp4"):
        jv.save_animation(anim, tmp_path / "m.avi")
    plt.close("all")


def test_bad_input_is_a_jaxkin_error():
    robot = jk.robots.load("niryo_one")
    with pytest.raises(jk.JaxkinError, match=r"shape \(6,\)"):
        jv.plot_robot(robot, [0.0, 1.0])
    with pytest.raises(jk.JaxkinError, match="exactly one"):
        jv.plot_twist(robot, NIRYO_Q)
    with pytest.raises(jk.JaxkinError, match="3-D axes"):
        jv.plot_robot(robot, NIRYO_Q, ax=plt.figure().add_subplot())
    with pytest.raises(jk.JaxkinError, match=r"\(n_steps, 6\)"):
        jv.animate(robot, NIRYO_Q)
    with pytest.raises(jk.JaxkinError, match="no frame"):
        jv.plot_robot(robot, NIRYO_Q, frames=["nosuch"])
    plt.close("all")


def test_missing_matplotlib_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib.pyplot", None)
    with pytest.raises(jv.VizDependencyError, match=r"pip install 'jaxkin\[viz\]'") as info:
        jv.plot_robot(jk.robots.load("two_link_planar"), [0.0, 0.0])
    assert isinstance(info.value, jk.JaxkinError) and isinstance(info.value, ImportError)


def test_import_jaxkin_does_not_import_matplotlib():
    import subprocess

    code = "import jaxkin, sys; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
