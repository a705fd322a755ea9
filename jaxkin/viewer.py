"""A 3-D robot viewer in the browser: meshes, frames, twist arrows, the velocity ellipsoid.

An optional extra (``pip install 'jaxkin[viewer]'``: `viser <https://viser.studio>`_ for the
web server and scene, ``trimesh`` and ``pycollada`` to read ``.stl``/``.obj``/``.dae`` meshes),
imported on its own. Without it, :func:`show` raises :class:`ViewerDependencyError`, which names
the install command. matplotlib (:mod:`jaxkin.viz`) stays the tool for static textbook figures::

    import jaxkin as jk
    import jaxkin.viewer as jview

    robot = jk.robots.load("erd/panda")
    view = jview.show(robot, q, qd)  # q, qd: (7,) joint positions and speeds
    print(view.url)             # open it in a browser
    view.update(q2, qd2)        # move the robot
    view.animate(qs, fps=30)    # play a trajectory (blocks until done)
    view.close()

What is drawn, in world coordinates (those of ``jk.fk_all``; ``robot.base`` is T_world_base), in m:

* one scene node per frame of ``robot.frame_names``, named ``/robot/<frame>`` (``/`` in a frame
  name becomes ``_``), with its x, y, z axes; its pose is ``fk_all(robot, q)[i]``;
* meshes: for a robot loaded from a URDF file, each link's ``<visual>`` meshes
  (``<mesh filename=... scale=...>``, with the visual's ``<origin>`` and ``<material>`` colour)
  as children ``/robot/<frame>/visual_<k>``. A robot from :func:`jaxkin.robots.load`
  (``"erd/..."``) finds its file by itself; otherwise pass ``urdf=`` (the path the robot was
  loaded from). Mesh files are read only from the places the user named (see "Where meshes are
  read from" below). ``<box>``, ``<cylinder>`` and ``<sphere>`` visuals are
  drawn too. For a robot loaded from an MJCF file (:func:`jaxkin.load_mjcf`), MuJoCo compiles
  the file *with* its mesh files and each visual geom of a body of ``robot.frame_names`` is
  drawn as ``/robot/<body>/visual_<k>`` (k: the geom's order in its body) at the geom's
  ``geom_pos``/``geom_quat`` in the body frame, coloured by its material (else ``geom_rgba``):
  meshes (``mesh_vert``/``mesh_face``, in the mesh frame MuJoCo re-centred), boxes, spheres,
  ellipsoids, capsules and cylinders. Collision-only geoms are skipped by MuJoCo's conventions:
  ``geom_group`` >= 3 (groups MuJoCo's viewer hides) or alpha 0; planes and height fields are
  not drawn. A robot from ``jk.robots.load("mjcf/...")`` finds its file by itself; otherwise
  pass ``mjcf=``. The file is pre-read as :func:`jaxkin.load_mjcf` does
  (:func:`jaxkin.mjcf.check_files`), and an asset file (mesh, height field, skin, texture) that
  is not a regular file is refused before MuJoCo reads it. Missing mesh files (urdf or mjcf)
  raise :class:`ViewerError`, which names the file; ``meshes=False`` draws segments instead.
  A robot without meshes (DH zoo robots, a robot loaded from an XML string) is drawn as
  segments from each joint's parent frame origin to its child frame origin (``/robot/links``);
* with ``qd``, the twist of the default frame (``jk.twist``, ``world_aligned``: the frame
  origin's velocity in world axes): ``/robot/twist_v`` (red, ``v`` in m/s) and
  ``/robot/twist_omega`` (blue, ``omega`` in rad/s), both drawn from the frame origin,
  ``arrow_scale`` metres per unit;
* the translational velocity ellipsoid of the default frame (``jk.velocity_ellipsoid`` of the
  geometric Jacobian): ``/robot/ellipsoid``, radii in m/s per unit joint speed times
  ``ellipsoid_scale``.

Twist and ellipsoid are drawn for ``frame=`` or, when it is ``None``, for the robot's default
frame; a robot without one (branching trees) shows neither until ``frame=`` is given.

The camera opens framing the robot at the first ``q`` (:func:`camera_framing` of the frame
origins and the corners of the meshes' bounding boxes): it looks at the centre of their
bounding box from the front, right and above, far enough for the whole box to be in view.

Where meshes are read from
--------------------------
A URDF file is untrusted input: its mesh paths are resolved within these places only, the
*package roots*:

* ``package://pkg/rest``: the directory of ``packages[pkg]`` when ``packages=`` names ``pkg``;
  else the URDF file's directory or its parent (:data:`PARENT_LEVELS` = 1 level up: the
  package of a ROS layout ``pkg/urdf/robot.urdf``) when it is named ``pkg``, or a directory
  ``pkg`` inside one of these two; else ``pkg`` in example-robot-data's ``share`` folder.
  Nothing further up is searched. ``rest`` must stay inside that package root once ``..`` and
  symbolic links are resolved.
* a plain or ``file://`` path (relative to the URDF's directory, or absolute) must lie inside
  the URDF's directory or its parent, a directory of ``packages=``, or example-robot-data's
  ``share`` folder.
* the file must be a regular file whose suffix is one of a mesh format (``.stl``, ``.obj``,
  ``.dae``, ``.ply``, ``.off``, ``.glb``, ``.gltf``; any case).

A mesh path that breaks one of these rules is never opened: its link is drawn without it, with
one :class:`MeshPathWarning` naming the path. A path inside these places that does not exist
raises :class:`ViewerError`. Keep a downloaded robot in a directory of its own (its parent
directory is read from), and name packages found elsewhere with ``packages=``.

Example (starts a server, so not run as a doctest)::

    >>> import jaxkin as jk, jaxkin.viewer as jview
    >>> robot = jk.robots.load("puma560")
    >>> view = jview.show(robot, [0.0, 0.5, -0.5, 0.0, 0.3, 0.0])  # doctest: +SKIP
    >>> view.url  # doctest: +SKIP
    'http://127.0.0.1:...'
    >>> view.close()  # doctest: +SKIP
"""

