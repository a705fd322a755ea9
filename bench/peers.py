"""Robots and peer adapters for the benchmark: the same URDF for jaxkin and every peer.

Robots (:func:`robot_sources`): example-robot-data's Panda (``erd/panda``: ``panda.urdf``, tip
``panda_hand_tcp``, fingers removed) and UR5 (``erd/ur5_robot``: ``ur5_robot.urdf``, tip
``tool0``), found by ``jaxkin.robots.example_robot_data``, and a serial chain of
:data:`CHAIN_JOINTS` revolute joints built with ``jk.Robot.from_joints`` (:func:`chain_robot`)
and written as URDF by ``jk.to_urdf``. Visual, collision, transmission and gazebo elements are
stripped (kinematics only; no mesh is ever opened); everything else is the file as shipped.

jaxkin builds each robot from that URDF text with ``jk.load_urdf(text, tip=...)``.

Peers, each verified numerically against jaxkin before it is timed (same frame, same quantity):

* :class:`Pinocchio`: ``pin.buildModelFromXML`` (joints not in jaxkin's ``q`` locked), one Python
  call per configuration: ``computeFrameJacobian(..., LOCAL_WORLD_ALIGNED)``; analytical: that,
  ``rpy.matrixToRpy`` and ``rpy.computeRpyJacobianInverse``; twist: ``forwardKinematics(q, v)``
  and ``getFrameVelocity(..., LOCAL_WORLD_ALIGNED)``.
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


@dataclass
class RobotSource:
    name: str
    urdf: str  # stripped URDF text, shared by jaxkin and every peer
    tip: str
    origin: str  # where the URDF comes from


def robot_sources(names: list[str] | None = None) -> list[RobotSource]:
    """Panda, UR5 and the generated chain (or the named subset, in that order)."""
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
    robot = jk.load_urdf(src.urdf, tip=src.tip, dtype=dtype, name=src.name)
    return robot, f"jk.load_urdf(<{src.name} URDF>, tip={src.tip!r})"


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
