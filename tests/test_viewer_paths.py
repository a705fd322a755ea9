"""jaxkin.viewer reads a URDF's mesh files only from the places the user named (the module doc,
"Where meshes are read from"): ``package://`` paths inside their package root (no ``..`` or
symbolic-link escape, no search above the URDF's parent directory), plain and ``file://`` paths
inside the URDF's directory or its parent or a ``packages=`` root, regular files of a mesh format
only. An offending mesh is skipped with one MeshPathWarning naming it and is never opened; the
link is drawn without it. Then the camera the page opens with frames the robot, meshes included."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest
from _blocking import raised_within

import jaxkin as jk
import jaxkin.viewer as jview

BOX = '<box size=".1 .1 .1"/>'


def _urdf(path, meshes: list[str], extra: str = "") -> None:
    visuals = "".join(
        f'<visual><geometry><mesh filename="{m}"/></geometry></visual>' for m in meshes
    )
    path.write_text(
        f'<robot name="r"><link name="a">{visuals}{extra}</link><link name="b"/>'
        '<joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
        '<origin xyz="0 0 .5"/><axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint></robot>'
    )


@pytest.fixture
def tree(tmp_path):
    """ws/mypkg/{urdf/robot.urdf, meshes/ok.stl}, ws/other_pkg/meshes/x.stl, outside/secret.stl
    (not a mesh: opening it as one would fail), and escapes into it."""
    ws, outside = tmp_path / "ws", tmp_path / "outside"
    for d in (ws / "mypkg" / "urdf", ws / "mypkg" / "meshes", ws / "other_pkg" / "meshes", outside):
        d.mkdir(parents=True)
    try:
        import trimesh

        trimesh.creation.box(extents=(0.2, 0.2, 0.2)).export(str(ws / "mypkg/meshes/ok.stl"))
    except ImportError:
        (ws / "mypkg/meshes/ok.stl").write_bytes(b"solid ok\nendsolid ok\n")
    (ws / "other_pkg/meshes/x.stl").write_bytes(b"solid x\nendsolid x\n")
    (outside / "secret.stl").write_text("not a mesh: a secret")
    (ws / "mypkg/meshes/link.stl").symlink_to(outside / "secret.stl")
    (ws / "mypkg/meshes/notes.txt").write_text("not a mesh")
    if hasattr(os, "mkfifo"):
        os.mkfifo(ws / "mypkg/meshes/pipe.stl")
    return tmp_path


def _visual_paths(urdf, **kw):
    return [v.path for v in jview.urdf_visuals(urdf, **kw) if v.kind == "mesh"]


def test_meshes_inside_the_package_and_beside_the_file_resolve(tree):
    urdf = tree / "ws/mypkg/urdf/robot.urdf"
    ok = (tree / "ws/mypkg/meshes/ok.stl").resolve()
    _urdf(urdf, ["package://mypkg/meshes/ok.stl", "../meshes/ok.stl", f"file://{ok}", str(ok)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _visual_paths(urdf) == [ok] * 4


@pytest.mark.parametrize(
    "mesh, why",
    [
        ("package://mypkg/../../outside/secret.stl", "outside the package root"),
        ("package://mypkg/meshes/../../../outside/secret.stl", "outside the package root"),
        ("package://mypkg/meshes/link.stl", "outside the package root"),  # symlink escape
        ("package://mypkg//{outside}/secret.stl", "outside the package root"),
        ("package://../outside/secret.stl", "names no package"),
        ("file://{outside}/secret.stl", "outside the places"),
        ("{outside}/secret.stl", "outside the places"),
        ("../../../outside/secret.stl", "outside the places"),
        ("package://mypkg/meshes/notes.txt", "not a mesh file"),
        ("package://mypkg/meshes/pipe.stl", "not a regular file"),
    ],
)
def test_escapes_and_special_files_are_skipped_with_one_warning(tree, mesh, why):
    if "pipe" in mesh and not hasattr(os, "mkfifo"):
        pytest.skip("needs os.mkfifo")
    urdf = tree / "ws/mypkg/urdf/robot.urdf"
    mesh = mesh.format(outside=tree / "outside")
    box = f"<visual><geometry>{BOX}</geometry></visual>"
    _urdf(urdf, [mesh, "package://mypkg/meshes/ok.stl"], box)
    with pytest.warns(jview.MeshPathWarning) as record:
        visuals = jview.urdf_visuals(urdf)
    assert len(record) == 1
    text = str(record[0].message)
    assert mesh in text and why in text and "never read" in text
    # The link keeps its other visuals; the offending one is left out.
    assert [v.kind for v in visuals] == ["mesh", "box"]
    assert visuals[0].path == (tree / "ws/mypkg/meshes/ok.stl").resolve()


def test_package_search_stops_at_the_parent_and_packages_names_others(tree):
    """``outside`` and ``ws`` are above the URDF's parent: not searched (the old lookup walked
    every parent up to ``/`` and found ``outside/secret.stl``); ``packages=`` names a root."""
    urdf = tree / "ws/mypkg/urdf/robot.urdf"
    _urdf(urdf, ["package://outside/secret.stl"])
    with pytest.raises(jview.ViewerError, match=r"package://outside/secret\.stl.*packages="):
        jview.urdf_visuals(urdf)
    _urdf(urdf, ["package://other_pkg/meshes/x.stl"])
    with pytest.raises(jview.ViewerError, match=r"no package 'other_pkg'"):
        jview.urdf_visuals(urdf)
    x = (tree / "ws/other_pkg/meshes/x.stl").resolve()
    assert _visual_paths(urdf, packages={"other_pkg": tree / "ws/other_pkg"}) == [x]
    # A plain path into a packages= root is allowed too; one that is missing there is an error.
    _urdf(urdf, [str(x)])
    with pytest.warns(jview.MeshPathWarning, match="outside the places"):
        assert _visual_paths(urdf) == []
    assert _visual_paths(urdf, packages={"other_pkg": tree / "ws/other_pkg"}) == [x]
    _urdf(urdf, ["package://mypkg/meshes/gone.stl"])
    with pytest.raises(jview.ViewerError, match=r"gone\.stl.*not found"):
        jview.urdf_visuals(urdf)


def test_show_skips_the_mesh_never_reads_it_and_frames_the_robot(tree):
    pytest.importorskip("viser", reason="the viewer extra: pip install 'jaxkin[viewer]'")
    urdf = tree / "ws/mypkg/urdf/robot.urdf"
    far_box = '<visual><origin xyz="0 0 3"/><geometry><box size="1 1 1"/></geometry></visual>'
    _urdf(
        urdf,
        ["package://mypkg/meshes/ok.stl", "package://mypkg/../../outside/secret.stl"],
        far_box,
    )
    robot = jk.load_urdf(urdf)
    q = np.array([0.3])
    # secret.stl is not a mesh: had it been opened, show would raise ViewerError.
    with (
        pytest.warns(jview.MeshPathWarning, match=r"secret\.stl"),
        jview.show(robot, q, urdf=urdf) as view,
    ):
        assert view.mesh_nodes == ["/robot/a/visual_0", "/robot/a/visual_1"]
        # The camera frames the frame origins and the meshes' boxes: the ok.stl cube (0.2 m)
        # at the origin and the 1 m box centred 3 m up, so it looks at z = (3.5 - 0.1) / 2.
        Ts = np.asarray(jk.fk_all(robot, q))
        box = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (2.5, 3.5)])
        cube = np.array([[x, y, z] for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1)])
        position, look_at = jview.camera_framing(np.vstack([Ts[:, :3, 3], box, cube]))
        np.testing.assert_allclose(look_at, [0.0, 0.0, 1.7], atol=1e-9)
        camera = view.server.initial_camera
        np.testing.assert_allclose(camera.look_at, look_at, atol=1e-9)
        np.testing.assert_allclose(camera.position, position, atol=1e-9)
        np.testing.assert_allclose(view.camera[0], position, atol=1e-9)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo (POSIX)")
def test_mjcf_special_files_are_refused_before_mujoco_reads_them(tmp_path):
    """The viewer compiles an MJCF file with its meshes: a mesh file or an include that is a
    FIFO is refused by name (no JAX compile happens: it fails while building the scene)."""
    pytest.importorskip("viser", reason="the viewer extra: pip install 'jaxkin[viewer]'")
    pytest.importorskip("mujoco")
    body = '<body name="upper"><joint name="j" axis="0 0 1"/><geom type="mesh" mesh="m"/></body>'
    (tmp_path / "assets").mkdir()
    os.mkfifo(tmp_path / "assets" / "upper.stl")
    xml = tmp_path / "arm.xml"
    xml.write_text(
        '<mujoco model="arm"><compiler meshdir="assets"/>'
        '<asset><mesh name="m" file="upper.stl"/></asset>'
        f"<worldbody>{body}</worldbody></mujoco>"
    )
    robot = jk.load_mjcf(xml)  # jaxkin's kinematics never reads the mesh files
    fifo = tmp_path / "assets/upper.stl"
    e = raised_within(lambda: jview.show(robot, np.zeros(1), mjcf=xml), [fifo])
    assert isinstance(e, jview.ViewerError), e
    assert "upper.stl" in str(e) and "not a regular file" in str(e)
    fifo = tmp_path / "part.xml"
    os.mkfifo(fifo)
    scene = tmp_path / "scene.xml"
    scene.write_text('<mujoco><worldbody><include file="part.xml"/></worldbody></mujoco>')
    e = raised_within(lambda: jview.show(robot, np.zeros(1), mjcf=scene), [fifo])
    assert isinstance(e, jk.mjcf.MJCFError) and "part.xml" in str(e), e
