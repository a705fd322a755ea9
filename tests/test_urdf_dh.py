"""The zoo's DH models against the URDFs of the same robots (example-robot-data), wherever their
frames coincide.

Panda (zoo ``"panda"``, modified DH, Franka's table; ``"erd/panda"``, franka_description): every DH
frame is a URDF link frame (of the whole file, fingers included: ``jk.load_urdf``), the fixed
transform between them being the identity:
``base = panda_link0``, ``link1..link6 = panda_link1..panda_link6``, ``link7 = panda_link8`` (the
zoo folds the 0.107 m flange into row 7; ``panda_link7`` is 0.107 m behind it) and
``tool = panda_hand_tcp`` (``Tz(0.1034) Rz(-pi/4)`` after the flange). Same q, same limits.
Agreement: 1e-12 * max(1, reach).

UR5 (zoo ``"ur5"``, standard DH, Universal Robots' table; ``"erd/ur5_robot"``, the ROS-Industrial
ur_description): the DH base frame is the URDF link ``base`` (``T_world_base = Rz(pi)`` from the
URDF root ``world``/``base_link``) and the DH flange frame ``link6`` is the URDF link ``tool0``
(identity between them); the intermediate DH frames are not URDF links, but every DH joint axis
``z_{i-1}`` is the URDF joint's axis line. Same q. The URDF writes pi/2 as ``1.57079632679``
(4.9e-12 rad short), so agreement is bounded by that rounding times the reach (about 1e-11 m);
asserted to 1e-10.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _urdf_support import erd_root
from _xla import FAST_COMPILE

import jaxkin as jk
from jaxkin.robots import example_robot_data as erd

if erd_root() is None:
    pytest.skip("example-robot-data is not installed (test extra)", allow_module_level=True)

N = 5
PI_ROUNDING_TOL = 1e-10  # see the module doc (UR5 URDF's 12-digit pi/2)


def _configs(robot, n, seed):
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    lo, hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)
    return lo + (hi - lo) * np.random.default_rng(seed).random((n, robot.dof))


def whole(name):
    """The whole file (fingers, ``base``, ``tool0`` and every other link), not the zoo's chain
    to the tool frame."""
    return jk.load_urdf(erd.path(name), dtype=np.float64)


def _rel(T_base, T):
    return np.linalg.inv(T_base) @ T


REFS = ("world_aligned", "local", "world")


@functools.cache
def _program(robot: jk.Robot, frames: tuple[str, ...]):
    """One compiled program per robot (cached; the same batch shape reuses it): at each row of
    ``qs``, ``fk_all``, ``fk`` of ``frames`` (k, 4, 4) and their Jacobians {reference: (k, 6,
    dof)} (one multi-frame call per reference, equal to single-frame calls bit for bit:
    test_multi_frame.py)."""

    def one(q):
        Js = {
            ref: jk.geometric_jacobian(robot, q, frame=list(frames), reference=ref) for ref in REFS
        }
        return jk.fk_all(robot, q), jk.fk(robot, q, frame=list(frames)), Js

    run = jax.jit(jax.vmap(one), compiler_options=FAST_COMPILE)
    return lambda qs: jax.tree_util.tree_map(np.asarray, run(jnp.asarray(qs)))


PANDA_PAIRS = [
    ("base", "panda_link0"),
    *[(f"link{i}", f"panda_link{i}") for i in range(1, 7)],
    ("link7", "panda_link8"),
    ("tool", "panda_hand_tcp"),
]


def test_panda_dh_frames_are_urdf_links():
    dh = jk.robots.load("panda", dtype=np.float64)
    urdf = whole("erd/panda")
    assert urdf.joint_names[:7] == tuple(f"panda_joint{i}" for i in range(1, 8))
    np.testing.assert_array_equal(np.asarray(dh.lower), np.asarray(urdf.lower)[:7])
    np.testing.assert_array_equal(np.asarray(dh.upper), np.asarray(urdf.upper)[:7])
    qs = _configs(dh, N, 5)
    qus = np.concatenate([qs, np.full((N, 1), 0.02)], axis=1)  # fingers half open: no DH frame
    jac_pairs = PANDA_PAIRS[4:]  # the Jacobians of the coinciding frames from link4 on
    Ts_D, T_D, J_D = _program(dh, (*(a for a, _ in jac_pairs), "link7"))(qs)
    Ts_U, T_U, J_U = _program(urdf, (*(b for _, b in jac_pairs), "panda_link7"))(qus)
    for k in range(N):
        Ts_d, Ts_u = Ts_D[k], Ts_U[k]
        tol = 1e-12 * max(1.0, float(np.max(np.linalg.norm(Ts_d[:, :3, 3], axis=-1))))
        for a, b in PANDA_PAIRS:
            Td = Ts_d[dh.frame_names.index(a)]
            Tu = Ts_u[urdf.frame_names.index(b)]
            np.testing.assert_allclose(Td, Tu, rtol=0, atol=tol, err_msg=f"{a} vs {b}")
        for i, (a, _) in enumerate(jac_pairs):
            for ref in REFS:
                Jd, Ju = J_D[ref][k, i], J_U[ref][k, i]
                np.testing.assert_allclose(Jd, Ju[:, :7], rtol=0, atol=tol, err_msg=f"{a} {ref}")
                assert np.all(Ju[:, 7] == 0.0)  # the finger is on no DH frame's path
        # panda_link7 sits 0.107 m behind the zoo's link7 (the flange) along its z axis.
        T7 = T_U[k, -1]
        flange = np.eye(4)
        flange[2, 3] = 0.107
        np.testing.assert_allclose(T7 @ flange, T_D[k, -1], rtol=0, atol=1e-12)


def test_ur5_dh_base_and_flange_are_urdf_base_and_tool0():
    dh = jk.robots.load("ur5", dtype=np.float64)
    urdf = whole("erd/ur5_robot")
    assert urdf.joint_names == (
        "shoulder_pan_joint",
        "shoulder_lift_joint",
        "elbow_joint",
        "wrist_1_joint",
        "wrist_2_joint",
        "wrist_3_joint",
    )
    Rz_pi = np.diag([-1.0, -1.0, 1.0, 1.0])
    qs = _configs(dh, N, 6)
    _, T_D, J_D = _program(dh, ("link6",))(qs)
    _, T_U, J_U = _program(urdf, ("base", "tool0"))(qs)
    for k in range(N):
        T_base = T_U[k, 0]
        # Fixed, q-independent (the URDF's pi is 3.14159265359: 2e-12 short).
        np.testing.assert_allclose(T_base, Rz_pi, rtol=0, atol=PI_ROUNDING_TOL)
        Td = T_D[k, 0]
        Tu = _rel(T_base, T_U[k, 1])
        np.testing.assert_allclose(Td, Tu, rtol=0, atol=PI_ROUNDING_TOL)
        # Jacobians of the flange: "local" is frame-intrinsic; "world_aligned" re-expressed in
        # the DH base axes (R = Rz(pi)).
        Jd, Ju = J_D["local"][k, 0], J_U["local"][k, 1]
        np.testing.assert_allclose(Jd, Ju, rtol=0, atol=PI_ROUNDING_TOL)
        Jd, Ju = J_D["world_aligned"][k, 0], J_U["world_aligned"][k, 1]
        R = Rz_pi[:3, :3]
        np.testing.assert_allclose(
            Jd, np.vstack([R.T @ Ju[:3], R.T @ Ju[3:]]), rtol=0, atol=PI_ROUNDING_TOL
        )


def test_ur5_dh_joint_axes_are_the_urdf_joint_axes():
    dh = jk.robots.load("ur5", dtype=np.float64)
    urdf = whole("erd/ur5_robot")
    moving = [j for j, k in enumerate(urdf.kinds) if k != "fixed"]
    # N configurations: the batch shape of the flange test, whose programs serve this one
    Ts_DH, _, _ = _program(dh, ("link6",))(_configs(dh, N, 7))
    Ts_URDF, _, _ = _program(urdf, ("base", "tool0"))(_configs(dh, N, 7))
    for Ts_dh, Ts_u in zip(Ts_DH, Ts_URDF, strict=True):  # Ts_dh: base, link1..link6
        T_base = Ts_u[urdf.frame_names.index("base")]
        axis = np.asarray(urdf.axis)
        for i, j in enumerate(moving):
            # DH: joint i + 1 turns about z of frame i, through its origin.
            z_dh, o_dh = Ts_dh[i][:3, 2], Ts_dh[i][:3, 3]
            Tj = _rel(T_base, Ts_u[j + 1])  # the joint's child link = its joint frame
            z_u, o_u = Tj[:3, :3] @ axis[j], Tj[:3, 3]
            np.testing.assert_allclose(z_u, z_dh, rtol=0, atol=PI_ROUNDING_TOL, err_msg=str(i))
            off = o_u - o_dh
            np.testing.assert_allclose(
                off - (off @ z_dh) * z_dh, 0.0, rtol=0, atol=PI_ROUNDING_TOL, err_msg=str(i)
            )
