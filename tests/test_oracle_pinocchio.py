"""Zoo robots against Pinocchio (independent oracle: its URDF parser and joint algebra).

* Niryo One: a minimal URDF written here from the manufacturer's numbers
  (shared/robots/niryo_one.md; kinematics only, no inertia) is loaded by Pinocchio and compared
  with the zoo's ``niryo_one`` (URDF-style placements).
* Panda: a URDF generated here from the zoo's modified-DH table (each joint's constant placement
  ``Rx(alpha) Tx(a) Rz(theta) Tz(d)`` becomes the URDF joint origin xyz/rpy with axis z; the tool a
  fixed joint): Pinocchio's URDF and joint algebra against jaxkin's DH kernel.

At 50 random configurations within the limits (fixed seed), for every frame in
``robot.frame_names``: jaxkin ``fk_all`` equals Pinocchio ``framesForwardKinematics`` /
``data.oMf``; ``geometric_jacobian`` equals ``computeJointJacobians`` + ``getFrameJacobian`` with
"world_aligned" == LOCAL_WORLD_ALIGNED, "local" == LOCAL and "world" == WORLD, to
``1e-12 * max(1, reach)``. Joints are matched by name (Pinocchio orders q by ``model.names``).
"""

from __future__ import annotations

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sampling import sample_configurations
from _xla import FAST_COMPILE

import jaxkin as jk

with warnings.catch_warnings():
    # Pinocchio imports cleanly today; keep a future import-time deprecation in it from failing
    # collection (warnings are errors in this suite).
    warnings.simplefilter("ignore", DeprecationWarning)
    pin = pytest.importorskip("pinocchio")

N_CONFIGS = 50
SEED = 7


REFERENCES = {
    "world_aligned": pin.LOCAL_WORLD_ALIGNED,
    "local": pin.LOCAL,
    "world": pin.WORLD,
}

# ----------------------------------------------------------------------------------- Niryo One
# The manufacturer's numbers (niryo_one_description v2, as listed in shared/robots/niryo_one.md),
# pi written as 3.14159265359 as in the description. Kinematics only: no inertia, no geometry.
_NIRYO_PI = "3.14159265359"
_NIRYO_HALF_PI = repr(float(_NIRYO_PI) / 2)
_NIRYO_JOINTS = [
    # name, type, parent, child, xyz, rpy, lower, upper
    ("ground_joint", "fixed", "ground_link", "base_link", "0 0 0", "0 0 0", None, None),
    ("joint_1", "revolute", "base_link", "shoulder_link", "0 0 0.103", "0 0 0", -3.05433, 3.05433),
    (
        "joint_2",
        "revolute",
        "shoulder_link",
        "arm_link",
        "0 0 0.08",
        f"{_NIRYO_HALF_PI} -{_NIRYO_HALF_PI} 0",
        f"-{_NIRYO_HALF_PI}",
        0.628319,
    ),
    (
        "joint_3",
        "revolute",
        "arm_link",
        "elbow_link",
        "0.21004 0 0",
        f"0 0 -{_NIRYO_HALF_PI}",
        -1.401,
        0.994838,
    ),
    (
        "joint_4",
        "revolute",
        "elbow_link",
        "forearm_link",
        "0.037 0.032 0",
        f"0 {_NIRYO_HALF_PI} 0",
        -2.61799,
        2.61799,
    ),
    (
        "joint_5",
        "revolute",
        "forearm_link",
        "wrist_link",
        "0 0 0.180",
        f"0 -{_NIRYO_HALF_PI} 0",
        -2.26893,
        2.26893,
    ),
    (
        "joint_6",
        "revolute",
        "wrist_link",
        "hand_link",
        "0.018 0 0",
        f"0 {_NIRYO_HALF_PI} 0",
        -2.57,
        2.57,
    ),
    (
        "hand_gripper_joint",
        "fixed",
        "hand_link",
        "gripper_link",
        "0 0 0",
        f"-{_NIRYO_HALF_PI} -{_NIRYO_HALF_PI} 0",
        None,
        None,
    ),
]


def niryo_urdf() -> str:
    links = ["ground_link"] + [j[3] for j in _NIRYO_JOINTS]
    parts = ['<?xml version="1.0"?>', '<robot name="niryo_one">']
    parts += [f'  <link name="{name}"/>' for name in links]
    for name, kind, parent, child, xyz, rpy, lower, upper in _NIRYO_JOINTS:
        parts.append(f'  <joint name="{name}" type="{kind}">')
        parts.append(f'    <parent link="{parent}"/><child link="{child}"/>')
        parts.append(f'    <origin xyz="{xyz}" rpy="{rpy}"/>')
        if kind != "fixed":
            parts.append('    <axis xyz="0 0 1"/>')
            parts.append(f'    <limit lower="{lower}" upper="{upper}" effort="10" velocity="1.0"/>')
        parts.append("  </joint>")
    parts.append("</robot>")
    return "\n".join(parts)


