"""Robots and peer adapters for the benchmark: the same URDF for jaxkin and every peer.

Robots (:func:`robot_sources`): example-robot-data's Panda (``erd/panda``: ``panda.urdf``, tip
``panda_hand_tcp``, fingers removed) and UR5 (``erd/ur5_robot``: ``ur5_robot.urdf``, tip
``tool0``), found by ``jaxkin.robots.example_robot_data``, and a serial chain of
:data:`CHAIN_JOINTS` revolute joints built with ``jk.Robot.from_joints`` (:func:`chain_robot`)
and written as URDF by ``jk.to_urdf``; and two free-flyer humanoids (:data:`HUMANOIDS`), each
with its :class:`Case` rows: Talos (``erd/talos_reduced``) one hand (:data:`TALOS_HAND`) in
``world_aligned`` and in ``local``, and the G1 (``erd/g1_29dof_rev_1_0``) with both feet and
both hands in one multi-frame call (the frames of ``bench.wholebody``). Visual, collision,
transmission and gazebo elements are stripped (kinematics only; no mesh is ever opened);
everything else is the file as shipped.

jaxkin builds each robot from that URDF text with ``jk.load_urdf(text, tip=...)``, a humanoid
with ``jk.load_urdf(text, floating_base=True)``. :class:`PinocchioLayout` maps jaxkin's
``(q, v)`` to a Pinocchio model's (quaternion order, column order): the one place the bench
writes it.

Peers, each verified numerically against jaxkin before it is timed (same frame, same quantity):

* :class:`Pinocchio`: ``pin.buildModelFromXML`` (joints not in jaxkin's ``q`` locked), one Python
  call per configuration: ``computeFrameJacobian(..., LOCAL_WORLD_ALIGNED)`` (results dropped,
  or each stored into a preallocated array: :meth:`Pinocchio.stored_loop`); analytical: that,
  ``rpy.matrixToRpy`` and ``rpy.computeRpyJacobianInverse``; twist: ``forwardKinematics(q, v)``
  and ``getFrameVelocity(..., LOCAL_WORLD_ALIGNED)``.
* :class:`PinocchioFrames` (humanoids): ``pin.buildModelFromXML(urdf, JointModelFreeFlyer())``,
  pre-built q arrays in Pinocchio's layout; one frame: ``computeFrameJacobian`` per
  configuration; several: ``computeJointJacobians`` + ``updateFramePlacements`` + one
  ``getFrameJacobian`` per frame; results stored into a preallocated array or dropped.
  pytorch_kinematics has no free-flyer joint: :func:`torch_free_flyer_check` checks the part it
  computes and says why it is not timed.
* :class:`TorchKinematics`: ``pytorch_kinematics.build_serial_chain_from_urdf`` and
  ``chain.jacobian(th)``, batched, float32 and float64 CPU tensors.
* :class:`MujocoLoop`: the URDF with :data:`MUJOCO_COMPILER` inserted (as in
  tests/test_urdf_mujoco.py, plus lower bounds on mass and inertia for links without an
  ``<inertial>``, e.g. the generated chain's); per configuration ``mj_kinematics``,
  ``mj_comPos``, ``mj_jac`` at the tip body's origin.
* :class:`MujocoBatch`: ``mujoco.batch.Batch`` (MuJoCo >= 4, its own thread pool): either
  ``forward(mjSTAGE_POS)`` then ``jac(body, xpos)`` (world-aligned at the body origin, as
  the others; the API takes world points, so the kinematics runs twice), or ``jac(body, 0)``
  alone: the Jacobian of the body point at the world origin, which is jaxkin's
  ``reference="world"`` (Pinocchio WORLD), checked against that.
* :class:`RoboticsToolbox`: ``rtb.Robot.URDF(file).ets(end=tip)`` and ``ets.jacob0(q)`` per
  configuration, only when every moving axis of the chain is exactly axis-aligned (its URDF
  import gets other axes, such as ``0 1 6.12e-17``, wrong).
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import os
import tempfile
import time
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import jaxkin as jk
from jaxkin.robots import example_robot_data

from .report import version

CHAIN_JOINTS = 32

# ---------------------------------------------------------------------------- URDF sources


def strip_urdf(text: str) -> str:
    """The URDF without ``<visual>``, ``<collision>``, ``<transmission>`` and ``<gazebo>``
    elements (meshes are never needed for kinematics, and some peers try to open them)."""
    root = ET.fromstring(text)
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for e in link.findall(tag):
                link.remove(e)
    for tag in ("transmission", "gazebo"):
        for e in root.findall(tag):
            root.remove(e)
    return ET.tostring(root, encoding="unicode")


def erd_urdf(name: str) -> str:
    """The stripped URDF text of the example-robot-data robot ``name`` (``"erd/..."``)."""
    return strip_urdf(example_robot_data.path(name).read_text())


def chain_robot(n: int = CHAIN_JOINTS) -> jk.Robot:
    """A float64 serial chain of ``n`` revolute joints ``joint1 ... joint<n>`` (frames ``base``,
    ``link1 ... link<n>``): axes cycling z, y, x (exactly axis-aligned, so every peer can load
    it), link offsets of 6 - 9 cm with small lateral parts, a twist (``rpy``) on every other
    joint, limits +-pi, and a fixed tool frame ``tip`` 5 cm past the last joint."""
    axes = ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))
    joints: list[dict[str, Any]] = []
    for i in range(n):
        joints.append(
            dict(
                name=f"joint{i + 1}",
                type="revolute",
                parent=f"link{i}" if i else "base",
                child=f"link{i + 1}",
                xyz=(0.01 * ((i % 3) - 1), 0.005 * (1 if i % 2 else -1), 0.06 + 0.01 * (i % 4)),
                rpy=(0.1 * (i % 3), 0.0, 0.25) if i % 2 else (0.0, 0.0, 0.0),
                axis=axes[i % 3],
                lower=-math.pi,
                upper=math.pi,
            )
        )
    joints.append(dict(name="tip_joint", type="fixed", child="tip", xyz=(0.0, 0.0, 0.05)))
    return jk.Robot.from_joints(joints, root="base", name=f"chain{n}", dtype=np.float64)


@dataclass(frozen=True)
class Case:
    """One free-flyer row: the Jacobians of ``frames`` (one name: a (6, nv) Jacobian; several:
    one ``jk.geometric_jacobian(robot, q, frame=[...])`` call) in ``reference``."""

    quantity: str  # the row's name in the tables
    frames: tuple[str, ...]
    reference: str  # jaxkin's reference ("world_aligned" or "local")
    several: bool  # the frame argument is a list (multi-frame API), even for one name


@dataclass
class RobotSource:
    name: str
    urdf: str  # stripped URDF text, shared by jaxkin and every peer
    tip: str
    origin: str  # where the URDF comes from
    floating_base: bool = False  # a free-flyer root joint (jaxkin ``floating_base=True``)
    cases: tuple[Case, ...] = ()  # the rows of a free-flyer robot (:data:`HUMANOIDS`)


TALOS_HAND = "gripper_left_base_link"
"""Talos's left hand: the gripper's base, fixed to ``arm_left_7_link`` (root, 2 torso joints and
7 arm joints on its path: 15 of the 38 columns)."""


G1_HAND = "left_rubber_hand"
"""G1's left hand, one of its four frames alone: the issue's bar puts the four in one call
within 1.5x of one frame's cost."""


