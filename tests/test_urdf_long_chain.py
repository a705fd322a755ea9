"""A 3,000-joint chain: it loads fast and iteratively (no recursion limit anywhere), and forward
kinematics of its tip is finite and equals the numpy product of its 3,000 joint transforms.

The chain cycles through revolute, prismatic, continuous and fixed joints with non-unit axes and
non-zero rpy (2,250 DOF). Loading is checked under a recursion limit only a little above the
caller's depth, so any recursive tree algorithm would fail here.

``jax.jit`` of ``fk`` and of the geometric Jacobian compiles in bounded time: long serial chains
run through the ``lax.scan`` forward pass of jaxkin/kinematics.py (``uses_scan``), whose compile
time does not grow with the number of joints (about 1 s each here, asserted < 60 s).
"""

from __future__ import annotations

import inspect
import math
import sys
import time

import jax
import numpy as np
import pytest

import jaxkin as jk
from jaxkin.urdf import load_urdf, parse_urdf

N = 3000
KINDS = ("revolute", "prismatic", "continuous", "fixed")
XYZ, RPY, AXIS = (0.01, 0.002, 0.003), (0.1, -0.05, 0.2), (0.3, 0.4, 1.0)
LOAD_SECONDS = 10.0  # measured about 1 s on a loaded 2-core machine


def chain_xml(n: int) -> str:
    parts = ['<?xml version="1.0"?>', '<robot name="snake">']
    parts += [f'  <link name="l{i}"/>' for i in range(n + 1)]
    xyz, rpy, axis = (" ".join(map(repr, v)) for v in (XYZ, RPY, AXIS))
    for i in range(n):
        kind = KINDS[i % 4]
        limit = (
            '<limit lower="-1" upper="1" effort="1" velocity="1"/>'
            if kind in ("revolute", "prismatic")
            else ""
        )
        parts.append(
            f'  <joint name="j{i}" type="{kind}"><parent link="l{i}"/><child link="l{i + 1}"/>'
            f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>{limit}</joint>'
        )
    parts.append("</robot>")
    return "\n".join(parts)


@pytest.fixture(scope="module")
def xml():
    return chain_xml(N)


def _numpy_tip(q: np.ndarray) -> np.ndarray:
    def rot(axis, t):
        k = np.asarray(axis) / np.linalg.norm(axis)
        K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        return np.eye(3) + math.sin(t) * K + (1 - math.cos(t)) * K @ K

    r, p, y = RPY
    origin = np.eye(4)
    origin[:3, :3] = rot((0, 0, 1), y) @ rot((0, 1, 0), p) @ rot((1, 0, 0), r)
    origin[:3, 3] = XYZ
    unit = np.asarray(AXIS) / np.linalg.norm(AXIS)
    T = np.eye(4)
    k = 0
    for i in range(N):
        T = T @ origin
        kind = KINDS[i % 4]
        if kind == "fixed":
            continue
        M = np.eye(4)
        if kind == "prismatic":
            M[:3, 3] = unit * q[k]
        else:
            M[:3, :3] = rot(AXIS, q[k])
        T = T @ M
        k += 1
    return T


def test_long_chain_parses_iteratively_and_fast(xml):
    depth = len(inspect.stack())
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(depth + 60)  # any recursion over 3,000 joints would blow this
    try:
        t0 = time.perf_counter()
        model = parse_urdf(xml)
        parse_s = time.perf_counter() - t0
    finally:
        sys.setrecursionlimit(old)
    assert len(model.joints) == N and model.root == "l0"
    assert len(list(model.depth_first())) == N
    t0 = time.perf_counter()
    robot = load_urdf(xml, dtype=np.float64)
    load_s = time.perf_counter() - t0
    assert robot.dof == N * 3 // 4 and robot.n_frames == N + 1
    assert robot.frame_names[-1] == f"l{N}"
    assert parse_s + load_s < LOAD_SECONDS, (parse_s, load_s)
    chain = load_urdf(xml, tip="l1500", base="l1000", dtype=np.float64)
    assert chain.n_frames == 501 and chain.dof == 375


def test_long_chain_cycle_is_found_iteratively():
    # A 3,000-link cycle hanging off nothing: found without recursion, reported by name.
    n = 3000
    parts = ['<robot name="loop">', '<link name="root"/>', '<link name="leaf"/>']
    parts += [f'<link name="c{i}"/>' for i in range(n)]
    parts.append('<joint name="r" type="fixed"><parent link="root"/><child link="leaf"/></joint>')
    parts += [
        f'<joint name="k{i}" type="fixed"><parent link="c{i}"/><child link="c{(i + 1) % n}"/>'
        "</joint>"
        for i in range(n)
    ]
    parts.append("</robot>")
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(len(inspect.stack()) + 60)
    try:
        with pytest.raises(jk.ModelError, match="the joints form a cycle: c0 -> c1 -> c2"):
            parse_urdf("\n".join(parts))
    finally:
        sys.setrecursionlimit(old)


def test_deeply_nested_xml_is_not_a_recursion_problem():
    deep = "<robot name='r'><link name='a'/>" + "<x>" * 100_000 + "</x>" * 100_000 + "</robot>"
    assert load_urdf(deep).dof == 0  # one link, no joint: a zero-dof robot (test_zero_dof)


COMPILE_SECONDS = 60.0  # measured about 1 s (scan path); an unrolled kernel takes minutes


