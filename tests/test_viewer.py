"""jaxkin.viewer: the scene holds one node per frame at its fk_all pose, the URDF's meshes, an
MJCF file's geoms at MuJoCo's poses, the twist arrows and the velocity ellipsoid; the page is
served and headless Chromium connects to it and mounts the 3-D view (its camera reaches the
server), and the camera it opens with frames the robot (jview.camera_framing)."""

import os
import shutil
import signal
import subprocess
import sys
import threading
import urllib.request
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from _oracle_modules import lazy_module

import jaxkin as jk

viser = lazy_module("viser", reason="the viewer extra: pip install 'jaxkin[viewer]'")
import jaxkin.viewer as jview  # noqa: E402

Q = np.array([0.1, -0.4, 0.2, -1.9, 0.3, 1.6, 0.5])
QD = np.array([0.3, -0.2, 0.1, 0.4, -0.5, 0.2, 0.6])
TOL = 1e-6


def _check_poses(view, robot, q):
    """Every frame node sits at its fk_all pose (position and rotation)."""
    Ts = np.asarray(jk.fk_all(robot, q))
    for i, name in enumerate(robot.frame_names):
        handle = view.server.scene.get_handle_by_name(view.nodes[name])
        assert handle is not None, name
        np.testing.assert_allclose(handle.position, Ts[i, :3, 3], atol=TOL)
        R = viser.transforms.SO3(np.asarray(handle.wxyz)).as_matrix()
        np.testing.assert_allclose(R, Ts[i, :3, :3], atol=TOL)


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def test_panda_meshes_frames_twist_ellipsoid_in_headless_chromium(tmp_path):
    if not jk.robots.erd_names():
        pytest.skip("example-robot-data is not installed (pip install example-robot-data)")
    browser = _chromium()
    if browser is None:
        pytest.skip("no chromium binary (Debian: apt-get install chromium)")
    robot = jk.robots.load("erd/panda")
    # The links of the file that carry a <visual><mesh>, read independently of the viewer.
    root = ET.parse(jk.robots.example_robot_data.path("erd/panda")).getroot()
    with_mesh = {
        link.get("name")
        for link in root.findall("link")
        if link.find("visual/geometry/mesh") is not None
    }
    expected_meshes = {f"/robot/{n}/visual_0" for n in with_mesh & set(robot.frame_names)}
    assert len(expected_meshes) >= 8  # link0..link7 and the hand

    with jview.show(robot, Q, QD) as view:
        assert view.url.startswith("http://127.0.0.1:")
        assert list(view.nodes) == list(robot.frame_names)
        assert set(view.mesh_nodes) == expected_meshes
        scene = view.server.scene
        for node in view.mesh_nodes:
            assert scene.get_handle_by_name(node) is not None, node
        assert scene.get_handle_by_name("/robot/links") is None  # meshes replace segments
        _check_poses(view, robot, Q)

        # Twist arrows and ellipsoid at the default frame (panda_hand_tcp).
        i = robot.frame_index(None)
        o = np.asarray(jk.fk_all(robot, Q))[i, :3, 3]
        ell = jk.velocity_ellipsoid(jk.geometric_jacobian(robot, Q))
        handle = scene.get_handle_by_name("/robot/ellipsoid")
        np.testing.assert_allclose(handle.position, o, atol=TOL)
        np.testing.assert_allclose(handle.scale, np.asarray(ell.radii) * 0.3, rtol=1e-6)
        for node in ("/robot/twist_v", "/robot/twist_omega"):
            assert scene.get_handle_by_name(node) is not None, node

        # update() and animate() move every frame.
        view.update(-Q, QD)
        _check_poses(view, robot, -Q)
        view.animate(np.stack([Q, 0.5 * Q, -0.5 * Q]), fps=200)
        _check_poses(view, robot, -0.5 * Q)

        with urllib.request.urlopen(view.url, timeout=10) as page:
            assert page.status == 200
            assert b"<html" in page.read().lower()

        # A headless browser loads the page, opens the websocket and mounts the 3-D canvas:
        # the client's first camera message reaches the server.
        mounted, framed = threading.Event(), threading.Event()
        connected = []

        def on_update(camera):
            mounted.set()
            # The browser reports its default camera, then the one the server set.
            position, look_at = np.array(camera.position), np.array(camera.look_at)
            if np.allclose(position, view.camera[0], atol=1e-3) and np.allclose(
                look_at, view.camera[1], atol=1e-3
            ):
                framed.set()

        def on_connect(client):
            connected.append(client.client_id)  # the browser may leave before we look
            client.camera.on_update(on_update)

        view.server.on_client_connect(on_connect)
        cmd = [
            browser,
            "--headless",
            "--disable-gpu",
            "--no-sandbox",
            "--no-first-run",
            f"--user-data-dir={tmp_path / 'profile'}",
            "--window-size=480,360",
            view.url,
        ]
        proc = subprocess.Popen(
            cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
        )
        try:
            assert mounted.wait(60), "headless chromium did not mount the viewer within 60 s"
            assert len(connected) >= 1
            # The browser's camera moves to the one that frames the robot (camera_framing).
            assert framed.wait(60), "the browser's camera did not take the framing camera"
        finally:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(20)
    with pytest.raises(jview.ViewerError, match="closed"):
        view.update(Q)