# ----------------------------------------------------------------------------------- DH -> URDF
def _rot_x(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_z(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rpy_from_matrix(R: np.ndarray) -> np.ndarray:
    """URDF rpy (R = Rz(y) Ry(p) Rx(r)) of R, checked to rebuild R."""
    yaw = math.atan2(R[1, 0], R[0, 0])
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    roll = math.atan2(R[2, 1], R[2, 2])
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rebuilt = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]]) @ Ry @ _rot_x(roll)
    np.testing.assert_allclose(rebuilt, R, rtol=0, atol=1e-15)
    return np.array([roll, pitch, yaw])


def _origin(T: np.ndarray) -> str:
    xyz = " ".join(repr(float(x)) for x in T[:3, 3])
    rpy = " ".join(repr(float(x)) for x in _rpy_from_matrix(T[:3, :3]))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def modified_dh_urdf(robot: jk.Robot) -> str:
    """URDF of a modified-DH zoo robot, from its parameters (read from the model at run time).

    Joint i (parent frame ``link{i-1}``, child ``link{i}``): origin ``Rx(alpha) Tx(a) Rz(theta)
    Tz(d)`` (theta including the joint offset), axis z. Base and tool are fixed joints.
    """
    assert robot.parameterisation == "dh_modified"
    P = {k: np.asarray(v, dtype=np.float64) for k, v in robot.params.items()}
    offset = np.asarray(robot.offset)
    lower, upper = np.asarray(robot.lower), np.asarray(robot.upper)
    names = robot.frame_names  # base, link1 .. linkN, [tool]
    parts = ['<?xml version="1.0"?>', f'<robot name="{robot.name}">', '  <link name="world"/>']
    parts += [f'  <link name="{name}"/>' for name in names]
    parts.append('  <joint name="base_placement" type="fixed">')
    parts.append(f'    <parent link="world"/><child link="{names[0]}"/>')
    parts.append(f"    {_origin(np.asarray(robot.base))}")
    parts.append("  </joint>")
    for i, kind in enumerate(robot.kinds):
        a, alpha, d, theta = P["a"][i], P["alpha"][i], P["d"][i], P["theta"][i]
        if kind == "revolute":
            theta = theta + offset[i]
        else:
            d = d + offset[i]
        B = np.eye(4)
        B[:3, :3] = _rot_x(alpha) @ _rot_z(theta)
        B[:3, 3] = [a, -math.sin(alpha) * d, math.cos(alpha) * d]
        lo = float(lower[i]) if np.isfinite(lower[i]) else -1e3
        hi = float(upper[i]) if np.isfinite(upper[i]) else 1e3
        parts.append(f'  <joint name="{robot.joint_names[i]}" type="{kind}">')
        parts.append(f'    <parent link="{names[i]}"/><child link="{names[i + 1]}"/>')
        parts.append(f"    {_origin(B)}")
        parts.append('    <axis xyz="0 0 1"/>')
        parts.append(f'    <limit lower="{lo!r}" upper="{hi!r}" effort="10" velocity="1"/>')
        parts.append("  </joint>")
    if robot.has_tool:
        parts.append('  <joint name="tool_placement" type="fixed">')
        parts.append(f'    <parent link="{names[-2]}"/><child link="tool"/>')
        parts.append(f"    {_origin(np.asarray(robot.tool))}")
        parts.append("  </joint>")
    parts.append("</robot>")
    return "\n".join(parts)


# ----------------------------------------------------------------------------------- helpers


def _kernel(robot: jk.Robot, qs: jax.Array):
    """fk_all and the geometric Jacobian of every frame in every reference, batched over qs: all
    frames in one call per reference (``frame=[...]``), and the last frame's single-frame call."""

    frames = list(robot.frame_names)

    def one(q):
        out = {"Ts": jk.fk_all(robot, q)}
        for ref in REFERENCES:
            # every frame in one pass (one program, not one per frame and reference) ...
            Js = jk.geometric_jacobian(robot, q, frame=frames, reference=ref)
            out.update({f"{f}/{ref}": J for f, J in zip(frames, Js, strict=True)})
            # ... and the single-frame call, for the last frame
            out[f"one/{ref}"] = jk.geometric_jacobian(robot, q, frame=frames[-1], reference=ref)
        return out

    return jax.vmap(one)(qs)