def test_long_chain_fk_and_jacobian_jit_and_match_numpy(xml):
    robot = load_urdf(xml, dtype=np.float64)
    q = np.random.default_rng(0).uniform(-1.0, 1.0, robot.dof)
    fk = jax.jit(lambda q: jk.fk(robot, q))
    t0 = time.perf_counter()
    T = np.asarray(fk(q))
    assert time.perf_counter() - t0 < COMPILE_SECONDS
    assert np.all(np.isfinite(T))
    expected = _numpy_tip(q)
    reach = max(1.0, float(np.linalg.norm(expected[:3, 3])))
    # 3,000 products of rotations: rounding grows with the number of joints (~ N * eps).
    np.testing.assert_allclose(T, expected, rtol=0, atol=N * 1e-15 * reach)
    jac = jax.jit(lambda q: jk.geometric_jacobian(robot, q, frame="l1500", reference="local"))
    t0 = time.perf_counter()
    J = np.asarray(jac(q))
    assert time.perf_counter() - t0 < COMPILE_SECONDS
    assert J.shape == (6, robot.dof) and np.all(np.isfinite(J))
    # Joints beyond link l1500 do not move it: exact zero columns (1500 joints, 1125 DOF before).
    assert np.all(J[:, 1125:] == 0.0) and np.all(np.any(J[:, :1125] != 0.0, axis=0))
    # Same answer eagerly (op by op), to the same rounding.
    np.testing.assert_allclose(np.asarray(jk.fk(robot, q)), T, rtol=0, atol=N * 1e-15 * reach)


def test_long_mimic_chain_resolves_in_linear_time():
    # 3,000 joints, each mimicking the previous one (value_i = 1.001 value_{i-1} + 0.001):
    # one DOF; resolved iteratively and memoised, both by the parser and by Robot.from_joints.
    n = 3000
    parts = ['<robot name="fingers">'] + [f'<link name="l{i}"/>' for i in range(n + 1)]
    for i in range(n):
        mimic = f'<mimic joint="j{i - 1}" multiplier="1.001" offset="0.001"/>' if i else ""
        parts.append(
            f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
            f'<axis xyz="0 0 1"/><limit lower="-1" upper="1"/>{mimic}</joint>'
        )
    parts.append("</robot>")
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(len(inspect.stack()) + 60)
    try:
        t0 = time.perf_counter()
        model = parse_urdf("\n".join(parts))
    finally:
        sys.setrecursionlimit(old)
    robot = load_urdf("\n".join(parts), dtype=np.float64)
    assert time.perf_counter() - t0 < LOAD_SECONDS
    assert robot.joint_names == ("j0",) and set(robot.q_index) == {0}
    assert model.independent_joints == ("j0",)
    M = np.asarray(robot.multiplier)
    O = np.asarray(robot.offset)
    k = np.arange(n)
    np.testing.assert_allclose(M, 1.001**k, rtol=1e-12)
    np.testing.assert_allclose(O, (1.001**k - 1.0) / 0.001 * 0.001, rtol=1e-9, atol=1e-15)


def test_long_random_chain_matches_pinocchio():
    """A 64-joint chain (long enough for the scan forward pass) with random placements, non-unit
    axes, every joint type and a mimic joint, against Pinocchio: every link's pose and the tip's
    Jacobian in all three references, to 1e-12 * max(1, reach)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        pin = pytest.importorskip("pinocchio")
    from _urdf_support import PinocchioMap, pinocchio_frames_and_jacobians

    rng = np.random.default_rng(64)
    n = 64
    parts = ['<robot name="random_chain">'] + [f'<link name="l{i}"/>' for i in range(n + 1)]
    for i in range(n):
        kind = ("revolute", "prismatic", "continuous", "fixed")[int(rng.integers(4))]
        xyz = " ".join(repr(float(x)) for x in rng.normal(0, 0.05, 3))
        rpy = " ".join(repr(float(x)) for x in rng.uniform(-np.pi, np.pi, 3))
        axis = " ".join(repr(float(x)) for x in rng.normal(0, 1, 3))
        lim = '<limit lower="-1" upper="1" effort="1" velocity="1"/>'
        limit = lim if kind in ("revolute", "prismatic") else ""
        mimic = '<mimic joint="j1" multiplier="-0.5" offset="0.1"/>' if i == 40 else ""
        if i in (1, 40):  # the leader and its follower
            kind, limit = "revolute", lim
        parts.append(
            f'<joint name="j{i}" type="{kind}"><parent link="l{i}"/><child link="l{i + 1}"/>'
            f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>{limit}{mimic}</joint>'
        )
    parts.append("</robot>")
    xml = "\n".join(parts)
    robot = load_urdf(xml, dtype=np.float64)
    model = pin.buildModelFromXML(xml)
    pmap = PinocchioMap(robot, parse_urdf(xml), model)
    refs = ("world_aligned", "local", "world")

    @jax.jit
    def kernel(q):
        return jk.fk_all(robot, q), [jk.geometric_jacobian(robot, q, reference=r) for r in refs]

    for q in rng.uniform(-1, 1, (5, robot.dof)):
        Ts, Js = (jax.tree_util.tree_map(np.asarray, x) for x in kernel(q))
        T_pin, J_pin = pinocchio_frames_and_jacobians(pmap, q)
        tol = 1e-12 * max(1.0, float(np.max(np.linalg.norm(T_pin[:, :3, 3], axis=-1))))
        np.testing.assert_allclose(Ts, T_pin, rtol=0, atol=tol)
        for r, J in zip(refs, Js, strict=True):
            np.testing.assert_allclose(J, J_pin[r][-1], rtol=0, atol=tol, err_msg=r)
