"""Real robot files against Pinocchio: jk.load_urdf versus Pinocchio's own URDF parser (urdfdom)
and joint algebra, on the URDFs example-robot-data ships.

For each robot, at 25 random configurations within the limits (fixed seed; continuous joints in
[-pi, pi]): every link's pose (``fk_all`` vs ``framesForwardKinematics``) and the geometric
Jacobian of every link in all three references ("world_aligned" == LOCAL_WORLD_ALIGNED, "local"
== LOCAL, "world" == WORLD) agree to ``1e-12 * max(1, reach)``; link names, joint names (matched
by name), the DOF count and the limits equal Pinocchio's. Joints are matched by name; Pinocchio's
continuous joints are (cos q, sin q). Pinocchio is built with ``mimic=False`` (each mimic joint
independent) and jaxkin's mimic folding is checked through ``J_jaxkin = J_pin @ S``,
``q_pin = pin_q(q)`` (``_urdf_support.PinocchioMap``); where Pinocchio also accepts
``mimic=True``, its DOF count and independent joints equal jaxkin's.

Default suite: Panda (tree: hand, fingers with a mimic prismatic joint, TCP), UR3, UR5, UR10,
Kinova (continuous joints), the KUKA iiwa 14 (``tests/data/kuka_iiwa14.urdf``: example-robot-data
6.0 ships no iiwa; see that file's header) and ``tests/data/tree_mimic.urdf`` (a chain of mimic
joints, one listed before its leader; branches in non-depth-first file order; CAD-residue and
non-unit axes).

``JAXKIN_FULL_CORPUS=1`` runs the other 60 loadable URDFs of example-robot-data 6.0 too (legged
robots, humanoids, hands, mobile manipulators: all are fixed-base trees in the URDF; none has a
floating joint, which jaxkin would refuse: g1's is commented out in the file): names, DOF and
every link's pose on the whole tree; the Jacobian in all three references of every link through
the chain root -> link (``load_urdf(tip=link)``, columns matched by name) and, on the whole tree,
of up to four leaf links (zero columns off their paths included). About 14 minutes on a 2-core
machine (tiago_dual, 101 DOF and 130 links, is the longest at about 70 s). The 4 files that are
not loadable kinematic models raise a ModelError instead (``test_urdf_loading.ERD_UNLOADABLE``):
``ur3.urdf`` (an empty xacro output), ``quadrotor_base`` (one link) and ``iris_simple`` (only
fixed joints) have no degree of freedom, and ``alex_psyonic_hands`` has mimic joints whose leader
does not exist (Pinocchio with ``mimic=True`` refuses it too).
"""

from __future__ import annotations

import time
import warnings

import jax
import numpy as np
import pytest
from _urdf_support import (
    FULL_CORPUS,
    REFERENCES,
    PinocchioMap,
    case_path,
    erd_root,
    oracle_case,
    pinocchio_frames_and_jacobians,
    pinocchio_model,
    random_q,
    sample_configurations,
    tolerance,
)
from _xla import FAST_COMPILE

import jaxkin as jk
from jaxkin.urdf import MOVING_TYPES, parse_urdf

with warnings.catch_warnings():
    warnings.simplefilter("ignore", DeprecationWarning)
    pin = pytest.importorskip("pinocchio")

if erd_root() is None:
    pytest.skip("example-robot-data is not installed (test extra)", allow_module_level=True)

DEFAULT = [
    "erd/panda",
    "erd/ur3_robot",
    "erd/ur5_robot",
    "erd/ur10_robot",
    "erd/kinova",
    "data/kuka_iiwa14.urdf",
    "data/tree_mimic.urdf",
]
# Not loadable kinematic models (see test_urdf_loading.ERD_UNLOADABLE for why).
UNLOADABLE = {"erd/ur3", "erd/quadrotor_base", "erd/iris_simple", "erd/alex_psyonic_hands"}
CORPUS_CONFIGS = 4
CORPUS = (
    [n for n in jk.robots.erd_names() if n not in UNLOADABLE and n not in DEFAULT]
    if FULL_CORPUS
    else []
)