def _g1_frames() -> tuple[str, ...]:
    from .wholebody_ik import ROBOTS

    return tuple(ROBOTS["g1"][1])  # both ankles (feet) and both hands, as bench.wholebody


def _humanoid(name: str, path: str, cases: tuple[Case, ...], what: str) -> RobotSource:
    return RobotSource(
        name,
        erd_urdf(path),
        cases[0].frames[0],
        f"example-robot-data {example_robot_data.path(path).name} ({what}; free-flyer root)",
        floating_base=True,
        cases=cases,
    )


HUMANOIDS = {
    "talos": lambda: _humanoid(
        "talos",
        "erd/talos_reduced",
        (
            Case("hand, world-aligned", (TALOS_HAND,), "world_aligned", False),
            Case("hand, local", (TALOS_HAND,), "local", False),
        ),
        f"one hand: {TALOS_HAND}",
    ),
    "g1": lambda: _humanoid(
        "g1",
        "erd/g1_29dof_rev_1_0",
        (
            Case("feet + hands, world-aligned", _g1_frames(), "world_aligned", True),
            Case("left hand, world-aligned", (G1_HAND,), "world_aligned", False),
        ),
        "both feet and both hands: " + ", ".join(_g1_frames()),
    ),
}
"""Free-flyer humanoids (:func:`robot_sources` names ``talos``, ``g1``): the G1 and its frames
are those of ``bench.wholebody`` and ``bench.wholebody_ik``."""


def robot_sources(names: list[str] | None = None) -> list[RobotSource]:
    """Panda, UR5, the generated chain, Talos and G1 (or the named subset, in that order)."""
    makers = {
        "panda": lambda: RobotSource(
            "panda",
            erd_urdf("erd/panda"),
            "panda_hand_tcp",
            "example-robot-data panda.urdf (fingers removed: chain to panda_hand_tcp)",
        ),
        "ur5": lambda: RobotSource(
            "ur5",
            erd_urdf("erd/ur5_robot"),
            "tool0",
            "example-robot-data ur5_robot.urdf (chain world -> tool0)",
        ),
        f"chain{CHAIN_JOINTS}": lambda: RobotSource(
            f"chain{CHAIN_JOINTS}",
            jk.to_urdf(chain_robot(CHAIN_JOINTS)),
            "tip",
            f"generated URDF string: {CHAIN_JOINTS} revolute joints, axes z/y/x, tool 'tip'",
        ),
        **HUMANOIDS,
    }
    chosen = list(makers) if not names else names
    unknown = [n for n in chosen if n not in makers]
    if unknown:
        raise SystemExit(f"unknown robot(s) {unknown}; choose from {list(makers)}")
    return [makers[n]() for n in chosen]