from __future__ import annotations

import math
import os
import socket
import stat
import time
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ._checks import check_q, check_v
from .analysis import velocity_ellipsoid
from .errors import JaxkinError
from .jacobians import geometric_jacobian
from .kinematics import fk_all
from .mjcf import MAX_BODIES, check_files
from .model import Robot
from .velocity import twist

__all__ = [
    "PARENT_LEVELS",
    "MeshPathWarning",
    "View",
    "ViewerDependencyError",
    "ViewerError",
    "Visual",
    "camera_framing",
    "show",
    "urdf_visuals",
]

_INSTALL = "pip install 'jaxkin[viewer]'"
_GREY = (170, 170, 180)
_LINK_COLOR = (74, 85, 104)
_V_COLOR = (197, 48, 48)
_W_COLOR = (43, 108, 176)
_ELLIPSOID_COLOR = (221, 107, 32)


class ViewerDependencyError(JaxkinError, ImportError):
    """viser or trimesh (the ``viewer`` extra) is not installed."""


class ViewerError(JaxkinError):
    """A viewer input jaxkin cannot show (a URDF file that is missing, a trajectory's shape)."""


class MeshPathWarning(UserWarning):
    """A URDF mesh path outside the package roots (module doc, "Where meshes are read from"),
    not a regular file or not a mesh format: the mesh is skipped, the file never opened."""


PARENT_LEVELS = 1
"""How many directories above the URDF file's own are searched for packages and may hold
meshes (module doc, "Where meshes are read from")."""

_MESH_SUFFIXES = frozenset({".stl", ".obj", ".dae", ".ply", ".off", ".glb", ".gltf"})


def _viser():
    try:
        import trimesh
        import viser
        import viser.transforms
    except ImportError as e:
        raise ViewerDependencyError(
            f"jaxkin.viewer needs viser and trimesh ({e}); install them with: {_INSTALL}"
        ) from e
    return viser, trimesh


@dataclass(frozen=True)
class Visual:
    """One ``<visual>`` of a URDF link.

    ``kind``: ``"mesh"`` (``path``, ``scale``), ``"box"`` (``size``), ``"cylinder"``
    (``radius``, ``length``) or ``"sphere"`` (``radius``); ``xyz``/``rpy``: its origin in the
    link frame; ``rgba``: the ``<material><color>`` (0..1) or ``None``.
    """

    link: str
    kind: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    path: Path | None = None
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.0
    length: float = 0.0
    rgba: tuple[float, float, float, float] | None = None


