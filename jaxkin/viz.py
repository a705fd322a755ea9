"""Pictures: the robot in 3-D, twist arrows, velocity ellipsoids, animated joint trajectories.

An optional extra (``pip install 'jaxkin[viz]'``, i.e. matplotlib), imported on its own::

    import jaxkin.viz as jv

    fig = jv.plot_robot(robot, q, frames="all")
    fig = jv.plot_twist(robot, q, qd)
    fig = jv.plot_ellipsoid(robot, q, rows="translation")
    anim = jv.animate(robot, qs, dt=0.05)
    jv.save_animation(anim, "motion.gif")

``import jaxkin`` never imports matplotlib; the functions here import it when called and raise
:class:`VizDependencyError` (a :class:`jaxkin.JaxkinError` and an ``ImportError``) if it is
missing. Every function returns the matplotlib ``Figure`` (or the ``FuncAnimation``) and never
calls ``plt.show()``; pass ``ax=`` (a 3-D axes) to draw into an existing figure. Figures are made
with ``matplotlib.pyplot``, so close them (``plt.close(fig)``) when making many.

What is drawn (all in world coordinates, metres):

* links: for joint j, a polyline from its parent frame's origin through the foot of the child
  frame's origin on the joint axis to the child frame's origin (for standard DH this is the
  textbook's ``d`` along ``z_{i-1}`` followed by ``a`` along ``x_i``);
* joint axes: a dashed segment along each moving joint's axis through a point on it (revolute:
  circle marker; prismatic: square), i.e. ``z_{i-1}`` at ``o_{i-1}`` of Table 4.1 for standard DH;
* frames: x, y, z axes in red, green, blue.

Twists and ellipsoids use the ``world_aligned`` reference: the velocity of the frame's origin in
world axes, rows ``[v; omega]``.
"""

from __future__ import annotations

import pathlib
from collections.abc import Sequence
from typing import Any

import numpy as np

from ._checks import check_q
from ._jit import compiler_options
from .errors import JaxkinError

__all__ = [
    "VizDependencyError",
    "animate",
    "plot_ellipsoid",
    "plot_robot",
    "plot_twist",
    "save_animation",
]

_FRAME_COLORS = ("#d62728", "#2ca02c", "#1f77b4")  # x, y, z
_LINK_COLOR = "#4a5568"
_AXIS_COLOR = "#dd6b20"
_V_COLOR = "#c53030"
_W_COLOR = "#2b6cb0"


class VizDependencyError(JaxkinError, ImportError):
    """matplotlib (the ``viz`` extra) is not installed."""


def _mpl():
    """Import matplotlib (pyplot and the 3-D toolkit) or raise a clear jaxkin error."""
    try:
        import matplotlib.pyplot as plt
        from mpl_toolkits.mplot3d import Axes3D  # noqa: F401  (registers the 3-D projection)
    except ImportError as exc:
        raise VizDependencyError(
            "jaxkin.viz needs matplotlib (>= 3.7): pip install 'jaxkin[viz]' "
            f"(or pip install matplotlib). Import failed with: {exc}"
        ) from None
    return plt


# ---------------------------------------------------------------------- geometry (numpy)
def _poses(robot, qs: np.ndarray) -> np.ndarray:
    """``fk_all`` of each row of ``qs`` (m, dof) -> (m, n_frames, 4, 4), float64 numpy."""
    import jax

    from .kinematics import fk_all

    if qs.shape[0] == 1:
        return np.asarray(fk_all(robot, qs[0]), dtype=float)[None]
    run = jax.jit(jax.vmap(lambda q: fk_all(robot, q)), compiler_options=compiler_options() or None)
    return np.asarray(run(qs), dtype=float)