def test_dh_robot_without_meshes_draws_link_segments():
    robot = jk.robots.load("puma560")
    q = np.array([0.2, -0.5, 0.4, 0.1, 0.6, -0.3])
    with jview.show(robot, q) as view:
        assert list(view.nodes) == list(robot.frame_names)
        assert view.mesh_nodes == []
        scene = view.server.scene
        assert scene.get_handle_by_name("/robot/links") is not None
        assert scene.get_handle_by_name("/robot/twist_v") is None  # no qd, no twist
        _check_poses(view, robot, q)
        # The page opens framing the robot at q: its frame origins (no meshes).
        position, look_at = jview.camera_framing(np.asarray(jk.fk_all(robot, q))[:, :3, 3])
        scene_camera = view.server.initial_camera
        np.testing.assert_allclose(scene_camera.position, position, atol=1e-9)
        np.testing.assert_allclose(scene_camera.look_at, look_at, atol=1e-9)
        np.testing.assert_allclose(view.camera[0], position, atol=1e-9)
        view.update(-q)  # later configurations leave the initial camera where it is
        np.testing.assert_allclose(scene_camera.position, position, atol=1e-9)
        with pytest.raises(jview.ViewerError, match=r"shape \(T, 6\)"):
            view.animate(q)
        with pytest.raises(jk.JaxkinError):
            view.update(q[:3])


def test_camera_framing_looks_at_the_centre_from_a_distance_proportional_to_the_extent():
    """A cube of side ``s`` centred at ``c``: the camera looks at ``c`` from the direction
    (1, 0.75, 0.6), at 1.1 r / sin(fov / 2) with r = s sqrt(3) / 2 (the box's sphere fills the
    vertical field of view with a 10 % margin): the distance scales with the robot."""
    c = np.array([0.4, -1.0, 0.7])
    unit = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) / 2.0
    u = np.array([1.0, 0.75, 0.6]) / np.linalg.norm([1.0, 0.75, 0.6])
    for side in (0.3, 1.0, 4.0):
        for fov in (np.radians(75.0), np.radians(50.0)):
            position, look_at = jview.camera_framing(c + side * unit, fov=fov)
            np.testing.assert_allclose(look_at, c, atol=1e-12)
            r = side * np.sqrt(3) / 2
            np.testing.assert_allclose(position, c + 1.1 * r / np.sin(fov / 2) * u, atol=1e-12)
    # The whole box is in view: its sphere subtends less than the field of view.
    position, look_at = jview.camera_framing(c + unit)
    d = np.linalg.norm(position - look_at)
    assert 2 * np.degrees(np.arcsin((np.sqrt(3) / 2) / d)) < 75.0
    # One point (a robot without links) and non-finite rows: a 5 cm sphere around what is finite.
    position, look_at = jview.camera_framing([[1.0, 2.0, 3.0], [np.nan, 0.0, 0.0]])
    np.testing.assert_allclose(look_at, [1.0, 2.0, 3.0])
    d = np.linalg.norm(position - look_at)
    np.testing.assert_allclose(d, 1.1 * 0.05 / np.sin(np.radians(37.5)))