def _floats(text: str | None, default: tuple[float, ...]) -> tuple[float, ...]:
    if not text:
        return default
    return tuple(float(v) for v in text.split())


def _erd_share() -> Path | None:
    """example-robot-data's ``share`` folder (None when it is not installed)."""
    try:
        from .robots import example_robot_data

        return Path(example_robot_data.robots_dir()).parent.parent.resolve()
    except Exception:  # not installed
        return None


class _Places:
    """The package roots of one URDF file (module doc, "Where meshes are read from")."""

    def __init__(self, urdf: Path, packages: Mapping[str, Any] | None) -> None:
        here = urdf.parent.resolve()
        share = _erd_share()
        self.urdf = urdf
        self.near = [here, *list(here.parents)[:PARENT_LEVELS]]
        self.packages = {
            str(k): Path(v).expanduser().resolve() for k, v in dict(packages or {}).items()
        }
        self.shared = [share] if share is not None else []
        self.roots = [self.near[-1], *self.packages.values(), *self.shared]

    def package(self, name: str) -> Path | None:
        """The root of package ``name`` (None: not in these places)."""
        if name in self.packages:
            return self.packages[name]
        for d in self.near:
            if d.name == name:
                return d
        for d in (*self.near, *self.shared):
            if (d / name).is_dir():
                return d / name
        return None


def _skip(message: str) -> None:
    warnings.warn(MeshPathWarning(f"{message}; the mesh is skipped, never read."), stacklevel=5)


def _inside(path: Path, roots: list[Path]) -> bool:
    return any(path.is_relative_to(os.path.realpath(r)) for r in roots)


def _resolve(filename: str, places: _Places) -> Path | None:
    """The real path of the mesh file ``filename`` names, or None (skipped with a warning:
    outside the package roots, not a regular file, not a mesh format; module doc)."""
    where = f"{places.urdf}: mesh {filename!r}"
    if filename.startswith("package://"):
        package, _, inner = filename[len("package://") :].partition("/")
        if package in ("", ".", ".."):
            return _skip(f"{where} names no package")
        root = places.package(package)
        if root is None:
            looked = [str(d) for d in places.near + places.shared]
            raise ViewerError(
                f"{where} not found: no package {package!r} at or in {looked}; pass "
                f"packages={{{package!r}: '<its directory>'}} to jaxkin.viewer.show, install the "
                "package that ships it, or pass meshes=False to draw link segments instead."
            )
        path, roots, what = root / inner, [root], f"the package root {str(root)!r}"
    else:
        rest = Path(filename[len("file://") :] if filename.startswith("file://") else filename)
        path = rest if rest.is_absolute() else places.urdf.parent / rest
        roots = places.roots
        what = f"the places meshes are read from {[str(r) for r in roots]}"
    real = Path(os.path.realpath(path))
    if not _inside(real, roots):
        return _skip(f"{where} resolves to {str(real)!r}, outside {what}")
    if real.suffix.lower() not in _MESH_SUFFIXES:
        return _skip(f"{where} is not a mesh file (suffix not one of {sorted(_MESH_SUFFIXES)})")
    try:
        mode = os.stat(real).st_mode
    except OSError:
        raise ViewerError(
            f"{where} not found (looked for {str(path)!r}); install the package that ships it "
            "or pass meshes=False to draw link segments instead."
        ) from None
    if not stat.S_ISREG(mode):
        return _skip(f"{where} ({str(real)!r}) is not a regular file")
    return real