def _structure(robot: jk.Robot, urdf, path):
    """Compare names, DOF and limits with Pinocchio; return the mimic=False model."""
    xml = path.read_text()
    model = pinocchio_model(xml, mimic=False)
    # Links: Pinocchio's BODY frames.
    bodies = {f.name for f in model.frames if f.type == pin.BODY}
    assert set(robot.frame_names) == bodies
    assert len(robot.frame_names) == len(bodies)
    # Joints: Pinocchio's (mimic=False) joints are every moving URDF joint. Both orders are
    # depth-first; siblings come in file order in jaxkin, by joint name in Pinocchio (urdfdom
    # keeps joints in a std::map), so names are compared as sets and jaxkin's order is checked
    # to be depth-first in file order.
    moving = list(model.names[1:])
    ours = [j.name for j in urdf.depth_first() if j.type in MOVING_TYPES]
    assert sorted(moving) == sorted(ours) and len(set(moving)) == len(moving)
    mimic = {j.name for j in urdf.joints if j.mimic is not None and j.type in MOVING_TYPES}
    assert list(robot.joint_names) == [n for n in ours if n not in mimic]
    assert robot.dof == model.nv - len(mimic)
    # With mimic=True (where Pinocchio accepts the file) its DOF are jaxkin's.
    try:
        mm = pinocchio_model(xml, mimic=True)
    except Exception:  # Pinocchio refuses some mimic layouts (romeo); mimic=False is checked
        mm = None
    if mm is not None:
        assert mm.nv == robot.dof
        independent = [
            mm.names[i] for i in range(1, mm.njoints) if "Mimic" not in mm.joints[i].shortname()
        ]
        assert sorted(independent) == sorted(robot.joint_names)
    # Limits of revolute and prismatic joints (continuous: unbounded in jaxkin).
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    for i, name in enumerate(robot.joint_names):
        j = model.joints[model.getJointId(name)]
        if urdf.joint_map[name].type == "continuous":
            assert np.isneginf(lo[i]) and np.isposinf(hi[i])
            continue
        assert lo[i] == model.lowerPositionLimit[j.idx_q], name
        assert hi[i] == model.upperPositionLimit[j.idx_q], name
    return model


@pytest.fixture(scope="module", params=DEFAULT)
def case(request):
    return oracle_case(request.param)


def test_names_dof_and_limits_match_pinocchio(case):
    _structure(case.robot, case.urdf, case.path)


def test_fk_of_every_link_matches_pinocchio(case):
    model = pinocchio_model(case.path.read_text())
    pmap = PinocchioMap(case.robot, case.urdf, model)
    tol = tolerance(case.out["Ts"])
    for k, q in enumerate(case.qs):
        Ts, _ = pinocchio_frames_and_jacobians(pmap, q, with_jacobians=False)
        np.testing.assert_allclose(case.out["Ts"][k], Ts, rtol=0, atol=tol, err_msg=f"q={q}")


def test_jacobian_of_every_link_in_every_reference_matches_pinocchio(case):
    model = pinocchio_model(case.path.read_text())
    pmap = PinocchioMap(case.robot, case.urdf, model)
    tol = tolerance(case.out["Ts"])
    for k, q in enumerate(case.qs):
        _, Js = pinocchio_frames_and_jacobians(pmap, q)
        for fi, fname in enumerate(case.robot.frame_names):
            for ref in REFERENCES:
                np.testing.assert_allclose(
                    case.out[f"{fname}/{ref}"][k],
                    Js[ref][fi],
                    rtol=0,
                    atol=tol,
                    err_msg=f"{case.key} frame {fname} reference {ref} q={q}",
                )


def test_reference_identities(case):
    """local = blkdiag(R^T, R^T) world_aligned; world = [Jv + skew(p) Jw; Jw] (all three)."""
    tol = tolerance(case.out["Ts"])
    for fi, fname in enumerate(case.robot.frame_names):
        T = case.out["Ts"][:, fi]
        R, p = T[:, :3, :3], T[:, :3, 3]
        wa, loc, wor = (case.out[f"{fname}/{ref}"] for ref in REFERENCES)
        Rt = np.swapaxes(R, 1, 2)
        np.testing.assert_allclose(loc[:, :3], Rt @ wa[:, :3], rtol=0, atol=tol)
        np.testing.assert_allclose(loc[:, 3:], Rt @ wa[:, 3:], rtol=0, atol=tol)
        np.testing.assert_allclose(
            wor[:, :3], wa[:, :3] + np.cross(p[:, :, None], wa[:, 3:], axis=1), rtol=0, atol=tol
        )
        np.testing.assert_allclose(wor[:, 3:], wa[:, 3:], rtol=0, atol=tol)


def test_default_set_is_what_the_issue_asks_for():
    assert {"erd/panda", "erd/ur3_robot", "erd/ur5_robot", "erd/ur10_robot"} <= set(DEFAULT)
    assert any("kinova" in k for k in DEFAULT) and any("iiwa" in k for k in DEFAULT)
    panda = oracle_case("erd/panda").robot
    assert panda.dof == 8 and "panda_finger_joint2" not in panda.joint_names  # mimic folded
    kinova = parse_urdf(case_path("erd/kinova"))
    assert any(j.type == "continuous" for j in kinova.joints)