def test_without_the_extra_the_error_names_the_install_command(monkeypatch):
    monkeypatch.setitem(sys.modules, "viser", None)
    with pytest.raises(jview.ViewerDependencyError, match=r"pip install 'jaxkin\[viewer\]'"):
        jview.show(jk.robots.load("puma560"), np.zeros(6))
    assert issubclass(jview.ViewerDependencyError, ImportError)


def test_missing_urdf_is_a_clear_error(tmp_path):
    with pytest.raises(jview.ViewerError, match="not found"):
        jview.urdf_visuals(tmp_path / "nope.urdf")
    urdf = tmp_path / "r.urdf"
    urdf.write_text(
        '<robot name="r"><link name="a"><visual><geometry>'
        '<mesh filename="package://nowhere/meshes/a.stl"/></geometry></visual></link></robot>'
    )
    with pytest.raises(jview.ViewerError, match=r"a\.stl"):
        jview.urdf_visuals(urdf)
    urdf.write_text(
        '<robot name="r"><link name="a"><visual><geometry>'
        '<sphere radius="big"/></geometry></visual></link></robot>'
    )
    with pytest.raises(jview.ViewerError, match=r"link 'a'.*not a number"):
        jview.urdf_visuals(urdf)


def _world(view, node):
    """World pose (4x4) of a scene node: its parents' poses times its own."""
    T = np.eye(4)
    parts = node.strip("/").split("/")
    for k in range(1, len(parts) + 1):
        handle = view.server.scene.get_handle_by_name("/" + "/".join(parts[:k]))
        if handle is None:
            continue  # "/robot" itself: no node of its own
        Tk = np.eye(4)
        Tk[:3, :3] = viser.transforms.SO3(np.asarray(handle.wxyz)).as_matrix()
        Tk[:3, 3] = handle.position
        T = T @ Tk
    return T


def test_mjcf_jaco_meshes_sit_at_mujoco_geom_poses():
    if "mjcf/jaco_arm" not in jk.robots.mjcf_names():
        pytest.skip("dm-control is not installed (pip install dm-control)")
    mujoco = pytest.importorskip("mujoco")
    robot = jk.robots.load("mjcf/jaco_arm")
    q = np.array([0.3, 2.9, 1.1, -0.7, 0.4, 1.2])
    # MuJoCo's own compile of the file with its meshes, and its geom poses at qpos = q.
    m = mujoco.MjModel.from_xml_path(str(jk.robots.mjcf.path("mjcf/jaco_arm")))
    d = mujoco.MjData(m)
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    expected, counts = {}, {}
    for g in range(m.ngeom):
        body = m.body(m.geom_bodyid[g]).name
        if body not in robot.frame_names or m.geom_group[g] >= 3:
            continue
        k = counts.get(body, 0)
        counts[body] = k + 1
        expected[f"/robot/{body}/visual_{k}"] = g
    n_mesh = sum(m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH for g in expected.values())
    assert n_mesh == 6  # b_base, b_1 .. b_5

    with jview.show(robot, q) as view:
        assert set(view.mesh_nodes) == set(expected)
        assert view.server.scene.get_handle_by_name("/robot/links") is None
        _check_poses(view, robot, q)
        for node, g in expected.items():
            T = _world(view, node)
            np.testing.assert_allclose(T[:3, 3], d.geom_xpos[g], atol=TOL, err_msg=node)
            R = d.geom_xmat[g].reshape(3, 3)
            np.testing.assert_allclose(T[:3, :3], R, atol=TOL, err_msg=node)


def test_mjcf_with_missing_mesh_files_is_a_clear_error(tmp_path):
    pytest.importorskip("mujoco")
    xml = tmp_path / "arm.xml"
    xml.write_text(
        '<mujoco model="arm"><asset><mesh name="m" file="nowhere/upper.stl"/></asset>'
        '<worldbody><body name="upper"><joint name="j" axis="0 0 1"/>'
        '<geom type="mesh" mesh="m"/></body></worldbody></mujoco>'
    )
    robot = jk.load_mjcf(xml)  # jaxkin's kinematics never reads the mesh files
    with pytest.raises(jview.ViewerError, match=r"upper\.stl.*meshes=False"):
        jview.show(robot, np.zeros(1), mjcf=xml)
    with jview.show(robot, np.zeros(1), mjcf=xml, meshes=False) as view:
        assert view.mesh_nodes == []
        assert view.server.scene.get_handle_by_name("/robot/links") is not None