def urdf_visuals(
    urdf: str | os.PathLike, packages: Mapping[str, str | os.PathLike] | None = None
) -> list[Visual]:
    """The ``<visual>`` elements of a URDF file's links, mesh paths resolved (module doc).

    ``packages``: ``{package name: its directory}`` for ``package://`` paths found elsewhere
    than beside the file. Mesh paths outside the package roots are left out, each with a
    :class:`MeshPathWarning` (module doc, "Where meshes are read from").

    >>> import jaxkin.viewer as jview, jaxkin.robots.example_robot_data as erd
    >>> vs = jview.urdf_visuals(erd.path("erd/panda"))  # doctest: +SKIP
    >>> vs[0].link, vs[0].kind, vs[0].path.name  # doctest: +SKIP
    ('panda_link0', 'mesh', 'link0.dae')
    """
    path = Path(urdf)
    if not path.is_file():
        raise ViewerError(
            f"URDF file {str(path)!r} not found; pass the path the robot was loaded from."
        )
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:
        raise ViewerError(f"{path}: not readable XML ({e}).") from e
    try:
        colors = {
            m.get("name"): _floats(m.find("color").get("rgba"), (0.7, 0.7, 0.7, 1.0))
            for m in root.findall("material")
            if m.find("color") is not None
        }
    except ValueError as e:
        raise ViewerError(f"{path}: a <material> color is not 4 numbers ({e}).") from e
    places = _Places(path, packages)
    out: list[Visual] = []
    for link in root.findall("link"):
        try:
            out += _link_visuals(link, places, colors)
        except ValueError as e:
            if isinstance(e, JaxkinError):
                raise
            raise ViewerError(
                f"{path}: a <visual> of link {link.get('name')!r} has a value that is not a "
                f"number ({e}); fix the file or pass meshes=False to jaxkin.viewer.show."
            ) from e
    return out


def _link_visuals(link: Any, places: _Places, colors: dict) -> list[Visual]:
    out = []
    for vis in link.findall("visual"):
        geom = vis.find("geometry")
        if geom is None or len(geom) == 0:
            continue
        origin = vis.find("origin")
        xyz = _floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0))
        rpy = _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0))
        rgba = None
        mat = vis.find("material")
        if mat is not None:
            color = mat.find("color")
            rgba = _floats(color.get("rgba"), None) if color is not None else None
            rgba = rgba or colors.get(mat.get("name"))
        shape = geom[0]
        common = dict(link=link.get("name"), xyz=xyz, rpy=rpy, rgba=rgba)
        if shape.tag == "mesh":
            p = _resolve(shape.get("filename", ""), places)
            if p is None:
                continue  # refused, with a warning
            scale = _floats(shape.get("scale"), (1.0, 1.0, 1.0))
            out.append(Visual(kind="mesh", path=p, scale=scale, **common))
        elif shape.tag == "box":
            out.append(Visual(kind="box", size=_floats(shape.get("size"), (0, 0, 0)), **common))
        elif shape.tag == "cylinder":
            r, h = float(shape.get("radius", 0)), float(shape.get("length", 0))
            out.append(Visual(kind="cylinder", radius=r, length=h, **common))
        elif shape.tag == "sphere":
            out.append(Visual(kind="sphere", radius=float(shape.get("radius", 0)), **common))
    return out


_MJCF_VISIBLE_GROUPS = 3  # groups 0, 1, 2: those MuJoCo's own viewer shows by default