# ----------------------------------------------------------------------------------- corpus
def _leaves(robot: jk.Robot) -> list[str]:
    parents = {robot.frame_names[p] for p in robot.parents}
    leaves = [f for f in robot.frame_names if f not in parents]
    return leaves[:: max(1, len(leaves) // 4)][:4]


@pytest.mark.skipif(not FULL_CORPUS, reason="set JAXKIN_FULL_CORPUS=1 for the whole corpus")
@pytest.mark.parametrize("name", CORPUS)
def test_corpus_robot_matches_pinocchio(name):
    t0 = time.perf_counter()
    path = case_path(name)
    robot = jk.load_urdf(path, dtype=np.float64)
    urdf = parse_urdf(path)
    model = _structure(robot, urdf, path)
    pmap = PinocchioMap(robot, urdf, model)
    qs = sample_configurations(robot, CORPUS_CONFIGS, 11)
    leaves = _leaves(robot)
    # Links below at least one moving joint (the others have an all-zero Jacobian).
    moving = [
        f
        for i, f in enumerate(robot.frame_names)
        if any(robot.kinds[j] != "fixed" for j in robot.ancestors(i))
    ]
    rigid = [f for f in robot.frame_names if f not in moving]
    chains = {f: jk.load_urdf(path, tip=f, dtype=np.float64) for f in moving}
    index = {n: i for i, n in enumerate(robot.joint_names)}
    cols = {f: np.array([index[n] for n in c.joint_names], dtype=int) for f, c in chains.items()}

    # Eager: for a handful of configurations of a big tree, compiling these long unrolled
    # kernels costs minutes; dispatching them op by op costs seconds.
    def one(q):
        out = {"Ts": jk.fk_all(robot, q)}
        for f in leaves:
            for ref in REFERENCES:
                out[f"tree/{f}/{ref}"] = jk.geometric_jacobian(robot, q, frame=f, reference=ref)
        for f, chain in chains.items():
            qc = q[cols[f]]
            for ref in REFERENCES:
                out[f"chain/{f}/{ref}"] = jk.geometric_jacobian(chain, qc, reference=ref)
        return out

    results = [one(q) for q in qs]
    out = {k: np.stack([np.asarray(r[k]) for r in results]) for k in results[0]}
    tol = tolerance(out["Ts"])
    for k, q in enumerate(qs):
        Ts, Js = pinocchio_frames_and_jacobians(pmap, q)
        np.testing.assert_allclose(out["Ts"][k], Ts, rtol=0, atol=tol, err_msg=f"{name} fk")
        for ref in REFERENCES:
            for fname in leaves:
                fi = robot.frame_names.index(fname)
                np.testing.assert_allclose(
                    out[f"tree/{fname}/{ref}"][k],
                    Js[ref][fi],
                    rtol=0,
                    atol=tol,
                    err_msg=f"{name} tree frame {fname} {ref}",
                )
            for fname in rigid:
                fi = robot.frame_names.index(fname)
                assert np.all(np.abs(Js[ref][fi]) <= tol), (name, fname)
            for fname in moving:
                fi = robot.frame_names.index(fname)
                expected = Js[ref][fi]
                got = np.zeros_like(expected)
                got[:, cols[fname]] = out[f"chain/{fname}/{ref}"][k]
                np.testing.assert_allclose(
                    got, expected, rtol=0, atol=tol, err_msg=f"{name} chain to {fname} {ref}"
                )
    print(f"{name}: dof {robot.dof}, {robot.n_frames} links, {time.perf_counter() - t0:.1f} s")


def test_float32_panda_within_float32_tolerance():
    """float32 loads and agrees with Pinocchio (float64) to tests/README.md's float32 bound
    ``4 * eps32 * (1 + max|q|) * reach * dof``."""
    path = case_path("erd/panda")
    robot = jk.load_urdf(path, dtype=np.float32)
    assert robot.dtype == np.float32
    urdf = parse_urdf(path)
    pmap = PinocchioMap(robot, urdf, pinocchio_model(path.read_text()))
    tip = robot.frame_names.index("panda_hand_tcp")
    qs = random_q(robot, 3, seed=5)

    def both(q):
        return jk.fk_all(robot, q), jk.geometric_jacobian(robot, q, frame="panda_hand_tcp")

    # one float32 program for the three configurations (not an eager kernel per function)
    Ts_all, J_all = jax.jit(jax.vmap(both), compiler_options=FAST_COMPILE)(qs.astype(np.float32))
    for q, Ts, J in zip(qs, np.asarray(Ts_all), np.asarray(J_all), strict=True):
        q32 = q.astype(np.float32)
        assert Ts.dtype == np.float32 and J.dtype == np.float32
        T_pin, J_pin = pinocchio_frames_and_jacobians(pmap, q32.astype(np.float64))
        reach = max(1.0, float(np.max(np.linalg.norm(T_pin[:, :3, 3], axis=-1))))
        tol = 4 * np.finfo(np.float32).eps * (1 + np.max(np.abs(q))) * reach * robot.dof
        np.testing.assert_allclose(Ts, T_pin, rtol=0, atol=tol)
        np.testing.assert_allclose(J, J_pin["world_aligned"][tip], rtol=0, atol=tol)
