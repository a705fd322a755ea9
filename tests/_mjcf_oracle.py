"""MuJoCo as the oracle of jk.load_mjcf: every body and site pose of ``mj_kinematics`` and every
point Jacobian of ``mj_jac``/``mj_jacSite`` against jaxkin's, at given configurations.

jaxkin's ``q`` is MuJoCo's ``qpos`` of the loaded hinge and slide joints without the coupled
(equality) joints; the coupled joints' ``qpos`` follow ``y = y0 + a0 + a1 (x - x0)`` and their
``mj_jac`` columns fold into the leader's with factor ``a1``: this module writes that mapping
itself from the compiled model (it shares no code with jaxkin.mjcf)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from _xla import FAST_COMPILE

import jaxkin as jk

POINT = np.array([0.05, -0.02, 0.1])  # in the frame's axes: a point off the origin


def couplings(m) -> dict[int, tuple[int, float, float]]:
    """Active linear joint equalities: follower joint id -> (leader joint id, a0, a1)."""
    out = {}
    for e in range(m.neq):
        if m.eq_active0[e] and m.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT:
            out[int(m.eq_obj1id[e])] = (int(m.eq_obj2id[e]), *map(float, m.eq_data[e][:2]))
    return out


def qpos_of(m, robot: jk.Robot, q: np.ndarray) -> np.ndarray:
    name = {j: mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)}
    qpos = m.qpos0.copy()
    for i, n in enumerate(robot.joint_names):
        qpos[m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]] = q[i]
    for y, (x, a0, a1) in couplings(m).items():
        if name[y] not in robot.joint_names:
            y0, x0 = m.qpos0[m.jnt_qposadr[y]], m.qpos0[m.jnt_qposadr[x]]
            qpos[m.jnt_qposadr[y]] = y0 + a0 + a1 * (qpos[m.jnt_qposadr[x]] - x0)
    return qpos


def column_map(m, robot: jk.Robot) -> np.ndarray:
    """(nv, dof) matrix C with J_jaxkin = J_mujoco @ C."""
    C = np.zeros((m.nv, robot.dof))
    for i, n in enumerate(robot.joint_names):
        C[m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)], i] = 1.0
    for y, (x, _, a1) in couplings(m).items():
        C[m.jnt_dofadr[y]] += a1 * C[m.jnt_dofadr[x]]
    return C


def sample(robot: jk.Robot, n: int, seed: int) -> np.ndarray:
    lo, hi = np.asarray(robot.lower, float), np.asarray(robot.upper, float)
    lo, hi = np.where(np.isfinite(lo), lo, -np.pi), np.where(np.isfinite(hi), hi, np.pi)
    return np.random.default_rng(seed).uniform(lo, hi, (n, robot.dof))


def jacobian_frames(robot: jk.Robot, known, k: int = 3) -> list[str]:
    """Up to ``k`` frames (of ``known``) for the Jacobian checks: the ends of the branches first
    (the default frame or the candidates), then the frame half-way down."""
    ends = list(robot.default_frames) or [robot.frame_names[robot.tip_frame]]
    middle = [n for n in robot.frame_names[len(robot.frame_names) // 2 :] if n in known][:1]
    return [n for n in dict.fromkeys([*ends[: k - 1], *middle]) if n in known][:k]


def check(m, robot: jk.Robot, qs: np.ndarray, *, jac_frames=None, tol: float = 1e-12) -> int:
    """Assert every body's and site's pose at each row of ``qs`` (``fk_all`` against
    ``xpos``/``xmat``/``site_xpos``/``site_xmat``), and the point Jacobian of ``jac_frames``
    (default :func:`jacobian_frames`) at ``POINT`` in each frame's axes against ``mj_jac`` at that
    world point (a site's through its body); returns the number of frames compared."""
    d = mujoco.MjData(m)
    frames = []
    for kind, count, obj in (("body", m.nbody, mujoco.mjtObj.mjOBJ_BODY),
                             ("site", m.nsite, mujoco.mjtObj.mjOBJ_SITE)):  # fmt: skip
        for i in range(1 if kind == "body" else 0, count):
            n = mujoco.mj_id2name(m, obj, i)
            if n in robot.frame_names:
                frames.append((kind, i, n))
    idx = np.array([robot.frame_names.index(n) for _, _, n in frames])
    C = column_map(m, robot)
    by_name = {n: (kind, i) for kind, i, n in frames}
    jac_frames = jacobian_frames(robot, by_name) if jac_frames is None else jac_frames
    jac_frames = [f for f in jac_frames if f in by_name] if robot.dof else []
    moved = 0.0

    # One program per robot, called per row: fk_all and one multi-frame Jacobian call (equal
    # to single-frame calls stacked, bit for bit: test_multi_frame.py), compiled with the
    # tests' options (the eager calls compiled one program per frame, with XLA's full passes).
    def poses_and_jacobians(q):
        Js = jk.geometric_jacobian(robot, q, frame=jac_frames, point=POINT) if jac_frames else ()
        return jk.fk_all(robot, q), Js

    kernel = jax.jit(poses_and_jacobians, compiler_options=FAST_COMPILE)
    rows = [jax.tree_util.tree_map(np.asarray, kernel(jnp.asarray(q))) for q in qs]
    Ts_all = np.stack([Ts for Ts, _ in rows]).astype(np.float64)
    Js = {f: np.stack([J[i] for _, J in rows]).astype(np.float64) for i, f in enumerate(jac_frames)}
    root = robot.frame_names[0]  # "world", or the base body: poses and axes relative to it
    base = None if root == "world" else mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, root)
    for row, q in enumerate(qs):
        d.qpos[:] = qpos_of(m, robot, np.asarray(q, dtype=np.float64))
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        R0, p0 = np.eye(3), np.zeros(3)
        if base is not None:
            R0, p0 = d.xmat[base].reshape(3, 3).copy(), d.xpos[base].copy()
        Ts = Ts_all[row][idx]
        reach = max(1.0, float(np.abs(Ts[:, :3, 3]).max()))
        for k, (kind, i, n) in enumerate(frames):
            p = R0.T @ ((d.xpos[i] if kind == "body" else d.site_xpos[i]) - p0)
            R = R0.T @ (d.xmat[i] if kind == "body" else d.site_xmat[i]).reshape(3, 3)
            np.testing.assert_allclose(Ts[k, :3, 3], p, rtol=0, atol=tol * reach, err_msg=n)
            np.testing.assert_allclose(Ts[k, :3, :3], R, rtol=0, atol=tol, err_msg=n)
        for f, J in Js.items():
            kind, i = by_name[f]
            T = Ts_all[row][robot.frame_names.index(f)]
            body = i if kind == "body" else int(m.site_bodyid[i])
            jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
            mujoco.mj_jac(m, d, jp, jr, p0 + R0 @ (T[:3, 3] + T[:3, :3] @ POINT), body)
            want = np.vstack([R0.T @ jp, R0.T @ jr]) @ C
            np.testing.assert_allclose(J[row], want, rtol=0, atol=tol * reach, err_msg=f)
            moved = max(moved, float(np.abs(want).max()))
    assert moved > 0 or not jac_frames  # non-trivial Jacobians were compared
    return len(frames)