def axis_aligned(robot: jk.Robot) -> bool:
    """True when every moving joint of ``robot`` has an exactly axis-aligned axis."""
    axes = np.abs(np.asarray(robot.axis, dtype=np.float64))
    moving = [a for a, kind in zip(axes, robot.kinds, strict=True) if kind != "fixed"]
    return all(sorted(a.tolist()) == [0.0, 0.0, 1.0] for a in moving)


def jaxkin_robot(src: RobotSource, dtype) -> tuple[jk.Robot, str]:
    """The jaxkin robot for ``src`` and how it was built."""
    if src.floating_base:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # e.g. G1's and Talos's zero-mass links
            robot = jk.load_urdf(src.urdf, floating_base=True, dtype=dtype, name=src.name)
        return robot, f"jk.load_urdf(<{src.name} URDF>, floating_base=True)"
    robot = jk.load_urdf(src.urdf, tip=src.tip, dtype=dtype, name=src.name)
    return robot, f"jk.load_urdf(<{src.name} URDF>, tip={src.tip!r})"


PINOCCHIO_COORDINATES = {
    "JointModelFreeFlyer": (
        ("x", "y", "z", "qx", "qy", "qz", "qw"),
        ("vx", "vy", "vz", "wx", "wy", "wz"),
    ),
    "JointModelSpherical": (("qx", "qy", "qz", "qw"), ("wx", "wy", "wz")),
    "JointModelPlanar": (("x", "y", "cos", "sin"), ("vx", "vy", "wz")),
}
"""Per Pinocchio multi-DOF joint kind, the jaxkin suffixes (``<joint>.<suffix>``) of its q and v
entries in Pinocchio's order."""


class PinocchioLayout:
    """jaxkin's ``(q, v)`` against Pinocchio's ``(nq, nv)`` layout, for a Pinocchio model whose
    joints carry jaxkin's joint names (a free-flyer root added by Pinocchio is ``root_joint``,
    as jaxkin's ``floating_base=True`` names it).

    ``q_src[i]`` is the jaxkin ``q`` index of Pinocchio's ``q[i]``, ``v_src[i]`` the jaxkin ``v``
    index of Pinocchio's ``v[i]`` (= Jacobian column i). Joint kinds: 1-DOF joints; free flyers
    (jaxkin ``<j>.x, .y, .z, .qw, .qx, .qy, .qz`` and ``<j>.vx ... .wz``; Pinocchio's quaternion
    is ``(x, y, z, w)``); spherical (``<j>.qx ... .qw``, ``<j>.wx ... .wz``); planar (``<j>.x, .y,
    .cos, .sin``, ``<j>.vx, .vy, .wz``). Both models use child-frame axes for a free flyer's
    velocity, so columns map one to one. Raises ``RuntimeError`` for another kind or a name
    jaxkin does not have.
    """

    def __init__(self, robot: jk.Robot, model) -> None:
        qi = {n: i for i, n in enumerate(robot.joint_names)}
        vi = {n: i for i, n in enumerate(robot.velocity_names)}
        self.q_src = np.zeros(model.nq, dtype=int)
        self.v_src = np.zeros(model.nv, dtype=int)
        try:
            for jid in range(1, model.njoints):
                name, joint = model.names[jid], model.joints[jid]
                if joint.nq == 1:
                    self.q_src[joint.idx_q], self.v_src[joint.idx_v] = qi[name], vi[name]
                    continue
                kind = joint.shortname()
                if kind not in PINOCCHIO_COORDINATES:
                    raise RuntimeError(
                        f"joint {name!r} is a Pinocchio {kind}: only 1-DOF, free-flyer, spherical "
                        "and planar joints are mapped"
                    )
                qn, vn = PINOCCHIO_COORDINATES[kind]
                for k, c in enumerate(qn):
                    self.q_src[joint.idx_q + k] = qi[f"{name}.{c}"]
                for k, c in enumerate(vn):
                    self.v_src[joint.idx_v + k] = vi[f"{name}.{c}"]
        except KeyError as e:
            raise RuntimeError(f"Pinocchio's model has {e} that jaxkin's robot lacks") from None
        if sorted(self.q_src) != list(range(robot.nq)) or sorted(self.v_src) != list(
            range(robot.nv)
        ):
            raise RuntimeError(
                f"Pinocchio's nq={model.nq}, nv={model.nv} do not cover jaxkin's nq={robot.nq}, "
                f"nv={robot.nv} one to one"
            )

    def q(self, q: np.ndarray) -> np.ndarray:
        """jaxkin configurations (..., nq) in Pinocchio's order (a copy)."""
        return np.ascontiguousarray(np.asarray(q)[..., self.q_src])

    def v(self, v: np.ndarray) -> np.ndarray:
        """jaxkin velocities (..., nv) in Pinocchio's order (a copy)."""
        return np.ascontiguousarray(np.asarray(v)[..., self.v_src])

    def columns_to_pinocchio(self, J: np.ndarray) -> np.ndarray:
        """jaxkin Jacobians (..., nv) with their columns in Pinocchio's velocity order."""
        return np.asarray(J)[..., self.v_src]

    def columns_to_jaxkin(self, J: np.ndarray) -> np.ndarray:
        """Pinocchio Jacobians (..., nv) with their columns in jaxkin's velocity order."""
        J = np.asarray(J)
        out = np.empty_like(J)
        out[..., self.v_src] = J
        return out