def _mjcf_geoms(
    path: Path, trimesh: Any, max_bodies: int
) -> list[tuple[str, Any, np.ndarray, np.ndarray]]:
    """``(body name, trimesh, geom_pos, geom_quat)`` of each visual geom of an MJCF file,
    compiled by MuJoCo with its mesh files (module doc: which geoms are drawn), after
    :func:`jaxkin.mjcf.check_files` (includes that are not regular files, size, bodies)."""
    try:
        import mujoco
    except ImportError as e:
        raise ViewerDependencyError(
            f"MJCF meshes need MuJoCo ({e}); install it with: pip install 'jaxkin[mjcf]', or "
            "pass meshes=False to draw link segments instead."
        ) from e
    if not path.is_file():
        raise ViewerError(
            f"MJCF file {str(path)!r} not found; pass mjcf= the path the robot was loaded from."
        )
    check_files(path, max_bodies=max_bodies)
    try:
        spec = mujoco.MjSpec.from_file(str(path))
        _check_asset_files(spec, path)
        spec.compiler.fusestatic = False  # the bodies of jk.load_mjcf, in the same order
        m = spec.compile()
    except ValueError as e:
        text = " ".join(str(e).split())
        raise ViewerError(
            f"{path}: MuJoCo could not compile the file with its meshes ({text}); install the "
            "package that ships them or pass meshes=False to draw link segments instead."
        ) from e
    G = mujoco.mjtGeom
    out = []
    for g in range(m.ngeom):
        kind, size = int(m.geom_type[g]), np.asarray(m.geom_size[g], float)
        rgba = m.mat_rgba[m.geom_matid[g]] if m.geom_matid[g] >= 0 else m.geom_rgba[g]
        if m.geom_group[g] >= _MJCF_VISIBLE_GROUPS or rgba[3] == 0:
            continue  # collision-only by MuJoCo's conventions: hidden group or invisible
        if kind == G.mjGEOM_MESH:
            i = int(m.geom_dataid[g])
            va, vn = int(m.mesh_vertadr[i]), int(m.mesh_vertnum[i])
            fa, fn = int(m.mesh_faceadr[i]), int(m.mesh_facenum[i])
            mesh = trimesh.Trimesh(
                np.array(m.mesh_vert[va : va + vn], float),
                np.array(m.mesh_face[fa : fa + fn]),
                process=False,
            )
        elif kind == G.mjGEOM_BOX:
            mesh = trimesh.creation.box(extents=2 * size)
        elif kind == G.mjGEOM_SPHERE:
            mesh = trimesh.creation.icosphere(radius=size[0])
        elif kind == G.mjGEOM_ELLIPSOID:
            mesh = trimesh.creation.icosphere(radius=1.0)
            mesh.apply_scale(size)
        elif kind == G.mjGEOM_CAPSULE:
            mesh = trimesh.creation.capsule(height=2 * size[1], radius=size[0])
        elif kind == G.mjGEOM_CYLINDER:
            mesh = trimesh.creation.cylinder(radius=size[0], height=2 * size[1])
        else:
            continue  # planes, height fields, SDFs: no body of a robot
        colors = (np.clip(np.asarray(rgba, float), 0, 1) * 255).astype(np.uint8)
        mesh.visual = trimesh.visual.ColorVisuals(
            mesh, face_colors=np.tile(colors, (len(mesh.faces), 1))
        )
        b = int(m.geom_bodyid[g])
        body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
        body = "world" if b == 0 else body
        out.append((body, mesh, np.array(m.geom_pos[g], float), np.array(m.geom_quat[g], float)))
    return out


def _check_asset_files(spec: Any, path: Path) -> None:
    """Refuse, before MuJoCo reads them, the mesh, height-field, skin and texture files of an
    MJCF model that exist but are not regular files (a FIFO would block MuJoCo)."""
    here = path.parent
    names = [("mesh", here / spec.meshdir, a.file) for a in (*spec.meshes, *spec.hfields)]
    names += [("skin", here / spec.meshdir, a.file) for a in spec.skins]
    for t in spec.textures:
        names += [("texture", here / spec.texturedir, f) for f in (t.file, *t.cubefiles)]
    for kind, folder, name in names:
        for c in dict.fromkeys((folder / name, here / name)) if name else ():
            try:
                mode = os.stat(c).st_mode
            except (OSError, ValueError):
                continue
            if not stat.S_ISREG(mode):
                raise ViewerError(
                    f"{path}: {kind} file {name!r} ({str(c)!r}) is not a regular file (a FIFO, "
                    "a device or a directory); MuJoCo would block reading it. Fix the file, or "
                    "pass meshes=False to draw link segments instead."
                )


def _mjcf_path(robot: Robot, mjcf: Any) -> Path | None:
    if mjcf is not None:
        return Path(mjcf)
    if robot.name.startswith("mjcf/"):
        from .robots import mjcf as mjcf_models

        try:
            return Path(mjcf_models.path(robot.name))
        except JaxkinError:
            return None
    return None


def _urdf_path(robot: Robot, urdf: Any) -> Path | None:
    if urdf is not None:
        return Path(urdf)
    if robot.name.startswith("erd/"):
        from .robots import example_robot_data

        try:
            return Path(example_robot_data.path(robot.name))
        except JaxkinError:
            return None
    return None


