"""``Robot.from_joints`` placements given as ``xyz`` + ``quat`` (w, x, y, z) or a 4x4
``transform`` instead of ``xyz`` + ``rpy``: the same robot to rounding, gimbal lock included,
one form per joint, clear errors. Oracle: the rotation matrix written with numpy from the
quaternion formula / the transform itself."""

from __future__ import annotations

import math

import numpy as np
import pytest

import jaxkin as jk
from jaxkin.spatial import matrix_to_rpy_np as rotation_to_rpy


def _rpy_matrix(r, p, y):
    cr, sr, cp, sp, cy, sy = (f(a) for a in (r, p, y) for f in (math.cos, math.sin))
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _quat_from_matrix(R):
    """(w, x, y, z) of a rotation (Shepperd's method, largest pivot), written for this test."""
    t = np.trace(R)
    cands = [t, R[0, 0], R[1, 1], R[2, 2]]
    k = int(np.argmax(cands))
    if k == 0:
        w = math.sqrt(1 + t) / 2
        return np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
                         (R[1, 0] - R[0, 1]) / (4 * w)])  # fmt: skip
    i, j, l = [(0, 1, 2), (1, 2, 0), (2, 0, 1)][k - 1]
    v = np.zeros(4)
    v[1 + i] = math.sqrt(1 + R[i, i] - R[j, j] - R[l, l]) / 2
    v[0] = (R[l, j] - R[j, l]) / (4 * v[1 + i])
    v[1 + j] = (R[j, i] + R[i, j]) / (4 * v[1 + i])
    v[1 + l] = (R[l, i] + R[i, l]) / (4 * v[1 + i])
    return v


def _angles():
    rng = np.random.default_rng(7)
    out = [rng.uniform(-math.pi, math.pi, 3) for _ in range(200)]
    for s in (1.0, -1.0):  # gimbal lock: exact and near, with every roll/yaw mix
        for d in (0.0, 1e-9, -1e-13, 1e-16):
            out += [np.array([r, s * math.pi / 2 + d, y]) for r, y in rng.uniform(-3, 3, (10, 2))]
    out.append(np.array([0.0, math.pi / 2, 0.0]))
    return out


def test_rotation_to_rpy_rebuilds_the_matrix_to_1e_15():
    worst = 0.0
    for a in _angles():
        R = _rpy_matrix(*a)
        back = _rpy_matrix(*rotation_to_rpy(R))
        worst = max(worst, float(np.abs(back - R).max()))
    assert worst <= 1e-15, worst
    # Exact lock matrices written by hand (entries 0 and +-1 only): yaw is 0, pitch +-pi/2.
    for s in (1.0, -1.0):
        R = np.array([[0.0, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, 0.0]])
        rpy = rotation_to_rpy(R)
        assert rpy[2] == 0.0 and rpy[1] == s * math.pi / 2
        np.testing.assert_allclose(_rpy_matrix(*rpy), R, rtol=0, atol=1e-16)


def _chain(form):
    rng = np.random.default_rng(3)
    joints = []
    for i, a in enumerate([*rng.uniform(-3, 3, (3, 3)), np.array([0.4, math.pi / 2, -1.1])]):
        xyz = rng.uniform(-1, 1, 3)
        R = _rpy_matrix(*a)
        spec = dict(name=f"j{i}", type="revolute", child=f"l{i}", axis=rng.normal(size=3))
        if form == "rpy":
            spec.update(xyz=xyz, rpy=a)
        elif form == "quat":
            q = _quat_from_matrix(R) * (-2.5 if i % 2 else 1.0)  # scale and sign do not matter
            spec.update(xyz=xyz, quat=q)
        else:
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = R, xyz
            spec.update(transform=T)
        joints.append(spec)
    return jk.Robot.from_joints(joints, dtype=np.float64)


@pytest.mark.parametrize("form", ["quat", "transform"])
def test_quat_and_transform_give_the_rpy_robot(form):
    """The stored placements rebuild the given rotations (numpy) to 1e-15; axes, names and
    limits are those of the rpy robot."""
    ref, robot = _chain("rpy"), _chain(form)
    np.testing.assert_array_equal(np.asarray(robot.params["xyz"]), np.asarray(ref.params["xyz"]))
    for a, b in zip(np.asarray(robot.params["rpy"]), np.asarray(ref.params["rpy"]), strict=True):
        np.testing.assert_allclose(_rpy_matrix(*a), _rpy_matrix(*b), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(robot.axis), np.asarray(ref.axis))
    assert robot.frame_names == ref.frame_names and robot.joint_names == ref.joint_names


def test_quat_is_scalar_first():
    """(w, x, y, z) = (cos 45deg, 0, 0, sin 45deg): a quarter turn about z."""
    s = math.sqrt(0.5)
    robot = jk.Robot.from_joints(
        [dict(name="f", type="fixed", child="c", quat=[s, 0, 0, s])], dtype=np.float64
    )
    R = np.asarray(jk.fk(robot, []))[:3, :3]
    np.testing.assert_allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], rtol=0, atol=1e-15)


@pytest.mark.parametrize(
    "extra, match",
    [
        (dict(rpy=[0, 0, 0], quat=[1, 0, 0, 0]), r"placement twice.*\['quat', 'rpy'\]"),
        (dict(transform=np.eye(4), xyz=[0, 0, 0]), r"placement twice.*exactly one form"),
        (dict(transform=np.eye(4), rpy=[0, 0, 0]), r"placement twice"),
        (dict(quat=[0, 0, 0, 0]), r"'quat' is the zero quaternion"),
        (dict(quat=[1, 0, 0]), r"'quat' must be 4 finite numbers \(w, x, y, z\)"),
        (dict(quat=[1, 0, float("nan"), 0]), r"'quat' must be 4 finite numbers"),
        (dict(transform=np.eye(3)), r"'transform' must be a 4x4"),
        (dict(transform=np.diag([1.0, 1.0, -1.0, 1.0])), r"'transform' rotation block .* -1"),
    ],
)
def test_placement_form_errors(extra, match):
    with pytest.raises(jk.ModelError, match=match):
        jk.Robot.from_joints([dict(name="j", type="revolute", child="c", **extra)])