def _check_qs(robot, qs: Any, what: str = "q", batch: bool = False) -> np.ndarray:
    """Joint values as float64 numpy (1, dof), or (n_steps, dof) for a trajectory."""
    if not batch:
        hint = "jk.viz.animate(robot, qs) to draw a joint trajectory (one configuration per frame)"
        q = check_q(robot, qs, what=what, fn="jaxkin.viz", batch_hint=hint)
        if not np.all(np.isfinite(np.asarray(q))):
            raise JaxkinError(f"{what} contains non-finite values.")
        return np.asarray(q, dtype=float)[None]
    try:
        arr = np.asarray(qs, dtype=float)
    except (TypeError, ValueError):
        raise JaxkinError(f"{what} must be numbers, got {qs!r:.80}.") from None
    want = f"(n_steps, {robot.nq})" if batch else f"({robot.nq},)"
    ok = arr.ndim == 2 and arr.shape[1] == robot.nq and arr.shape[0] >= 1
    if not batch:
        ok = arr.shape == (robot.nq,)
        arr = arr[None]
    if not ok:
        raise JaxkinError(
            f"{what} must have shape {want} for robot {robot.name!r} ({robot.nq} joints), "
            f"got shape {np.shape(qs)}."
        )
    if not np.all(np.isfinite(arr)):
        raise JaxkinError(f"{what} contains non-finite values.")
    return arr


def _joint_axes(robot, T: np.ndarray) -> list[tuple[int, str, np.ndarray, np.ndarray]]:
    """``(joint, kind, point, unit direction)`` of every moving joint, from frame poses (n, 4, 4).

    Standard DH: joint j turns about z of its parent frame through that frame's origin. Modified
    DH and URDF-style placements: about the child frame's (unit) axis through its origin.
    """
    out = []
    axis = np.asarray(robot.axis, dtype=float)
    for j, kind in enumerate(robot.kinds):
        if kind == "fixed":
            continue
        child, parent = j + 1, robot.parents[j]
        if robot.parameterisation == "dh_standard":
            R, p = T[parent, :3, :3], T[parent, :3, 3]
            direction = R[:, 2]
        else:
            R, p = T[child, :3, :3], T[child, :3, 3]
            direction = R @ axis[j]
        out.append((j, kind, p, direction / np.linalg.norm(direction)))
    return out


def _link_polylines(robot, T: np.ndarray, axes) -> list[np.ndarray]:
    """One (k, 3) polyline per joint (and one for the tool): parent -> foot on axis -> child."""
    by_joint = {j: (pt, d) for j, _, pt, d in axes}
    lines = []
    for j in range(robot.n_joints):
        a, b = T[robot.parents[j], :3, 3], T[j + 1, :3, 3]
        pts = [a]
        if j in by_joint:
            pt, d = by_joint[j]
            pts += [pt, pt + d * float(d @ (b - pt))]
        pts.append(b)
        poly = [pts[0]]
        for x in pts[1:]:
            if np.linalg.norm(x - poly[-1]) > 1e-12:
                poly.append(x)
        lines.append(np.array(poly))
    if robot.has_tool:
        lines.append(T[[robot.n_joints, robot.n_joints + 1], :3, 3])
    return lines


def _reach(T: np.ndarray) -> float:
    """Largest distance of a frame origin from the base origin (at least 1 mm)."""
    p = T[..., :3, 3].reshape(-1, 3)
    return max(float(np.max(np.linalg.norm(p - T.reshape(-1, 4, 4)[0, :3, 3], axis=1))), 1e-3)


def _frame_indices(robot, frames) -> list[int]:
    if frames is None or frames is False or frames == "none":
        return []
    if frames == "all" or frames is True:
        return list(range(robot.n_frames))
    if frames == "tip":
        return [robot.tip_frame]
    if isinstance(frames, (str, int)):
        frames = [frames]
    return [robot.frame_index(f) for f in frames]


# ---------------------------------------------------------------------- axes helpers
def _axes3d(ax, figsize=(6.0, 6.0)):
    plt = _mpl()
    if ax is None:
        fig = plt.figure(figsize=figsize)
        ax = fig.add_subplot(projection="3d")
    elif getattr(ax, "name", "") != "3d":
        raise JaxkinError("ax must be a 3-D axes: fig.add_subplot(projection='3d').")
    return ax