# ---------------------------------------------------------------------------- peers


def _lwa():
    import pinocchio as pin

    return pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class Pinocchio:
    """Pinocchio from Python, one call per configuration (the reference of every ratio)."""

    label = "Pinocchio (Python loop)"

    def __init__(self, src: RobotSource, robot64: jk.Robot):
        import pinocchio as pin

        full = pin.buildModelFromXML(src.urdf)
        keep = set(robot64.joint_names)
        lock = [full.getJointId(n) for n in list(full.names)[1:] if n not in keep]
        model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
        if model.nq != robot64.dof or model.nv != robot64.dof:
            raise RuntimeError(
                f"Pinocchio's {src.name} has nq={model.nq}, nv={model.nv}; jaxkin's dof is "
                f"{robot64.dof} (continuous joints are (cos, sin) pairs in Pinocchio)."
            )
        if tuple(model.names[1:]) != tuple(robot64.joint_names):
            raise RuntimeError(
                f"joint order differs: Pinocchio {list(model.names[1:])}, jaxkin "
                f"{list(robot64.joint_names)}"
            )
        if not model.existFrame(src.tip):
            raise RuntimeError(f"Pinocchio's {src.name} has no frame {src.tip!r}")
        self.model, self.data = model, model.createData()
        self.fid = model.getFrameId(src.tip)
        self.locked = [full.names[i] for i in lock]
        self.version = pin.__version__
        self.how = f"pin.buildModelFromXML + computeFrameJacobian(LOCAL_WORLD_ALIGNED), {src.tip}"
        if self.locked:
            self.how += f"; locked {self.locked}"

    # one configuration (verification)
    def geometric(self, q):
        import pinocchio as pin

        return pin.computeFrameJacobian(self.model, self.data, q, self.fid, _lwa()).copy()

    def pose(self, q):
        import pinocchio as pin

        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.fid].homogeneous.copy()

    def analytical(self, q):
        import pinocchio as pin

        J = pin.computeFrameJacobian(self.model, self.data, q, self.fid, _lwa())
        rpy = pin.rpy.matrixToRpy(self.data.oMf[self.fid].rotation)
        J[3:] = pin.rpy.computeRpyJacobianInverse(rpy, pin.ReferenceFrame.WORLD) @ J[3:]
        return J.copy()

    def twist(self, q, qd):
        import pinocchio as pin

        pin.forwardKinematics(self.model, self.data, q, qd)
        return pin.getFrameVelocity(self.model, self.data, self.fid, _lwa()).vector.copy()

    # loops (timed)
    def loop(self, quantity: str):
        """A function ``f(qs, qds)`` that computes ``quantity`` for every row, one call each."""
        import pinocchio as pin

        model, data, fid, lwa = self.model, self.data, self.fid, _lwa()
        if quantity == "geometric":
            jac = pin.computeFrameJacobian

            def geometric(qs, qds):
                for q in qs:
                    jac(model, data, q, fid, lwa)

            return geometric
        if quantity == "analytical":
            jac, world = pin.computeFrameJacobian, pin.ReferenceFrame.WORLD
            to_rpy, rpy_jinv = pin.rpy.matrixToRpy, pin.rpy.computeRpyJacobianInverse
            oMf = data.oMf

            def analytical(qs, qds):
                for q in qs:
                    J = jac(model, data, q, fid, lwa)
                    J[3:] = rpy_jinv(to_rpy(oMf[fid].rotation), world) @ J[3:]

            return analytical
        fk, vel = pin.forwardKinematics, pin.getFrameVelocity

        def twist(qs, qds):
            for q, qd in zip(qs, qds, strict=True):
                fk(model, data, q, qd)
                vel(model, data, fid, lwa)

        return twist

    def stored_loop(self, n: int):
        """A function ``f(qs, qds)`` computing the geometric Jacobian of every row (at most
        ``n``), each stored into a preallocated (n, 6, nv) array, as a user collecting the N
        Jacobians writes it (``qds`` unused)."""
        import pinocchio as pin

        model, data, fid, lwa = self.model, self.data, self.fid, _lwa()
        jac, out = pin.computeFrameJacobian, np.empty((n, 6, model.nv))

        def stored(qs, qds):
            for i, q in enumerate(qs):
                out[i] = jac(model, data, q, fid, lwa)

        return stored


