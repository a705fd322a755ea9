"""Several frames in one call (issue 23, item 1): ``jk.fk``, ``jk.geometric_jacobian``,
``jk.twist``, ``jk.jacobians.frame_jacobian`` and ``jk.jacobian_fwd``/``jacobian_rev`` with
``frame=[f1, f2, ...]``.

Oracles: the single-frame calls stacked (bit for bit, op by op, on random trees; within 1e-15 of
the result's scale compiled under ``jit(vmap(...))``), Pinocchio's ``getFrameJacobian`` of a
free-flyer humanoid for several frames in all three references (columns in Pinocchio's velocity
order, as tests/test_floating_base.py compares), and the kernel's structure: one shared pass
computes the sine of each revolute joint on the union of the frames' paths once.

Cost: random robots run op by op (no compile); the humanoid op by op at one configuration
(simple_humanoid; Talos too with ``JAXKIN_FULL_CORPUS=1``); two small compiles for jit/vmap and
float32.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sampling import random_q
from _urdf_support import FULL_CORPUS
from _xla import FAST_COMPILE, jaxpr_eqns, op_by_op
from hypothesis import given
from hypothesis import strategies as st

import jaxkin as jk
import jaxkin.testing as jkt
from jaxkin import _jacobian_pass
from jaxkin.robots import example_robot_data as erd

REFERENCES = ("world_aligned", "local", "world")


# ----------------------------------------------------------------------------- random trees
@st.composite
def trees_with_frames(draw):
    """A random tree, a configuration, 1 to 4 frames (names and indices mixed, duplicates
    possible), a reference and a point choice: None, one (3,) or one per frame (k, 3)."""
    robot, q = draw(jkt.robots_and_configurations(2, 6, kind="tree"))
    picks = draw(st.lists(st.integers(0, robot.n_frames - 1), min_size=1, max_size=4))
    names = draw(st.lists(st.booleans(), min_size=len(picks), max_size=len(picks)))
    frames = [
        robot.frame_names[f] if by_name else f for f, by_name in zip(picks, names, strict=True)
    ]
    k = len(frames)
    point = draw(
        st.sampled_from([None, "one", "each"]).map(
            lambda c: (
                None
                if c is None
                else np.linspace(-0.3, 0.4, 3)
                if c == "one"
                else np.linspace(-0.5, 0.5, 3 * k).reshape(k, 3)
            )
        )
    )
    reference = draw(st.sampled_from(REFERENCES))
    as_tuple = draw(st.booleans())
    return robot, q, tuple(frames) if as_tuple else frames, point, reference


def _point_of(point, i):
    if point is None:
        return None
    return point if point.ndim == 1 else point[i]


@given(trees_with_frames())
@op_by_op
def test_several_frames_equal_the_single_frame_calls_stacked(case):
    robot, q, frames, point, reference = case
    k = len(frames)
    qd = np.linspace(-1.0, 1.0, robot.nv)
    T = jk.fk(robot, q, frame=frames)
    J = jk.geometric_jacobian(robot, q, frame=frames, point=point, reference=reference)
    V = jk.twist(robot, q, qd, frame=frames, reference=reference, point=point)
    assert T.shape == (k, 4, 4) and J.shape == (k, 6, robot.nv) and V.shape == (k, 6)
    for i, f in enumerate(frames):
        pt = _point_of(point, i)
        np.testing.assert_array_equal(T[i], jk.fk(robot, q, frame=f))
        J1 = jk.geometric_jacobian(robot, q, frame=f, point=pt, reference=reference)
        np.testing.assert_array_equal(J[i], J1)
        np.testing.assert_array_equal(
            V[i], jk.twist(robot, q, qd, frame=f, reference=reference, point=pt)
        )
    if point is not None:
        v = jk.point_velocity(robot, q, qd, point, frame=frames)
        assert v.shape == (k, 3)
        np.testing.assert_array_equal(v[-1], jk.point_velocity(robot, q, qd, pt, frame=f))


def _chain_tree() -> jk.Robot:
    """A small tree: a trunk of three revolute joints and two branches of two."""
    specs = []
    for name, parent in [
        ("t0", "base"),
        ("t1", "l_t0"),
        ("t2", "l_t1"),
        ("a0", "l_t2"),
        ("a1", "l_a0"),
        ("b0", "l_t2"),
        ("b1", "l_b0"),
    ]:
        i = len(specs)
        specs.append(
            dict(
                name=name,
                type="prismatic" if name == "a1" else "revolute",
                parent=parent,
                child=f"l_{name}",
                xyz=[0.1 * (i + 1), 0.05 * i, 0.2],
                rpy=[0.3 * i, -0.2, 0.1 * i],
                axis=[np.sin(i), 0.3, np.cos(i)],
                lower=-2.0,
                upper=2.0,
            )
        )
    return jk.Robot.from_joints(specs, name="two_branches", dtype=np.float64)


@functools.cache
def small_tree() -> jk.Robot:
    return _chain_tree()


def test_frame_lists_are_checked():
    robot = small_tree()
    q = np.zeros(robot.nq)
    for empty in ([], ()):
        with pytest.raises(jk.JaxkinError, match=r"jk.fk: frame must be .* non-empty list"):
            jk.fk(robot, q, frame=empty)
        with pytest.raises(jk.JaxkinError, match="non-empty list"):
            jk.geometric_jacobian(robot, q, frame=empty)
    with pytest.raises(jk.ModelError, match="has no frame 'nope'"):
        jk.fk(robot, q, frame=["l_a1", "nope"])
    with pytest.raises(jk.ModelError, match="out of range"):
        jk.twist(robot, q, q, frame=[1, 99])
    with pytest.raises(jk.ShapeError, match=r"point must have shape \(3,\) .* or \(2, 3\)"):
        jk.geometric_jacobian(robot, q, frame=[1, 2], point=np.zeros((3, 3)))
    with pytest.raises(jk.JaxkinError, match="takes one frame"):
        jk.analytical_jacobian(robot, q, frame=[1, 2])
    with jax.disable_jit():  # a 1-D array of indices is several frames too
        np.testing.assert_array_equal(
            jk.fk(robot, q, frame=np.array([2, 5])), jk.fk(robot, q, frame=(2, "l_a1"))
        )


# ----------------------------------------------------------------------------- one shared pass
def _sine_sizes(fn, q) -> list[int]:
    return [e.invars[0].aval.size for e in jaxpr_eqns(fn, q) if e.primitive.name == "sin"]


def test_one_pass_computes_each_joint_of_the_union_once():
    """Both branch tips share the trunk: the multi-frame kernel takes the sine of the union's
    revolute joints (3 trunk + 1 + 2 = 6) in one stacked op, where two single calls take 5 + 5."""
    robot = small_tree()
    q = jnp.zeros(robot.nq)
    frames = ["l_a1", "l_b1"]
    revolute = {j for f in frames for j in robot.ancestors(robot.frame_index(f))} & {
        j for j, kind in enumerate(robot.kinds) if kind == "revolute"
    }
    assert len(revolute) == 6
    for call in (
        lambda q: jk.fk(robot, q, frame=frames),
        lambda q: jk.geometric_jacobian(robot, q, frame=frames, reference="world"),
        lambda q: jk.twist(robot, q, q, frame=frames),
    ):
        assert _sine_sizes(call, q) == [len(revolute)]
    singles = _sine_sizes(lambda q: [jk.geometric_jacobian(robot, q, frame=f) for f in frames], q)
    assert singles == [4, 5]  # a1 is prismatic: 3 trunk + a0, 3 trunk + b0 + b1
    g = _jacobian_pass.jacobians_pass(robot, q, tuple(robot.frame_index(f) for f in frames))
    assert g.matrix().shape == (2, 6, robot.nv) and g.pose().shape == (2, 4, 4)


def test_jit_vmap_float32_and_autodiff():
    """Compiled under ``jit(vmap(...))`` the multi-frame kernels give the op-by-op numbers
    (which equal the single-frame calls stacked, bit for bit: above) to a few ulps, in float64
    and float32, and float32 is within ORACLES.md's tolerance of float64. ``jacobian_fwd`` and
    ``jacobian_rev`` of several frames (one pass, differentiated once) equal the hand-built
    columns. One small compile per dtype; the op-by-op reference at one configuration."""
    robot = small_tree()
    frames = ("l_a1", 5, "l_a1")
    qs = np.random.default_rng(3).uniform(-1.5, 1.5, (2, robot.nq))
    points = np.linspace(-0.2, 0.3, 9).reshape(3, 3)

    def multi(r, q):
        J, T = jk.jacobians.frame_jacobian(r, q, frame=frames, point=points, reference="world")
        return J, T, jk.twist(r, q, q, frame=frames, reference="local")

    def with_autodiff(q):
        fwd = jk.jacobian_fwd(robot, q, frame=frames, point=points, reference="local")
        rev = jk.jacobian_rev(robot, q, frame=frames, point=points, reference="world")
        return multi(robot, q), fwd, rev

    out, fwd, rev = jax.jit(jax.vmap(with_autodiff), compiler_options=FAST_COMPILE)(qs)
    assert fwd.shape == rev.shape == (2, 3, 6, robot.nv)
    np.testing.assert_allclose(rev, out[0], rtol=0, atol=1e-13)  # autodiff vs Table 4.1
    with jax.disable_jit():
        local = jk.geometric_jacobian(robot, qs[0], frame=frames, point=points, reference="local")
    np.testing.assert_allclose(fwd[0], local, rtol=0, atol=1e-13)
    r32 = robot.astype(np.float32)
    out32 = jax.jit(jax.vmap(lambda q: multi(r32, q)), compiler_options=FAST_COMPILE)(
        qs.astype(np.float32)
    )
    for r, got_all in ((robot, out), (r32, out32)):
        with jax.disable_jit():
            expected = multi(r, qs[0].astype(r.dtype))
        eps = float(np.finfo(r.dtype).eps)
        for got, want in zip(got_all, expected, strict=True):
            assert got.dtype == r.dtype and got.shape[:2] == (2, 3)
            scale = max(1.0, float(np.abs(want).max()))
            np.testing.assert_allclose(got[0], want, rtol=0, atol=4 * eps * scale)
    tol = 4 * float(np.finfo(np.float32).eps) * (1 + 1.5) * 3.0 * robot.nv  # ORACLES.md
    for a, b in zip(out32, out, strict=True):
        np.testing.assert_allclose(np.asarray(a, np.float64), b, rtol=0, atol=tol)


# ----------------------------------------------------------------------------- a humanoid
HUMANOIDS = ["erd/simple_humanoid"] + (["erd/talos_reduced"] if FULL_CORPUS else [])
PIN_REFS = {"world_aligned": "LOCAL_WORLD_ALIGNED", "local": "LOCAL", "world": "WORLD"}


def _pin_columns(robot: jk.Robot, model) -> np.ndarray:
    """For each Pinocchio velocity entry, the jaxkin velocity index (joints matched by name;
    the free flyer's (v, omega) in the root's axes, as jaxkin's ``root_joint.vx ... wz``)."""
    vi = {n: i for i, n in enumerate(robot.velocity_names)}
    src = np.zeros(model.nv, dtype=int)
    for jid in range(1, model.njoints):
        name, joint = model.names[jid], model.joints[jid]
        if joint.nv == 1:
            src[joint.idx_v] = vi[name]
        else:
            assert joint.shortname() == "JointModelFreeFlyer"
            for k, c in enumerate(["vx", "vy", "vz", "wx", "wy", "wz"]):
                src[joint.idx_v + k] = vi[f"{name}.{c}"]
    assert sorted(src) == list(range(robot.nv))
    return src


def _pin_q(robot: jk.Robot, model, q: np.ndarray) -> np.ndarray:
    qi = {n: i for i, n in enumerate(robot.joint_names)}
    out = np.zeros(model.nq)
    for jid in range(1, model.njoints):
        name, joint = model.names[jid], model.joints[jid]
        if joint.nq == 1:
            out[joint.idx_q] = q[qi[name]]
        else:  # Pinocchio: (x, y, z, qx, qy, qz, qw)
            for k, c in enumerate(["x", "y", "z", "qx", "qy", "qz", "qw"]):
                out[joint.idx_q + k] = q[qi[f"{name}.{c}"]]
    return out


@pytest.fixture(scope="module", params=HUMANOIDS)
def humanoid(request):
    pin = pytest.importorskip("pinocchio")
    name = request.param
    robot = jk.robots.load(name, floating_base=True, dtype=np.float64)
    model = pin.buildModelFromUrdf(str(erd.path(name)), pin.JointModelFreeFlyer())
    q = random_q(robot, 1, seed=11)[0]  # numpy: no sampler compiled per humanoid
    # both feet, both hands, the root link once more
    frames = [*robot.default_frames[-4:], robot.frame_names[1], robot.default_frames[-1]]
    with jax.disable_jit():  # op by op: no compile of a humanoid's kernel
        out = {
            ref: jk.geometric_jacobian(robot, q, frame=frames, reference=ref) for ref in PIN_REFS
        }
        out["T"] = jk.fk(robot, q, frame=frames)
        out["single"] = jk.geometric_jacobian(robot, q, frame=frames[0], reference="local")
    return pin, robot, model, q, frames, jax.tree_util.tree_map(np.asarray, out)


def test_humanoid_frames_match_pinocchio_in_every_reference(humanoid):
    pin, robot, model, q, frames, out = humanoid
    assert robot.kinds[0] == "free" and len(set(frames)) == 5
    data = model.createData()
    qp = _pin_q(robot, model, q)
    pin.computeJointJacobians(model, data, qp)
    pin.framesForwardKinematics(model, data, qp)
    src = _pin_columns(robot, model)
    tol = 1e-12 * max(1.0, float(np.abs(out["T"][:, :3, 3]).max()))
    for ref, rf in PIN_REFS.items():
        assert out[ref].shape == (len(frames), 6, robot.nv)
        for i, f in enumerate(frames):
            fid = model.getFrameId(f, pin.BODY)
            Jp = np.empty((6, robot.nv))
            Jp[:, src] = pin.getFrameJacobian(model, data, fid, getattr(pin, rf))
            np.testing.assert_allclose(out[ref][i], Jp, rtol=0, atol=tol, err_msg=(f, ref))
            if ref == "world_aligned":
                T = data.oMf[fid].homogeneous
                np.testing.assert_allclose(out["T"][i], T, rtol=0, atol=tol, err_msg=f)
    np.testing.assert_array_equal(out["local"][0], out["single"])  # row 0: the single call
    np.testing.assert_array_equal(out["world"][-1], out["world"][3])  # a duplicate frame