def _set_limits(ax, points: np.ndarray, pad: float = 0.1) -> None:
    """Equal-scale cube around ``points`` (k, 3), merged with limits set by earlier calls."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    if getattr(ax, "_jaxkin_limits", None) is not None:
        lo = np.minimum(lo, ax._jaxkin_limits[0])
        hi = np.maximum(hi, ax._jaxkin_limits[1])
    ax._jaxkin_limits = (lo, hi)
    center = 0.5 * (lo + hi)
    half = 0.5 * float(np.max(hi - lo)) * (1.0 + pad) + 1e-3
    ax.set_xlim(center[0] - half, center[0] + half)
    ax.set_ylim(center[1] - half, center[1] + half)
    ax.set_zlim(center[2] - half, center[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")


def _arrow(ax, start, vec, color, label=None, lw=2.5):
    ax.quiver(*start, *vec, color=color, linewidth=lw, arrow_length_ratio=0.18, label=label)


class _RobotArtists:
    """The line artists of one drawn robot, updatable for animations."""

    def __init__(self, ax, robot, T, frames, joint_axes, scale, color, alpha, labels):
        self.robot, self.frames, self.joint_axes, self.scale = robot, frames, joint_axes, scale
        axes = _joint_axes(robot, T)
        polys = _link_polylines(robot, T, axes)
        self.links = [
            ax.plot(*p.T, color=color, lw=4, alpha=alpha, solid_capstyle="round")[0] for p in polys
        ]
        marker = {"revolute": "o", "prismatic": "s"}
        self.axis_lines, self.axis_marks = [], []
        if joint_axes:
            for _, kind, pt, d in axes:
                seg = np.stack([pt - 0.5 * scale * d, pt + 0.5 * scale * d])
                self.axis_lines.append(ax.plot(*seg.T, color=_AXIS_COLOR, lw=2, ls="--")[0])
                self.axis_marks.append(
                    ax.plot(*pt[:, None], marker=marker[kind], ms=6, color=_AXIS_COLOR)[0]
                )
        self.triads = []
        for f in frames:
            self.triads.append(
                [
                    ax.plot(*self._triad(T, f, k).T, color=c, lw=1.5)[0]
                    for k, c in enumerate(_FRAME_COLORS)
                ]
            )
        self.texts = []
        if labels:  # one label per place: frames at the same origin share it
            groups: dict[int, list[int]] = {}
            for f in frames:
                same = [g for g in groups if np.linalg.norm(T[g, :3, 3] - T[f, :3, 3]) < 1e-9]
                groups.setdefault(same[0] if same else f, []).append(f)
            for f, members in groups.items():
                names = " = ".join(robot.frame_names[g] for g in members)
                self.texts.append((ax.text(*T[f, :3, 3], f"  {names}", fontsize=7), f))

    def _triad(self, T, f, k):
        p = T[f, :3, 3]
        return np.stack([p, p + 0.6 * self.scale * T[f, :3, k]])

    def update(self, T):
        axes = _joint_axes(self.robot, T)
        for line, p in zip(self.links, _link_polylines(self.robot, T, axes), strict=True):
            line.set_data_3d(*p.T)
        if self.joint_axes:
            for line, mark, (_, _, pt, d) in zip(
                self.axis_lines, self.axis_marks, axes, strict=True
            ):
                seg = np.stack([pt - 0.5 * self.scale * d, pt + 0.5 * self.scale * d])
                line.set_data_3d(*seg.T)
                mark.set_data_3d(*pt[:, None])
        for lines, f in zip(self.triads, self.frames, strict=True):
            for k, line in enumerate(lines):
                line.set_data_3d(*self._triad(T, f, k).T)
        for text, f in self.texts:
            text.set_position_3d(T[f, :3, 3])


# ---------------------------------------------------------------------- figures
def plot_robot(
    robot,
    q: Any,
    *,
    ax=None,
    frames: str | Sequence[str | int] | None = "tip",
    joint_axes: bool = True,
    labels: bool = False,
    scale: float | None = None,
    color: str = _LINK_COLOR,
    alpha: float = 1.0,
    view: tuple[float, float] | None = None,
    title: str | None = None,
):
    """Draw ``robot`` at configuration ``q`` (dof,) in 3-D; returns the Figure.

    Args:
      frames: which frames get x/y/z triads: ``"tip"`` (default), ``"all"``, ``None``, or a list
        of frame names or indices.
      joint_axes: draw each moving joint's axis (dashed) and location (circle: revolute, square:
        prismatic).
      labels: write frame names next to the drawn triads.
      scale: length unit of triads and axis segments in metres (default: 15% of the reach).
      view: ``(elevation, azimuth)`` in degrees, e.g. ``(90, -90)`` to look down the z axis.
    """
    qs = _check_qs(robot, q)
    T = _poses(robot, qs)[0]
    scale = 0.15 * _reach(T) if scale is None else float(scale)
    ax = _axes3d(ax)
    _RobotArtists(
        ax, robot, T, _frame_indices(robot, frames), joint_axes, scale, color, alpha, labels
    )
    _set_limits(ax, T[:, :3, 3])
    if view is not None:
        ax.view_init(*view)
    ax.set_title(
        title if title is not None else f"{robot.name} at q = {np.round(qs[0], 3).tolist()}"
    )
    return ax.figure


def plot_twist(
    robot,
    q: Any,
    qd: Any = None,
    *,
    twist: Any = None,
    frame: int | str | None = None,
    ax=None,
    scale: float | None = None,
    angular_scale: float | None = None,
    screw_axis: bool = True,
    show_robot: bool = True,
    **robot_kw: Any,
):
    """Draw the twist ``[v; omega]`` of ``frame`` (default: the tip) as two arrows; returns the
    Figure.

    Give joint velocities ``qd`` (dof,) (the twist is then ``jk.twist(robot, q, qd, frame)``) or
    the twist itself (6,), world_aligned: ``v`` is the velocity of the frame's origin, both in
    world axes. ``v`` (red) is drawn at ``scale`` metres per m/s, ``omega`` (blue) at
    ``angular_scale`` metres per rad/s (defaults: longest arrow 40% of the reach). With
    ``screw_axis``, the instantaneous screw axis (the line through
    ``p + omega x v / |omega|^2`` along ``omega``) is drawn dotted: every point on it moves along
    it, and for a pure rotation (``v . omega = 0``) it is the axis the body turns about.
    """
    from .velocity import twist as twist_fn

    qs = _check_qs(robot, q)
    if (qd is None) == (twist is None):
        raise JaxkinError("plot_twist: give exactly one of qd (dof,) or twist (6,).")
    if twist is None:
        qd = _check_qs(robot, qd, "qd")[0]
        V = np.asarray(twist_fn(robot, qs[0], qd, frame=frame), dtype=float)
    else:
        V = np.asarray(twist, dtype=float)
        if V.shape != (6,) or not np.all(np.isfinite(V)):
            raise JaxkinError(f"twist must be 6 finite numbers [v; omega], got shape {V.shape}.")
    T = _poses(robot, qs)[0]
    f = robot.frame_index(frame)
    p = T[f, :3, 3]
    v, w = V[:3], V[3:]
    reach = _reach(T)
    nv, nw = float(np.linalg.norm(v)), float(np.linalg.norm(w))
    scale = 0.4 * reach / nv if scale is None and nv > 0 else (scale or 1.0)
    angular_scale = 0.4 * reach / nw if angular_scale is None and nw > 0 else (angular_scale or 1.0)
    ax = _axes3d(ax)
    if show_robot:
        robot_kw.setdefault("title", "")
        plot_robot(robot, qs[0], ax=ax, **robot_kw)
    pts = [p]
    if nv > 0:
        _arrow(ax, p, scale * v, _V_COLOR, f"v = {nv:.4g} m/s")
        pts.append(p + scale * v)
    if nw > 0:
        _arrow(ax, p, angular_scale * w, _W_COLOR, f"ω = {nw:.4g} rad/s")
        pts.append(p + angular_scale * w)
        if screw_axis:
            c = p + np.cross(w, v) / nw**2
            d = w / nw
            seg = np.stack([c - 0.5 * reach * d, c + 0.5 * reach * d])
            ax.plot(*seg.T, color=_W_COLOR, ls=":", lw=1.5, label="screw axis")
            pts += list(seg)
    _set_limits(ax, np.array(pts))
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"twist of {robot.frame_names[f]} (world_aligned)")
    return ax.figure


def plot_ellipsoid(
    robot,
    q: Any,
    *,
    rows: str = "translation",
    kind: str = "velocity",
    frame: int | str | None = None,
    ax=None,
    scale: float | None = None,
    color: str = "#805ad5",
    alpha: float = 0.25,
    show_robot: bool = True,
    **robot_kw: Any,
):
    """Draw the velocity (manipulability) or force ellipsoid of ``frame`` at ``q``; returns the
    Figure.

    With ``J_r`` the ``rows`` of the world_aligned geometric Jacobian (``"translation"``: the
    3 x dof block ``J_v``, m/s per rad/s; ``"rotation"``: ``J_omega``) and its SVD
    ``J_r = U diag(sigma) V^T``:

    * ``kind="velocity"``: ``{J_r qd : |qd| <= 1}``, semi-axes ``sigma_i u_i`` (Yoshikawa's
      manipulability ellipsoid; its volume is proportional to ``prod sigma_i``). Flat where
      ``J_r`` loses rank.
    * ``kind="force"``: the dual ``{f : |J_r^T f| <= 1}``, semi-axes ``u_i / sigma_i``; unbounded
      (an error) at a singular configuration.

    Centred at the frame's origin, drawn at ``scale`` metres per unit (default: longest semi-axis
    40% of the reach). The title lists ``sigma``.
    """
    from .jacobians import geometric_jacobian

    if rows not in ("translation", "rotation"):
        raise JaxkinError(f"rows must be 'translation' or 'rotation', got {rows!r}.")
    if kind not in ("velocity", "force"):
        raise JaxkinError(f"kind must be 'velocity' or 'force', got {kind!r}.")
    qs = _check_qs(robot, q)
    J = np.asarray(geometric_jacobian(robot, qs[0], frame=frame), dtype=float)
    Jr = J[:3] if rows == "translation" else J[3:]
    U, s, _ = np.linalg.svd(Jr)
    sigma = np.zeros(3)
    sigma[: s.size] = s
    if kind == "velocity":
        semi = sigma
    else:
        if np.min(sigma) <= 1e-12 * max(1.0, float(np.max(sigma))):
            raise JaxkinError(
                f"the force ellipsoid is unbounded here: J's {rows} rows have singular values "
                f"{sigma.tolist()} (rank deficient). Draw kind='velocity' instead."
            )
        semi = 1.0 / sigma
    T = _poses(robot, qs)[0]
    f = robot.frame_index(frame)
    p = T[f, :3, 3]
    reach = _reach(T)
    top = float(np.max(semi))
    scale = (0.4 * reach / top if top > 0 else 1.0) if scale is None else float(scale)
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 40), np.linspace(0, np.pi, 20))
    sphere = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
    pts = p + scale * (sphere * semi) @ U.T
    ax = _axes3d(ax)
    if show_robot:
        robot_kw.setdefault("title", "")
        plot_robot(robot, qs[0], ax=ax, **robot_kw)
    ax.plot_surface(*np.moveaxis(pts, -1, 0), color=color, alpha=alpha, linewidth=0, shade=True)
    for i in range(3):
        seg = np.stack([p - scale * semi[i] * U[:, i], p + scale * semi[i] * U[:, i]])
        ax.plot(*seg.T, color=color, lw=1.2)
    _set_limits(ax, pts.reshape(-1, 3))
    block, unit = ("J_v", "m/s") if rows == "translation" else ("J_ω", "rad/s")
    ax.set_title(
        f"{kind} ellipsoid ({rows}) of {robot.frame_names[f]}\n"
        f"σ({block}) = {np.array2string(sigma, precision=3)} ({unit} per unit joint rate)"
    )
    return ax.figure


# ---------------------------------------------------------------------- animation
def animate(
    robot,
    qs: Any,
    *,
    dt: float = 0.05,
    qds: Any = None,
    frame: int | str | None = None,
    ax=None,
    frames: str | Sequence[str | int] | None = "tip",
    joint_axes: bool = True,
    trace: bool = True,
    twist_scale: float | None = None,
    speed: float = 1.0,
    view: tuple[float, float] | None = None,
    title: str | None = None,
):
    """Animate a joint trajectory ``qs`` (n_steps, dof) sampled every ``dt`` seconds.

    Returns a ``matplotlib.animation.FuncAnimation``: save it with :func:`save_animation`, or in
    a notebook show it with ``IPython.display.HTML(anim.to_jshtml())``. With ``trace``, the path
    of ``frame``'s origin (default: the tip) is drawn as it goes; with joint velocities ``qds``
    (n_steps, dof) the linear velocity of that origin is drawn as a red arrow at ``twist_scale``
    metres per m/s. ``speed`` > 1 plays faster than real time. All poses are computed up front
    (one ``jax.vmap``).
    """
    from matplotlib.animation import FuncAnimation

    from .velocity import twist as twist_fn

    qs = _check_qs(robot, qs, "qs", batch=True)
    if not (np.isfinite(dt) and dt > 0 and np.isfinite(speed) and speed > 0):
        raise JaxkinError(f"dt and speed must be positive, got dt={dt!r}, speed={speed!r}.")
    Ts = _poses(robot, qs)
    f = robot.frame_index(frame)
    path = Ts[:, f, :3, 3]
    V = None
    if qds is not None:
        import jax

        qds = _check_qs(robot, qds, "qds", batch=True)
        if qds.shape != qs.shape:
            raise JaxkinError(f"qds must have the shape of qs {qs.shape}, got {qds.shape}.")
        twists = jax.vmap(lambda q, qd: twist_fn(robot, q, qd, frame=frame))
        V = np.asarray(jax.jit(twists, compiler_options=compiler_options() or None)(qs, qds))
        top = float(np.max(np.linalg.norm(V[:, :3], axis=1)))
        if twist_scale is None:
            twist_scale = 0.3 * _reach(Ts) / top if top > 0 else 1.0
    ax = _axes3d(ax)
    fig = ax.figure
    scale = 0.15 * _reach(Ts)
    art = _RobotArtists(ax, robot, Ts[0], _frame_indices(robot, frames), joint_axes, scale,
                        _LINK_COLOR, 1.0, False)  # fmt: skip
    pts = [Ts[:, :, :3, 3].reshape(-1, 3)]
    if V is not None:
        pts.append(path + twist_scale * V[:, :3])
    _set_limits(ax, np.concatenate(pts))
    if view is not None:
        ax.view_init(*view)
    trail = ax.plot(*path[:1].T, color="#b83280", lw=1.5)[0] if trace else None
    arrow = ax.plot([], [], [], color=_V_COLOR, lw=2.5)[0] if V is not None else None
    label = title if title is not None else robot.name
    head = ax.set_title(f"{label}   t = 0.00 s")

    def update(k):
        art.update(Ts[k])
        if trail is not None:
            trail.set_data_3d(*path[: k + 1].T)
        if arrow is not None:
            arrow.set_data_3d(*np.stack([path[k], path[k] + twist_scale * V[k, :3]]).T)
        head.set_text(f"{label}   t = {k * dt:.2f} s")
        return []

    anim = FuncAnimation(fig, update, frames=len(qs), interval=1000.0 * dt / speed, blit=False)
    anim._jaxkin_fps = speed / dt  # read by save_animation
    return anim


def save_animation(anim, path: str | pathlib.Path, *, fps: float | None = None, dpi: int = 80):
    """Save an animation from :func:`animate` as ``.gif`` (Pillow) or ``.mp4`` (needs ffmpeg on
    the PATH); returns the path. ``fps`` defaults to the animation's own rate."""
    from matplotlib import animation as mpl_animation

    path = pathlib.Path(path)
    suffix = path.suffix.lower()
    if fps is None:
        fps = getattr(anim, "_jaxkin_fps", 10.0)
    if suffix == ".gif":
        writer = mpl_animation.PillowWriter(fps=fps)
    elif suffix == ".mp4":
        if not mpl_animation.writers.is_available("ffmpeg"):
            raise JaxkinError(
                f"saving {path.name} needs ffmpeg on the PATH (e.g. apt install ffmpeg or "
                "conda install ffmpeg); save as .gif instead."
            )
        writer = mpl_animation.FFMpegWriter(fps=fps)
    else:
        raise JaxkinError(f"save_animation writes .gif or .mp4, got {path.name!r}.")
    if not path.parent.is_dir():
        raise JaxkinError(f"cannot write {path}: directory {path.parent} does not exist.")
    anim.save(str(path), writer=writer, dpi=dpi)
    return path
