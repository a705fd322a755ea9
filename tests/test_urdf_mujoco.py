"""Real robot files against MuJoCo: MuJoCo's own URDF importer and ``mj_jac`` at an offset point.

MuJoCo loads each URDF with the compiler settings of tests/README.md (``fusestatic="false"`` so that
fixed-joint links stay bodies, ``discardvisual``, ``balanceinertia``; plus ``boundmass`` and
``boundinertia`` because the visual and collision meshes are stripped before loading, so no mesh
file is looked for). At the shared 25 random configurations (``_urdf_support.oracle_case``, no
extra compile): every link's pose (``xpos``, ``xmat`` after ``mj_kinematics``) equals jaxkin's
``fk_all``, and for three links per robot the point Jacobian ``mj_jac(m, d, jacp, jacr, point,
body)`` at the world point ``p + R @ POINT`` (POINT an offset in the link's axes) equals
``jk.geometric_jacobian(robot, q, frame=link, point=POINT)`` ([v; omega], world axes), to
``1e-12 * max(1, reach)``. MuJoCo turns a URDF mimic into an equality constraint between two
independent joints; jaxkin's folded columns are compared through the same linear map as for
Pinocchio (``J_jaxkin = J_mj @ S``).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from _urdf_support import POINT, erd_root, oracle_case, point_frames, tolerance

mujoco = pytest.importorskip("mujoco")

if erd_root() is None:
    pytest.skip("example-robot-data is not installed (test extra)", allow_module_level=True)

ROBOTS = ["erd/panda", "erd/kinova", "data/kuka_iiwa14.urdf", "erd/ur5_robot"]


def mujoco_model(path):
    # The file is example-robot-data's or ours (trusted test input): ElementTree is fine here.
    root = ET.fromstring(path.read_bytes())
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for e in link.findall(tag):
                link.remove(e)
    extra = ET.SubElement(root, "mujoco")
    ET.SubElement(
        extra,
        "compiler",
        fusestatic="false",
        discardvisual="true",
        balanceinertia="true",
        boundmass="1e-6",
        boundinertia="1e-9",
    )
    return mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))


class MujocoMap:
    """jaxkin q -> MuJoCo qpos, and S (nv x dof) with J_jaxkin = J_mj @ S, by joint name."""

    def __init__(self, case, m):
        index = {n: i for i, n in enumerate(case.robot.joint_names)}
        by_name = case.urdf.joint_map
        self.S = np.zeros((m.nv, case.robot.dof))
        self.terms = []
        for jid in range(m.njnt):
            name = m.joint(jid).name
            j, mult, off = by_name[name], 1.0, 0.0
            while j.mimic is not None:
                mult, off = mult * j.mimic.multiplier, mult * j.mimic.offset + off
                j = by_name[j.mimic.joint]
            i = index[j.name]
            self.S[m.jnt_dofadr[jid], i] = mult
            self.terms.append((m.jnt_qposadr[jid], i, mult, off))

    def qpos(self, m, q):
        out = np.zeros(m.nq)
        for adr, i, mult, off in self.terms:
            out[adr] = mult * q[i] + off
        return out


@pytest.fixture(scope="module", params=ROBOTS)
def setup(request):
    case = oracle_case(request.param)
    m = mujoco_model(case.path)
    return case, m, MujocoMap(case, m)


def test_mujoco_model_has_the_same_links_and_joints(setup):
    case, m, _ = setup
    bodies = {m.body(i).name for i in range(m.nbody)}
    assert set(case.robot.frame_names) <= bodies
    joints = {m.joint(i).name for i in range(m.njnt)}
    mimic = {j.name for j in case.urdf.joints if j.mimic is not None and j.type != "fixed"}
    assert joints == set(case.robot.joint_names) | mimic
    assert m.nv == case.robot.dof + len(mimic)


def test_fk_of_every_link_matches_mujoco(setup):
    case, m, mm = setup
    d = mujoco.MjData(m)
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f) for f in case.robot.frame_names]
    tol = tolerance(case.out["Ts"])
    for k, q in enumerate(case.qs):
        d.qpos[:] = mm.qpos(m, q)
        mujoco.mj_kinematics(m, d)
        for fi, bid in enumerate(ids):
            T = case.out["Ts"][k, fi]
            np.testing.assert_allclose(T[:3, 3], d.xpos[bid], rtol=0, atol=tol)
            np.testing.assert_allclose(T[:3, :3], d.xmat[bid].reshape(3, 3), rtol=0, atol=tol)


def test_point_jacobian_matches_mj_jac(setup):
    case, m, mm = setup
    d = mujoco.MjData(m)
    frames = point_frames(case.robot)
    assert len(frames) == 3
    tol = tolerance(case.out["Ts"])
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    checked = 0
    for k, q in enumerate(case.qs):
        d.qpos[:] = mm.qpos(m, q)
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        for f in frames:
            fi = case.robot.frame_names.index(f)
            T = case.out["Ts"][k, fi]
            world_point = T[:3, 3] + T[:3, :3] @ POINT
            bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f)
            mujoco.mj_jac(m, d, jacp, jacr, world_point, bid)
            expected = np.vstack([jacp, jacr]) @ mm.S
            np.testing.assert_allclose(
                case.out[f"{f}/point"][k],
                expected,
                rtol=0,
                atol=tol,
                err_msg=f"{case.key} frame {f} q={q}",
            )
            checked += int(np.any(np.abs(expected) > 0))
    assert checked >= len(case.qs)  # non-trivial Jacobians were compared
    assert math.isfinite(tol)