def _trimesh(visual: Visual, trimesh: Any) -> Any:
    if visual.kind == "mesh":
        try:
            mesh = trimesh.load(str(visual.path), force="mesh")
        except Exception as e:
            raise ViewerError(
                f"mesh {str(visual.path)!r} of link {visual.link!r} could not be read ({e}); "
                f"{_INSTALL} installs the readers for .stl, .obj and .dae."
            ) from e
        mesh.apply_scale(visual.scale)
    elif visual.kind == "box":
        mesh = trimesh.creation.box(extents=visual.size)
    elif visual.kind == "cylinder":
        mesh = trimesh.creation.cylinder(radius=visual.radius, height=visual.length)
    else:
        mesh = trimesh.creation.icosphere(radius=visual.radius)
    if visual.rgba is not None or visual.kind != "mesh" or mesh.visual.kind is None:
        rgba = np.array(visual.rgba if visual.rgba is not None else (*np.array(_GREY) / 255, 1))
        mesh.visual = trimesh.visual.ColorVisuals(mesh, face_colors=(rgba * 255).astype(np.uint8))
    return mesh


_FOV = math.radians(75.0)  # viser's (three.js's) default vertical field of view
_VIEW_FROM = (1.0, 0.75, 0.6)  # in front (+x), to the right (+y), above (+z)
_MARGIN = 1.1
_MIN_RADIUS = 0.05


