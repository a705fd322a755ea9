"""Shared helpers of the URDF tests: example-robot-data paths, configuration sampling, the batched
jaxkin kernels (per robot: poses and point Jacobians, shared by the Pinocchio and MuJoCo tests;
every frame's Jacobian in every reference, compiled only where a test reads it), and the map
between jaxkin's q and Pinocchio's.

Pinocchio is always built here with ``mimic=False`` (every moving URDF joint independent, which
Pinocchio supports for every file) and jaxkin's mimic folding is checked against it through the
linear map ``S`` (``J_jaxkin = J_pin @ S``, ``q_pin = pin_q(q)``): a mimic joint's value is
``multiplier * q[leader] + offset`` and its column folds into the leader's with its multiplier.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import jax
import numpy as np
from _sampling import random_q, sample_configurations
from _xla import FAST_COMPILE

import jaxkin as jk
from jaxkin.robots import example_robot_data as erd
from jaxkin.urdf import URDFModel, parse_urdf

DATA = Path(__file__).parent / "data"
REFERENCES = ("world_aligned", "local", "world")
FULL_CORPUS = os.environ.get("JAXKIN_FULL_CORPUS") == "1"


def erd_root() -> Path | None:
    return erd.robots_dir()


def tolerance(Ts: np.ndarray) -> float:
    """1e-12 * max(1, reach), the reach being the farthest frame origin seen."""
    return 1e-12 * max(1.0, float(np.max(np.linalg.norm(Ts[..., :3, 3], axis=-1))))


# ----------------------------------------------------------------------------------- cases
N_CONFIGS = 25
SEED = 20240611


def case_path(key: str) -> Path:
    """``"erd/<name>"`` (example-robot-data registry name) or ``"data/<file>"`` (tests/data)."""
    if key.startswith("data/"):
        return DATA / key.removeprefix("data/")
    return erd.path(key)


def point_frames(robot: jk.Robot) -> list[str]:
    """Frames whose point Jacobian (at POINT) the shared kernel also computes: the last link in
    depth-first order, the frame before it and one in the middle (for MuJoCo's mj_jac)."""
    names = robot.frame_names
    return sorted({names[-1], names[-2], names[len(names) // 2]}, key=names.index)


POINT = np.array([0.03, -0.02, 0.05])  # m, in the frame's own axes


class Outputs(Mapping):
    """``Case.out``: ``"Ts"`` and ``"<frame>/point"`` from one compiled program, and
    ``"<frame>/<reference>"`` from a second one, compiled the first time such a key is read (the
    MuJoCo tests read no reference Jacobian: a process that runs only them does not compile the
    larger program)."""

    def __init__(self, base: dict[str, np.ndarray], frames: list[str], references) -> None:
        self._base = base
        self._frames = {f: i for i, f in enumerate(frames)}
        self._references = references  # () -> {reference: (N, n_frames, 6, nv)}, called once
        self._by_reference: dict[str, np.ndarray] | None = None

    def _keys(self) -> list[str]:
        refs = [f"{f}/{r}" for r in REFERENCES for f in self._frames]
        return list(self._base) + refs

    def __getitem__(self, key: str) -> np.ndarray:
        if key in self._base:
            return self._base[key]
        frame, _, ref = key.rpartition("/")
        if ref not in REFERENCES or frame not in self._frames:
            raise KeyError(key)
        if self._by_reference is None:
            self._by_reference = self._references()
        return self._by_reference[ref][:, self._frames[frame]]

    def __iter__(self):
        return iter(self._keys())

    def __len__(self) -> int:
        return len(self._keys())


@dataclass
class Case:
    key: str
    path: Path
    robot: jk.Robot
    urdf: URDFModel
    qs: np.ndarray
    out: Outputs


def _batched(fn, qs: np.ndarray) -> dict[str, np.ndarray]:
    """``fn`` at every row of ``qs`` as one compiled program (``lax.map``: one loop body)."""
    f = jax.jit(lambda qs: jax.lax.map(fn, qs), compiler_options=FAST_COMPILE)
    return jax.tree_util.tree_map(np.asarray, f(jax.device_put(qs)))


@functools.cache
def oracle_case(key: str, frames: str = "all") -> Case:
    """Load ``key`` in float64 and evaluate, at N_CONFIGS random configurations within the limits
    (``_sampling.random_q``, fixed seed):
    ``fk_all`` and the world_aligned point Jacobian at POINT of :func:`point_frames` (keys
    ``"Ts"`` and ``"<frame>/point"``, single-frame calls) in one program; in a second one,
    compiled on the first read of such a key, the geometric Jacobian of every frame in every
    reference (keys ``"<frame>/<reference>"``; ``frames="all"``, none otherwise): one multi-frame
    call per reference (``frame=[...]``, which test_multi_frame.py shows equal to stacked
    single-frame calls bit for bit). Two programs cost what one with both costs (XLA does not
    share the forward pass between the references). Cached: the Pinocchio and MuJoCo tests share
    the compiles per robot."""
    path = case_path(key)
    robot = jk.load_urdf(path, dtype=np.float64)
    urdf = parse_urdf(path)
    qs = random_q(robot, N_CONFIGS, SEED)  # numpy: no sampler compiled per robot
    names = list(robot.frame_names) if frames == "all" else []

    def base(q):
        out = {"Ts": jk.fk_all(robot, q)}
        for f in point_frames(robot):  # single-frame calls
            out[f"{f}/point"] = jk.geometric_jacobian(robot, q, frame=f, point=POINT)
        return out

    def every_frame(q):  # every frame in one multi-frame pass per reference
        return {r: jk.geometric_jacobian(robot, q, frame=names, reference=r) for r in REFERENCES}

    references = functools.partial(_batched, every_frame, qs)
    return Case(key, path, robot, urdf, qs, Outputs(_batched(base, qs), names, references))


class PinocchioMap:
    """jaxkin q <-> Pinocchio (``mimic=False``) q and v, and link frames, matched by name."""

    def __init__(self, robot: jk.Robot, urdf: URDFModel, model) -> None:
        import pinocchio as pin

        self.model = model
        by_name = urdf.joint_map
        dof_index = {n: i for i, n in enumerate(robot.joint_names)}
        self.nq, self.nv = model.nq, model.nv
        self.S = np.zeros((model.nv, robot.dof))
        self._terms = []  # (idx_q, nq, dof index or -1, multiplier, offset)
        for jid in range(1, model.njoints):
            name = model.names[jid]
            joint = model.joints[jid]
            leader, m, o = name, 1.0, 0.0
            j = by_name[name]
            while j.mimic is not None:  # resolve the mimic chain, as jaxkin does
                m, o = m * j.mimic.multiplier, m * j.mimic.offset + o
                j = by_name[j.mimic.joint]
                leader = j.name
            i = dof_index.get(leader, -1)
            if i >= 0:
                self.S[joint.idx_v, i] = m
            self._terms.append((joint.idx_q, joint.nq, i, m, o))
        self.frame_ids = []
        for fname in robot.frame_names:
            assert model.existFrame(fname, pin.BODY), fname
            self.frame_ids.append(model.getFrameId(fname, pin.BODY))

    def q(self, q: np.ndarray) -> np.ndarray:
        out = np.zeros(self.nq)
        for idx_q, nq, i, m, o in self._terms:
            value = m * q[i] + o if i >= 0 else 0.0
            if nq == 1:
                out[idx_q] = value
            else:  # continuous joint: (cos, sin)
                out[idx_q : idx_q + 2] = math.cos(value), math.sin(value)
        return out


def pinocchio_frames_and_jacobians(pmap: PinocchioMap, q: np.ndarray, with_jacobians=True):
    """Pinocchio's T_world_frame of every jaxkin frame and its Jacobians (mapped to jaxkin's q),
    {ref: (n_frames, 6, dof)}."""
    import pinocchio as pin

    model = pmap.model
    data = model.createData()
    qp = pmap.q(q)
    pin.framesForwardKinematics(model, data, qp)
    Ts = np.stack([data.oMf[fid].homogeneous for fid in pmap.frame_ids])
    if not with_jacobians:
        return Ts, None
    pin.computeJointJacobians(model, data, qp)
    pin.updateFramePlacements(model, data)
    rfs = {"world_aligned": pin.LOCAL_WORLD_ALIGNED, "local": pin.LOCAL, "world": pin.WORLD}
    Js = {
        ref: np.stack(
            [pin.getFrameJacobian(model, data, fid, rf) @ pmap.S for fid in pmap.frame_ids]
        )
        for ref, rf in rfs.items()
    }
    return Ts, Js


def pinocchio_model(source: Path | str, mimic: bool = False):
    import pinocchio as pin

    xml = Path(source).read_text() if isinstance(source, Path) else source
    return pin.buildModelFromXML(xml, mimic=mimic)


__all__ = [
    "DATA",
    "FULL_CORPUS",
    "POINT",
    "REFERENCES",
    "Case",
    "Outputs",
    "PinocchioMap",
    "case_path",
    "erd_root",
    "oracle_case",
    "parse_urdf",
    "pinocchio_frames_and_jacobians",
    "pinocchio_model",
    "point_frames",
    "sample_configurations",
    "tolerance",
]