# the robot static: constants folded, a compile several times faster than over a traced robot
_kernel = jax.jit(_kernel, static_argnums=0, compiler_options=FAST_COMPILE)


def _pinocchio_model(name: str, robot: jk.Robot):
    xml = niryo_urdf() if name == "niryo_one" else modified_dh_urdf(robot)
    return pin.buildModelFromXML(xml)


@pytest.fixture(scope="module", params=["niryo_one", "panda"])
def case(request):
    name = request.param
    robot = jk.robots.load(name, dtype=np.float64)
    model = _pinocchio_model(name, robot)
    qs = sample_configurations(robot, N_CONFIGS, SEED)
    out = jax.tree_util.tree_map(np.asarray, _kernel(robot, jnp.asarray(qs)))
    return name, robot, model, qs, out


def _index_maps(robot: jk.Robot, model):
    """Pinocchio q and v indices of each jaxkin joint, matched by name."""
    assert model.nq == robot.dof and model.nv == robot.dof
    iq, iv = [], []
    for jname in robot.joint_names:
        assert model.existJointName(jname), jname
        joint = model.joints[model.getJointId(jname)]
        assert joint.nq == 1 and joint.nv == 1, jname
        iq.append(joint.idx_q)
        iv.append(joint.idx_v)
    return np.array(iq), np.array(iv)


def _frame_ids(robot: jk.Robot, model) -> list[int]:
    ids = []
    for fname in robot.frame_names:
        assert model.existFrame(fname), fname
        ids.append(model.getFrameId(fname))
    return ids


def _tolerance(Ts: np.ndarray) -> float:
    """1e-12 * max(1, reach), the reach being the farthest frame origin seen."""
    return 1e-12 * max(1.0, float(np.max(np.linalg.norm(Ts[..., :3, 3], axis=-1))))


# ----------------------------------------------------------------------------------- tests
def test_urdf_matches_zoo_structure(case):
    _, robot, model, _, _ = case
    iq, iv = _index_maps(robot, model)
    assert sorted(iq) == list(range(robot.dof))
    assert sorted(iv) == list(range(robot.dof))
    _frame_ids(robot, model)
    # Joint limits carried into the URDF (Niryo: typed from the manufacturer's numbers).
    lo = np.asarray(model.lowerPositionLimit)[iq]
    hi = np.asarray(model.upperPositionLimit)[iq]
    np.testing.assert_allclose(lo, np.asarray(robot.lower), rtol=0, atol=1e-12)
    np.testing.assert_allclose(hi, np.asarray(robot.upper), rtol=0, atol=1e-12)


def test_fk_all_matches_pinocchio(case):
    _, robot, model, qs, out = case
    data = model.createData()
    iq, _ = _index_maps(robot, model)
    fids = _frame_ids(robot, model)
    tol = _tolerance(out["Ts"])
    for k, q in enumerate(qs):
        q_pin = np.zeros(model.nq)
        q_pin[iq] = q
        pin.framesForwardKinematics(model, data, q_pin)
        expected = np.stack([data.oMf[fid].homogeneous for fid in fids])
        np.testing.assert_allclose(out["Ts"][k], expected, rtol=0, atol=tol, err_msg=f"q={q}")


def test_geometric_jacobian_matches_pinocchio_every_frame_and_reference(case):
    name, robot, model, qs, out = case
    data = model.createData()
    iq, iv = _index_maps(robot, model)
    fids = _frame_ids(robot, model)
    tol = _tolerance(out["Ts"])
    for k, q in enumerate(qs):
        q_pin = np.zeros(model.nq)
        q_pin[iq] = q
        pin.computeJointJacobians(model, data, q_pin)
        pin.framesForwardKinematics(model, data, q_pin)
        for fname, fid in zip(robot.frame_names, fids, strict=True):
            for ref, rf in REFERENCES.items():
                expected = pin.getFrameJacobian(model, data, fid, rf)[:, iv]
                np.testing.assert_allclose(
                    out[f"{fname}/{ref}"][k],
                    expected,
                    rtol=0,
                    atol=tol,
                    err_msg=f"{name} frame {fname} reference {ref} q={q}",
                )
        for ref, rf in REFERENCES.items():  # the single-frame call, for the last frame
            expected = pin.getFrameJacobian(model, data, fids[-1], rf)[:, iv]
            np.testing.assert_allclose(
                out[f"one/{ref}"][k],
                expected,
                rtol=0,
                atol=tol,
                err_msg=f"{name} single-frame call, frame {robot.frame_names[-1]} reference {ref}",
            )