def camera_framing(points: Any, fov: float = _FOV) -> tuple[np.ndarray, np.ndarray]:
    """``(position, look_at)`` of a camera that frames ``points`` (n, 3), z up.

    ``look_at`` is the centre ``c`` of the bounding box of the (finite) points; ``position`` is
    ``c + d u``, ``u`` the unit vector along ``(1, 0.75, 0.6)`` (in front, to the right, above)
    and ``d = 1.1 r / sin(fov / 2)``: the distance at which the sphere around the box (``r``:
    half its diagonal, at least 5 cm) fills the vertical field of view ``fov`` (radians;
    default 75 degrees, viser's) with a 10 % margin. The distance is proportional to the
    robot's extent.

    >>> import jaxkin.viewer as jview
    >>> position, look_at = jview.camera_framing([[0, 0, 0], [2, 2, 2], [1, 0, 1]])
    >>> look_at.tolist()
    [1.0, 1.0, 1.0]
    >>> round(float(((position - look_at) ** 2).sum() ** 0.5), 4)  # 1.1 sqrt(3) / sin(37.5 deg)
    3.1297
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) == 0:
        p = np.zeros((1, 3))
    lo, hi = p.min(axis=0), p.max(axis=0)
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, _MIN_RADIUS)
    u = np.array(_VIEW_FROM) / np.linalg.norm(_VIEW_FROM)
    distance = _MARGIN * radius / math.sin(float(fov) / 2)
    return centre + distance * u, centre


def _node(frame: str) -> str:
    return "/robot/" + frame.replace("/", "_")


class View:
    """A running viewer (made by :func:`show`): ``url``, ``update``, ``animate``, ``close``.

    ``server`` is the ``viser.ViserServer``; ``nodes`` maps each frame name to its scene node
    name; ``mesh_nodes`` lists the mesh nodes; ``camera`` is the ``(position, look_at)`` the
    page opens with (:func:`camera_framing` of the robot at the first ``q``; also viser's
    "Reset View").
    """

    def __init__(
        self, robot, server, frame, arrow_scale, ellipsoid_scale, meshes, urdf, mjcf, packages=None
    ):
        viser, trimesh = _viser()
        self.robot = robot
        self.server = server
        self._so3 = viser.transforms.SO3
        self._frame = frame
        self._arrow_scale = float(arrow_scale)
        self._ellipsoid_scale = float(ellipsoid_scale)
        self._closed = False
        scene = server.scene
        self.nodes = {name: _node(name) for name in robot.frame_names}
        self._frames = [
            scene.add_frame(self.nodes[n], axes_length=0.08, axes_radius=0.004, origin_radius=0.008)
            for n in robot.frame_names
        ]
        self.mesh_nodes: list[str] = []
        self.camera: tuple[np.ndarray, np.ndarray] | None = None
        self._corners: list[tuple[int, np.ndarray]] = []  # (frame, mesh box corners in it)
        path = _urdf_path(robot, urdf) if meshes else None
        if path is not None:
            for vis in urdf_visuals(path, packages):
                if vis.link in self.nodes:  # else a link of the file the chain left out
                    wxyz = self._so3.from_rpy_radians(*vis.rpy).wxyz
                    self._add_mesh(vis.link, _trimesh(vis, trimesh), np.array(vis.xyz), wxyz)
        path = _mjcf_path(robot, mjcf) if meshes and urdf is None else None
        if path is not None:
            n_bodies = max(MAX_BODIES, robot.n_frames)
            for body, mesh, pos, quat in _mjcf_geoms(path, trimesh, n_bodies):
                if body in self.nodes:  # else a body of the file that this robot's part left out
                    self._add_mesh(body, mesh, pos, quat)
        if not self.mesh_nodes:
            self._segments = [(p, j + 1) for j, p in enumerate(robot.parents)]
            if robot.has_tool:
                self._segments.append((len(robot.parents), robot.n_frames - 1))
        self._has_target = frame is not None or robot.has_default_frame
        self._ellipsoid = None
        if self._has_target:
            self._ellipsoid = scene.add_icosphere(
                "/robot/ellipsoid", 1.0, _ELLIPSOID_COLOR, subdivisions=3, opacity=0.35
            )
        self._kernel = jax.jit(self._state)

    def _add_mesh(self, frame: str, mesh: Any, position: np.ndarray, wxyz: Any) -> None:
        """Draw ``mesh`` at ``position``/``wxyz`` in ``frame`` as its next ``visual_<k>``."""
        k = sum(n.startswith(self.nodes[frame] + "/visual_") for n in self.mesh_nodes)
        name = f"{self.nodes[frame]}/visual_{k}"
        self.server.scene.add_mesh_trimesh(name, mesh, position=position, wxyz=wxyz)
        self.mesh_nodes.append(name)
        lo, hi = np.asarray(mesh.bounds, float)
        box = np.array([[(lo, hi)[b >> i & 1][i] for i in range(3)] for b in range(8)])
        R = self._so3(np.asarray(wxyz, float)).as_matrix()
        self._corners.append((self.robot.frame_index(frame), box @ R.T + position))

    def _frame_camera(self, Ts: np.ndarray) -> None:
        """Open the page framing the robot at poses ``Ts`` (frame origins and mesh boxes)."""
        points = [Ts[:, :3, 3]]
        points += [c @ Ts[i, :3, :3].T + Ts[i, :3, 3] for i, c in self._corners]
        camera = self.server.initial_camera
        self.camera = camera_framing(np.concatenate(points), fov=camera.fov)
        camera.position, camera.look_at = self.camera

    @property
    def url(self) -> str:
        """``http://host:port`` of the page."""
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    def _state(self, q, qd):
        Ts = fk_all(self.robot, q)
        if not self._has_target:
            return Ts, None, None, None
        i = self.robot.frame_index(self._frame)
        J = geometric_jacobian(self.robot, q, frame=i)
        e = velocity_ellipsoid(J)
        V = twist(self.robot, q, qd, frame=i)
        return Ts, V, e.radii, e.axes

    def update(self, q: Any, qd: Any = None) -> None:
        """Move the robot to ``q`` (nq,) and draw the twist for ``qd`` (nv,) if given."""
        self._check_open()
        q = check_q(self.robot, q, fn="jaxkin.viewer.View.update")
        has_qd = qd is not None
        qd = check_v(
            self.robot,
            qd if has_qd else np.zeros(self.robot.nv),
            "qd",
            "jaxkin.viewer.View.update",
        )
        Ts, V, radii, axes = jax.device_get(self._kernel(q, qd))
        Ts = np.asarray(Ts, float)
        if self.camera is None:
            self._frame_camera(Ts)
        wxyz = self._so3.from_matrix(Ts[:, :3, :3]).wxyz
        scene = self.server.scene
        with self.server.atomic():
            for handle, T, quat in zip(self._frames, Ts, wxyz, strict=True):
                handle.position = T[:3, 3]
                handle.wxyz = quat
            if not self.mesh_nodes:
                points = np.array([[Ts[a, :3, 3], Ts[b, :3, 3]] for a, b in self._segments])
                scene.add_line_segments("/robot/links", points, _LINK_COLOR, thickness=0.01)
            if not self._has_target:
                return
            i = self.robot.frame_index(self._frame)
            o = Ts[i, :3, 3]
            axes = np.asarray(axes, float)
            if np.linalg.det(axes) < 0:
                axes = axes * np.array([1.0, 1.0, -1.0])
            self._ellipsoid.position = o
            self._ellipsoid.wxyz = self._so3.from_matrix(axes).wxyz
            self._ellipsoid.scale = tuple(np.maximum(radii * self._ellipsoid_scale, 1e-6))
            if has_qd:
                V = np.asarray(V, float) * self._arrow_scale
                for name, vec, color in (
                    ("/robot/twist_v", V[:3], _V_COLOR),
                    ("/robot/twist_omega", V[3:], _W_COLOR),
                ):
                    scene.add_arrows(
                        name,
                        np.array([[o, o + vec]]),
                        color,
                        shaft_radius=0.006,
                        head_radius=0.015,
                        head_length=0.03,
                    )

    def animate(self, qs: Any, fps: float = 30.0, qds: Any = None, loops: int = 1) -> None:
        """Play the trajectory ``qs`` (T, nq) (and ``qds`` (T, nv)) at ``fps``; blocks."""
        qs = np.asarray(qs, float)
        if qs.ndim != 2 or qs.shape[1] != self.robot.nq:
            raise ViewerError(
                f"animate needs qs of shape (T, {self.robot.nq}), got {qs.shape}; "
                "stack the configurations with np.stack(qs)."
            )
        if qds is not None and np.shape(qds) != (qs.shape[0], self.robot.nv):
            raise ViewerError(
                f"qds must have shape {(qs.shape[0], self.robot.nv)} (one velocity per row of "
                f"qs), got {np.shape(qds)}."
            )
        if not fps > 0:
            raise ViewerError(f"fps must be positive, got {fps}.")
        for _ in range(loops):
            for k, q in enumerate(qs):
                start = time.perf_counter()
                self.update(q, None if qds is None else qds[k])
                time.sleep(max(0.0, 1.0 / fps - (time.perf_counter() - start)))

    def close(self) -> None:
        """Stop the server (idempotent)."""
        if not self._closed:
            self._closed = True
            self.server.stop()

    def _check_open(self) -> None:
        if self._closed:
            raise ViewerError("this viewer was closed; call jaxkin.viewer.show again.")

    def __enter__(self) -> View:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _free_port(host: str) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def show(
    robot: Robot,
    q: Any,
    qd: Any = None,
    *,
    port: int | None = None,
    host: str = "127.0.0.1",
    frame: int | str | None = None,
    urdf: str | os.PathLike | None = None,
    mjcf: str | os.PathLike | None = None,
    meshes: bool = True,
    packages: Mapping[str, str | os.PathLike] | None = None,
    arrow_scale: float = 0.2,
    ellipsoid_scale: float = 0.3,
) -> View:
    """Serve a 3-D view of ``robot`` at ``q`` (and the twist for ``qd``) on ``http://host:port``.

    ``port=None`` picks a free port; ``host`` defaults to loopback (``"0.0.0.0"`` serves other
    machines). ``frame``: where twist and ellipsoid are drawn (default: the robot's default
    frame). ``urdf``: the file the robot was loaded from, for its meshes (found by itself for
    ``jk.robots.load("erd/...")``); ``mjcf``: the same for a robot of :func:`jaxkin.load_mjcf`
    (found by itself for ``jk.robots.load("mjcf/...")``); ``meshes=False`` draws link segments
    instead. ``packages``: ``{package name: directory}`` for the URDF's ``package://`` paths
    found elsewhere than beside it (module doc, "Where meshes are read from"). The page opens
    framing the robot (:func:`camera_framing`). Returns a
    :class:`View`; see the module doc for what is drawn and the example.
    """
    viser, _ = _viser()
    if not isinstance(robot, Robot):
        raise ViewerError(f"show needs a jaxkin Robot, got {type(robot).__name__}.")
    if urdf is not None and mjcf is not None:
        raise ViewerError("pass urdf= or mjcf= (the file the robot was loaded from), not both.")
    if port is None:
        port = _free_port(host)
    server = viser.ViserServer(host=host, port=int(port), verbose=False)
    try:
        view = View(
            robot, server, frame, arrow_scale, ellipsoid_scale, meshes, urdf, mjcf, packages
        )
        view.update(q, qd)
    except BaseException:
        server.stop()
        raise
    return view