def pin_reference(name: str):
    """Pinocchio's ReferenceFrame for jaxkin's reference ``name``."""
    import pinocchio as pin

    rf = pin.ReferenceFrame
    return {"world_aligned": rf.LOCAL_WORLD_ALIGNED, "local": rf.LOCAL, "world": rf.WORLD}[name]


class PinocchioFrames:
    """Pinocchio from Python on the free-flyer model of ``src``
    (``pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer())``): the Jacobians of a
    :class:`Case`'s frames in its reference, written as a user who wants N Jacobians in an array
    writes it. Inputs are pre-built q arrays in Pinocchio's layout (:class:`PinocchioLayout`).

    One frame: ``computeFrameJacobian(model, data, q, frame, reference)`` per configuration.
    Several: ``computeJointJacobians`` + ``updateFramePlacements`` + one ``getFrameJacobian``
    per frame. :meth:`loop` times it with each result stored into a preallocated (N, [k,] 6, nv)
    array (``stored=True``) or dropped.
    """

    def __init__(self, src: RobotSource, robot64: jk.Robot, case: Case):
        import pinocchio as pin

        model = pin.buildModelFromXML(src.urdf, pin.JointModelFreeFlyer())
        self.layout = PinocchioLayout(robot64, model)
        missing = [f for f in case.frames if not model.existFrame(f)]
        if missing:
            raise RuntimeError(f"Pinocchio's {src.name} has no frame {missing}")
        self.model, self.data, self.case = model, model.createData(), case
        self.ids = [model.getFrameId(f) for f in case.frames]
        self.rf = pin_reference(case.reference)
        self.version = pin.__version__
        rf = str(self.rf).rsplit(".", 1)[-1]
        self.how = (
            f"computeJointJacobians + updateFramePlacements + getFrameJacobian({rf}) per frame"
            if case.several
            else f"computeFrameJacobian({rf})"
        ) + " per configuration; pre-built q arrays in Pinocchio's layout"

    def prepare(self, q64: np.ndarray) -> list[np.ndarray]:
        """jaxkin configurations (n, nq) as a list of Pinocchio-layout q arrays (untimed)."""
        return list(self.layout.q(q64))

    def shape(self, n: int) -> tuple[int, ...]:
        """The shape of ``n`` configurations' Jacobians: (n, 6, nv) or (n, k, 6, nv)."""
        k = (len(self.ids),) if self.case.several else ()
        return (n, *k, 6, self.model.nv)

    def loop(self, stored: bool, n: int, out: np.ndarray | None = None):
        """A function ``f(qs)`` computing every Jacobian of at most ``n`` prepared
        configurations, each stored into ``out`` (preallocated here when not given) when
        ``stored``."""
        import pinocchio as pin

        model, data, ids, rf = self.model, self.data, self.ids, self.rf
        if out is None:
            out = np.empty(self.shape(n))
        if not self.case.several:
            jac, fid = pin.computeFrameJacobian, ids[0]

            def one_stored(qs):
                for i, q in enumerate(qs):
                    out[i] = jac(model, data, q, fid, rf)

            def one(qs):
                for q in qs:
                    jac(model, data, q, fid, rf)

            return one_stored if stored else one
        joints, place, get = (
            pin.computeJointJacobians,
            pin.updateFramePlacements,
            pin.getFrameJacobian,
        )

        def several_stored(qs):
            for i, q in enumerate(qs):
                joints(model, data, q)
                place(model, data)
                for k, fid in enumerate(ids):
                    out[i, k] = get(model, data, fid, rf)

        def several(qs):
            for q in qs:
                joints(model, data, q)
                place(model, data)
                for fid in ids:
                    get(model, data, fid, rf)

        return several_stored if stored else several

    def jacobians(self, q64: np.ndarray) -> np.ndarray:
        """float64 (n, 6, nv), or (n, k, 6, nv) for several frames, in jaxkin's column order."""
        qs = self.prepare(q64)
        out = np.empty(self.shape(len(qs)))
        self.loop(True, len(qs), out)(qs)
        return self.layout.columns_to_jaxkin(out)

    def poses(self, q64: np.ndarray) -> np.ndarray:
        """(n, k, 4, 4) world poses of the case's frames."""
        import pinocchio as pin

        out = []
        for q in self.prepare(q64):
            pin.framesForwardKinematics(self.model, self.data, q)
            out.append([self.data.oMf[f].homogeneous.copy() for f in self.ids])
        return np.array(out)


class Peer:
    """A Jacobian peer: ``prepare(q64)`` (untimed), ``run(prepared)`` (timed), and
    ``jacobians(q64)`` (float64 (n, 6, dof), for the numerical check)."""

    label = "?"
    dtype = "float64"
    batched = False
    reference = "world_aligned"  # the jaxkin reference it is checked against
    how = ""
    version = ""

    def prepare(self, q64: np.ndarray) -> Any:
        return [np.ascontiguousarray(q) for q in q64]

    def run(self, prepared: Any) -> None:
        raise NotImplementedError

    def jacobians(self, q64: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def bytes_per_config(self) -> float:
        return 0.0

    def tune(self, q64: np.ndarray) -> None:
        """Pick settings (e.g. threads) on a probe batch before timing; default: nothing."""

    def close(self) -> None:
        pass


@contextlib.contextmanager
def quiet():
    """Silence a library's Python-level chatter (pytorch_kinematics' URDF parser warns about
    every attribute it does not know)."""
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        yield


class TorchKinematics(Peer):
    batched = True

    def __init__(self, src: RobotSource, robot64: jk.Robot, dtype: str):
        import pytorch_kinematics as pk
        import torch

        self.torch = torch
        self.tdtype = {"float32": torch.float32, "float64": torch.float64}[dtype]
        self.dtype = dtype
        with quiet():
            chain = pk.build_serial_chain_from_urdf(src.urdf.encode(), src.tip)
        self.chain = chain.to(dtype=self.tdtype)
        names = tuple(self.chain.get_joint_parameter_names())
        if names != tuple(robot64.joint_names):
            raise RuntimeError(f"joint order differs: {names} vs {robot64.joint_names}")
        self.n_frames = len(robot64.frame_names)
        self.threads = torch.get_num_threads()
        self.label = "pytorch_kinematics (batched)"
        self.how = "pk.build_serial_chain_from_urdf + chain.jacobian(th), CPU tensors"
        from importlib.metadata import version

        pk_version = version("pytorch-kinematics")
        self.version = f"pytorch-kinematics {pk_version}, torch {torch.__version__}"

    def prepare(self, q64):
        self.torch.set_num_threads(self.threads)  # process-wide: set before every series
        return self.torch.as_tensor(np.ascontiguousarray(q64, dtype=self.dtype))

    def tune(self, q64):
        """Use 1 thread or torch's default, whichever is faster on this probe batch: on a
        loaded machine OpenMP's spinning threads can make 2 threads 50x slower than 1."""
        default = self.torch.get_num_threads()
        best = {}
        for threads in sorted({1, default}):
            self.threads = threads
            th = self.prepare(q64)
            self.run(th)
            times = []
            for _ in range(3):
                t = time.perf_counter()
                self.run(th)
                times.append(time.perf_counter() - t)
            best[threads] = min(times)
        self.threads = min(best, key=best.get)
        self.tuning = {f"{k} threads": f"{v * 1e3:.2f} ms" for k, v in best.items()}
        plural = "s" if self.threads > 1 else ""
        self.label = f"pytorch_kinematics (batched, {self.threads} thread{plural})"
        self.how += f"; torch threads {self.threads} (probe of {len(q64)}: {self.tuning})"

    def run(self, th):
        with self.torch.no_grad():
            self.chain.jacobian(th)

    def jacobians(self, q64):
        with self.torch.no_grad():
            return self.chain.jacobian(self.prepare(q64)).numpy().astype(np.float64)

    def bytes_per_config(self) -> float:
        # (frames, N, 4, 4) transforms, a few temporaries of that size, the (N, 6, dof) result
        item = 4 if self.dtype == "float32" else 8
        return item * (4 * self.n_frames * 16 + 3 * 6 * self.n_frames)


def urdf_root(text: str) -> str:
    """The root link of a URDF text (the link that is no joint's child)."""
    root = ET.fromstring(text)
    children = {j.find("child").get("link") for j in root.iter("joint")}
    return next(link.get("name") for link in root.iter("link") if link.get("name") not in children)


def torch_free_flyer_check(src: RobotSource, robot64: jk.Robot, q64: np.ndarray) -> str:
    """Why pytorch_kinematics is not timed on a free-flyer robot, and the check of what it does
    compute: it has no free-flyer joint, so ``build_serial_chain_from_urdf(urdf, frame)`` gives
    the fixed-base Jacobian of the frame's chain joints in the root link's axes; rotated by the
    base orientation it must equal those columns of jaxkin's world-aligned Jacobian at ``q64``."""
    import pytorch_kinematics as pk
    import torch

    frames = list(dict.fromkeys(f for case in src.cases for f in case.frames))
    root = urdf_root(src.urdf)
    J_all = np.stack([np.asarray(jk.geometric_jacobian(robot64, q, frame=frames)) for q in q64])
    R = np.stack([np.asarray(jk.fk(robot64, q, frame=root))[:3, :3] for q in q64])
    diffs, counts = [], []
    for i, frame in enumerate(frames):
        with quiet():
            chain = pk.build_serial_chain_from_urdf(src.urdf.encode(), frame, root)
        chain = chain.to(dtype=torch.float64)
        names = chain.get_joint_parameter_names()
        qi = [robot64.joint_names.index(n) for n in names]
        vi = [robot64.velocity_names.index(n) for n in names]
        with torch.no_grad():
            Jt = chain.jacobian(torch.as_tensor(q64[:, qi])).numpy()
        rotated = np.concatenate([R @ Jt[:, :3], R @ Jt[:, 3:]], axis=1)
        diffs.append(float(np.abs(rotated - J_all[:, i][..., vi]).max()))
        counts.append(len(names))
    return (
        f"pytorch-kinematics {version('pytorch-kinematics')} has no free-flyer joint: "
        f"`build_serial_chain_from_urdf(urdf, frame)` gives the fixed-base Jacobian of the "
        f"frame's {'/'.join(map(str, counts))} chain joints in {root}'s axes, without the base's "
        f"6 columns (checked: rotated by the base orientation it equals those columns of "
        f"jaxkin's to {max(diffs):.1e}); a smaller quantity than the (6, {robot64.nv}) rows, "
        "so not timed"
    )


MUJOCO_COMPILER = (
    '<mujoco><compiler fusestatic="false" discardvisual="true" balanceinertia="true" '
    'boundmass="1e-6" boundinertia="1e-9"/></mujoco>'
)
"""Inserted under ``<robot>``: fixed-joint frames kept as bodies (``fusestatic``), and every
moving body given a mass and inertia (MuJoCo rejects massless moving bodies; the Jacobian of a
point does not depend on them)."""


def mujoco_model(src: RobotSource):
    import mujoco

    text = src.urdf
    i = text.rindex("</robot>")
    return mujoco.MjModel.from_xml_string(text[:i] + MUJOCO_COMPILER + text[i:])


class _MujocoBase(Peer):
    def __init__(self, src: RobotSource, robot64: jk.Robot):
        import mujoco

        self.mj = mujoco
        self.m = mujoco_model(src)
        self.body = self.m.body(src.tip).id
        jids = [self.m.joint(n).id for n in robot64.joint_names]
        self.qadr = np.array([self.m.jnt_qposadr[j] for j in jids])
        self.dofs = np.array([self.m.jnt_dofadr[j] for j in jids])
        k = len(jids)
        contiguous = np.array_equal(self.qadr, np.arange(self.qadr[0], self.qadr[0] + k))
        self.qsel = slice(int(self.qadr[0]), int(self.qadr[0]) + k) if contiguous else self.qadr
        self.version = f"mujoco {mujoco.__version__}"
        self.extra = [self.m.joint(j).name for j in range(self.m.njnt) if j not in jids]


class MujocoLoop(_MujocoBase):
    label = "MuJoCo (Python loop)"

    def __init__(self, src, robot64):
        super().__init__(src, robot64)
        self.d = self.mj.MjData(self.m)
        self.jp = np.zeros((3, self.m.nv))
        self.jr = np.zeros((3, self.m.nv))
        self.how = "mj_kinematics + mj_comPos + mj_jac(point = xpos[tip body]) per configuration"
        if self.extra:
            self.how += f"; other joints {self.extra} at 0, their columns dropped"

    def run(self, qs):
        m, d, body, jp, jr, sel = self.m, self.d, self.body, self.jp, self.jr, self.qsel
        kin, com, jac = self.mj.mj_kinematics, self.mj.mj_comPos, self.mj.mj_jac
        qpos, xpos = d.qpos, d.xpos
        for q in qs:
            qpos[sel] = q
            kin(m, d)
            com(m, d)
            jac(m, d, jp, jr, xpos[body], body)

    def jacobians(self, q64):
        out = []
        for q in q64:
            self.d.qpos[:] = 0.0
            self.d.qpos[self.qsel] = q
            self.run([q])
            out.append(np.vstack([self.jp, self.jr])[:, self.dofs])
        return np.stack(out)


class MujocoBatch(_MujocoBase):
    """``mujoco.batch.Batch`` on its thread pool; ``mode`` "origin" (world-aligned at the body
    origin: forward to the POS stage for ``xpos``, then ``jac``) or "world" (``jac`` at the
    world origin: the WORLD-reference Jacobian, one kinematics pass)."""

    batched = True

    def __init__(self, src, robot64, mode: str, nthread: int | None = None):
        super().__init__(src, robot64)
        from mujoco import batch  # noqa: F401  (MuJoCo >= 4; fail here, not while timing)

        self.mode = mode
        self.nthread = nthread or os.cpu_count() or 1
        self.reference = "world_aligned" if mode == "origin" else "world"
        if mode == "origin":
            self.label = f"MuJoCo Batch forward(POS) + jac ({self.nthread} threads)"
            self.how = (
                "mujoco.batch.Batch: qpos rows written, forward(stage=mjSTAGE_POS) (contacts and "
                "constraints disabled), jac(body, xpos[:, body])"
            )
            self.m = copy.copy(self.m)  # a private copy with the flags
            dis = self.mj.mjtDisableBit
            self.m.opt.disableflags |= int(dis.mjDSBL_CONTACT) | int(dis.mjDSBL_CONSTRAINT)
        else:
            self.label = f"MuJoCo Batch jac at world origin ({self.nthread} threads)"
            self.how = (
                "mujoco.batch.Batch: qpos rows written, jac(body, 0): the body point at the "
                "world origin, i.e. the WORLD-reference Jacobian (checked against jaxkin "
                "reference='world')"
            )
        self._batch = None
        self._nsim = 0

    def _get(self, n: int):
        from mujoco import batch as mjb

        if self._nsim != n:
            self._batch = None  # free the old one first
            b = mjb.Batch(self.m, nsim=n, nthread=self.nthread)
            # bind before the first call: a derived field bound between calls stays zero
            self._fields = (b.bind("qpos"), b.bind("xpos"))
            self._batch, self._nsim = b, n
        return self._batch

    def prepare(self, q64):
        b = self._get(len(q64))
        return b, np.ascontiguousarray(q64, dtype=np.float64)

    def run(self, prepared):
        b, q = prepared
        qpos, xpos = self._fields
        qpos[:, self.qsel] = q
        if self.mode == "origin":
            b.forward(stage=self.mj.mjtStage.mjSTAGE_POS)
            return b.jac(self.body, xpos[:, self.body])
        return b.jac(self.body, np.zeros(3))

    def jacobians(self, q64):
        b, q = self.prepare(q64)
        self._fields[0][:] = 0.0
        jp, jr = self.run((b, q))
        return np.concatenate([jp, jr], axis=1)[:, :, self.dofs]

    def bytes_per_config(self) -> float:
        return 8.0 * (2 * 3 * self.m.nv + 3 * self.m.nbody + 4 * self.m.nq)

    def close(self):
        self._batch, self._fields, self._nsim = None, None, 0


class RoboticsToolbox(Peer):
    label = "Robotics Toolbox ETS (Python loop)"

    def __init__(self, src: RobotSource, robot64: jk.Robot):
        import roboticstoolbox as rtb

        if not axis_aligned(robot64):
            raise RuntimeError(
                "not every moving axis is exactly axis-aligned: RTB's URDF import is wrong then, "
                "so it is not run"
            )
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"{src.name}.urdf"
            path.write_text(src.urdf)
            with warnings.catch_warnings(), quiet():
                warnings.simplefilter("ignore")
                robot = rtb.Robot.URDF(str(path))
        self.ets = robot.ets(end=src.tip)
        if self.ets.n != robot64.dof:
            raise RuntimeError(f"RTB ETS has {self.ets.n} joints, jaxkin {robot64.dof}")
        self.version = f"roboticstoolbox-python {rtb.__version__}"
        self.how = "rtb.Robot.URDF(same file).ets(end=tip), ets.jacob0(q) per configuration"

    def run(self, qs):
        jac = self.ets.jacob0
        for q in qs:
            jac(q)

    def jacobians(self, q64):
        return np.stack([self.ets.jacob0(q) for q in q64])


def build_peers(src: RobotSource, robot64: jk.Robot) -> tuple[list[Peer], dict[str, str]]:
    """Every peer that loads this robot; ``failed`` maps a peer to why it could not."""
    makers = [
        ("pytorch_kinematics float32", lambda: TorchKinematics(src, robot64, "float32")),
        ("pytorch_kinematics float64", lambda: TorchKinematics(src, robot64, "float64")),
        ("MuJoCo loop", lambda: MujocoLoop(src, robot64)),
        ("MuJoCo Batch origin", lambda: MujocoBatch(src, robot64, "origin")),
        ("MuJoCo Batch world", lambda: MujocoBatch(src, robot64, "world")),
        ("Robotics Toolbox", lambda: RoboticsToolbox(src, robot64)),
    ]
    peers, failed = [], {}
    for name, make in makers:
        try:
            peers.append(make())
        except Exception as e:  # a missing or failing peer is reported, not fatal
            failed[name] = f"{type(e).__name__}: {e}"
    return peers, failed
