"""J-dot, J-dot qd and the kinematic Hessian against Pinocchio, the Robotics Toolbox, closed forms
and central finite differences.

* Pinocchio (Panda from a URDF generated from the zoo's modified-DH table, Niryo One from the
  manufacturer's numbers; see test_oracle_pinocchio.py): ``computeJointJacobiansTimeVariation`` +
  ``updateFramePlacements`` + ``getFrameJacobianTimeVariation`` for the tip and the joint-6 frame
  in the three references, to ``1e-12 * max(1, reach)``; ``computeJointKinematicHessians`` +
  ``getJointKinematicHessian`` (joint frames = jaxkin's ``link*`` frames, all three references;
  the array is a column-major buffer, read as ``P.reshape(nv, nv, 6)``).
* Finite differences of the hand-built Jacobian along ``qd`` (J-dot) and along each joint
  (Hessian), ``h = 1e-6``, to ``1e-7``; the analytical J-dot (rpy, zyz, rotvec) against finite
  differences of ``jk.analytical_jacobian``.
* The Robotics Toolbox's ``hessian0`` (Panda) and the closed form of Haviland & Corke (2022).
"""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE, jaxpr_eqns

import jaxkin as jk

with warnings.catch_warnings():
    warnings.simplefilter("ignore", DeprecationWarning)
    pin = pytest.importorskip("pinocchio")

from test_oracle_pinocchio import (
    _frame_ids,
    _index_maps,
    modified_dh_urdf,
    niryo_urdf,
    sample_configurations,
)

N_CONFIGS = 20
SEED = 11
H = 1e-6
REFERENCES = {"world_aligned": pin.LOCAL_WORLD_ALIGNED, "local": pin.LOCAL, "world": pin.WORLD}
REPRESENTATIONS = ("rpy", "zyz", "rotvec")


def joint6_frame(robot: jk.Robot) -> str:
    """The frame moved by the sixth joint (its joint frame in Pinocchio)."""
    return robot.frame_names[robot.q_index.index(5) + 1]


def compared_frames(robot: jk.Robot) -> list[str]:
    """The tip (tool or last link) and the frame after joint 6 (a joint frame)."""
    return [robot.frame_names[-1], joint6_frame(robot)]


def _each(one, *xs):
    """``one`` at each configuration, as a loop (``lax.map``): the body is traced once,
    unbatched. For the J-dot kernel that halves the tracing and trims the compile (about 1 of 5
    CPU seconds per robot); the other kernels' loop bodies compile slower than their batched
    programs, so they stay ``jax.vmap``. Batching is tested in test_singular_domain.py."""
    return jax.lax.map(lambda x: one(*x), xs)


def _jdot_kernel(robot: jk.Robot, qs, qds):
    """J-dot of three frames in three references, J-dot qd, and central differences along qd."""

    def one(q, qd):
        out = {}
        for f in compared_frames(robot):
            for ref in REFERENCES:
                out[f"Jd/{f}/{ref}"] = jk.jacobian_dot(robot, q, qd, frame=f, reference=ref)
        steps = jnp.stack([q + H * qd, q - H * qd])  # one traced Jacobian for both steps
        for ref in REFERENCES:
            out[f"Jdqd/{ref}"] = jk.jacobian_dot_qd(robot, q, qd, reference=ref)
            Jp, Jm = jax.vmap(lambda x, r=ref: jk.geometric_jacobian(robot, x, reference=r))(steps)
            out[f"fd_Jd/{ref}"] = (Jp - Jm) / (2 * H)
            out[f"Jdtip/{ref}"] = out[f"Jd/{robot.frame_names[-1]}/{ref}"]
        out["Ts"] = jk.fk_all(robot, q)
        return out

    return _each(one, qs, qds)


def _hessian_kernel(robot: jk.Robot, qs):
    """Kinematic Hessians (joint-6 frame in three references, the tip) and differences of J."""
    f6 = joint6_frame(robot)

    def one(q):
        out = {
            f"H/{ref}": jk.kinematic_hessian(robot, q, frame=f6, reference=ref)
            for ref in REFERENCES
        }
        eye = jnp.eye(robot.dof, dtype=q.dtype)
        steps = jnp.concatenate([q[None] + H * eye, q[None] - H * eye])  # one traced Jacobian
        Js = jax.vmap(lambda x: jk.geometric_jacobian(robot, x, frame=f6))(steps)
        out["fd_H"] = (Js[: robot.dof] - Js[robot.dof :]) / (2 * H)  # [k] = dJ/dq_k
        out["Htip"] = jk.kinematic_hessian(robot, q)
        out["Jtip"] = jk.geometric_jacobian(robot, q)  # for the closed form of Haviland & Corke
        return out

    return jax.vmap(one)(qs)


def _analytical_kernel(robot: jk.Robot, qs, qds):
    """Analytical J-dot in each representation, with margins and differences along qd."""

    def one(q, qd):
        out = {}
        steps = jnp.stack([q + H * qd, q - H * qd])  # one traced Jacobian for both steps
        for rep in REPRESENTATIONS:
            Jad, margin = jk.analytical_jacobian_dot(robot, q, qd, rep, return_margin=True)
            out[f"Jad/{rep}"] = Jad
            out[f"margin/{rep}"] = margin
            if rep == "rpy":
                out[f"Jadqd/{rep}"] = jk.analytical_jacobian_dot_qd(
                    robot, q, qd, rep, return_margin=True
                )[0]
            Jap, Jam = jax.vmap(
                lambda x, r=rep: jk.analytical_jacobian(robot, x, r, return_margin=True)[0]
            )(steps)
            out[f"fd_Jad/{rep}"] = (Jap - Jam) / (2 * H)
        return out

    return jax.vmap(one)(qs, qds)


# Three kernels per robot: XLA's compile time grows faster than linearly with kernel size.
_jdot_kernel = jax.jit(_jdot_kernel, static_argnums=0, compiler_options=FAST_COMPILE)
_hessian_kernel = jax.jit(_hessian_kernel, static_argnums=0, compiler_options=FAST_COMPILE)
_analytical_kernel = jax.jit(_analytical_kernel, static_argnums=0, compiler_options=FAST_COMPILE)


@functools.cache
def computed(name: str):
    """Everything jaxkin computes for ``name`` (three compiled kernels), shared by the tests."""
    robot = jk.robots.load(name, dtype=np.float64)
    xml = niryo_urdf() if name == "niryo_one" else modified_dh_urdf(robot)
    model = pin.buildModelFromXML(xml)
    qs = sample_configurations(robot, N_CONFIGS, SEED)
    qds = np.random.default_rng(SEED + 1).normal(size=qs.shape)
    q, qd = jnp.asarray(qs), jnp.asarray(qds)
    out = {
        **_jdot_kernel(robot, q, qd),
        **_hessian_kernel(robot, q),
        **_analytical_kernel(robot, q, qd),
    }
    out = jax.tree_util.tree_map(np.asarray, out)
    reach = max(1.0, float(np.max(np.linalg.norm(out["Ts"][..., :3, 3], axis=-1))))
    return name, robot, model, qs, qds, out, reach


@pytest.fixture(scope="module", params=["panda", "niryo_one"])
def case(request):
    return computed(request.param)


def test_jacobian_dot_matches_pinocchio_in_every_reference(case):
    name, robot, model, qs, qds, out, reach = case
    data = model.createData()
    iq, iv = _index_maps(robot, model)
    fids = dict(zip(robot.frame_names, _frame_ids(robot, model), strict=True))
    for k in range(len(qs)):
        q_pin, v_pin = np.zeros(model.nq), np.zeros(model.nv)
        q_pin[iq], v_pin[iv] = qs[k], qds[k]
        pin.computeJointJacobiansTimeVariation(model, data, q_pin, v_pin)
        pin.updateFramePlacements(model, data)
        for f in compared_frames(robot):
            for ref, rf in REFERENCES.items():
                expected = pin.getFrameJacobianTimeVariation(model, data, fids[f], rf)[:, iv]
                np.testing.assert_allclose(
                    out[f"Jd/{f}/{ref}"][k], expected, rtol=0, atol=1e-12 * reach,
                    err_msg=f"{name} {f} {ref} k={k}",
                )  # fmt: skip


def test_kinematic_hessian_matches_pinocchio(case):
    name, robot, model, qs, _, out, _ = case
    data = model.createData()
    iq, iv = _index_maps(robot, model)
    jid = model.getJointId(robot.joint_names[5])  # joint 6's frame is joint6_frame(robot)
    n = model.nv
    for k in range(len(qs)):
        q_pin = np.zeros(model.nq)
        q_pin[iq] = qs[k]
        pin.computeJointKinematicHessians(model, data, q_pin)
        for ref, rf in REFERENCES.items():
            P = np.asarray(pin.getJointKinematicHessian(model, data, jid, rf))
            # Pinocchio hands back a column-major (6, nv, nv) tensor's buffer in C order.
            H_pin = np.transpose(P.reshape(n, n, 6), (0, 2, 1))  # [k, row, j]
            H_pin = H_pin[np.ix_(iv, np.arange(6), iv)]
            np.testing.assert_allclose(
                out[f"H/{ref}"][k], H_pin, rtol=0, atol=1e-12, err_msg=f"{name} {ref} k={k}"
            )


def test_jacobian_dot_and_hessian_match_finite_differences(case):
    _, _, _, _, _, out, reach = case
    for ref in REFERENCES:
        np.testing.assert_allclose(
            out[f"Jdtip/{ref}"], out[f"fd_Jd/{ref}"], rtol=0, atol=1e-7 * reach
        )
    # fd_H[k] = dJ/dq_k of frame link6: (N, dof, 6, dof) like H
    np.testing.assert_allclose(out["H/world_aligned"], out["fd_H"], rtol=0, atol=1e-7 * reach)


def test_identities_between_jdot_jdotqd_and_hessian(case):
    _, _, _, _, qds, out, reach = case
    for ref in REFERENCES:
        Jd = out[f"Jdtip/{ref}"]
        np.testing.assert_allclose(
            out[f"Jdqd/{ref}"], np.einsum("nij,nj->ni", Jd, qds), rtol=0, atol=1e-13 * reach
        )
    Jd_from_H = np.einsum("nk,nkij->nij", qds, out["Htip"])
    np.testing.assert_allclose(out["Jdtip/world_aligned"], Jd_from_H, rtol=0, atol=1e-13 * reach)


def test_analytical_jacobian_dot_matches_finite_differences(case):
    name, _, _, qs, qds, out, reach = case
    for rep in REPRESENTATIONS:
        ok = out[f"margin/{rep}"] > 0.05  # away from the representation singularity
        assert ok.sum() >= len(qs) // 2, (name, rep, ok.sum())
        scale = 1e-7 * reach / np.minimum(out[f"margin/{rep}"][ok], 1.0) ** 2
        err = np.abs(out[f"Jad/{rep}"][ok] - out[f"fd_Jad/{rep}"][ok]).max(axis=(1, 2))
        assert np.all(err <= scale), (name, rep, err.max())
        if rep == "rpy":
            np.testing.assert_allclose(
                out[f"Jadqd/{rep}"][ok],
                np.einsum("nij,nj->ni", out[f"Jad/{rep}"][ok], qds[ok]),
                rtol=1e-12,
                atol=1e-12,
            )


def test_hessian_matches_robotics_toolbox_and_closed_form():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        rtb = pytest.importorskip("roboticstoolbox")
    _, robot, _, qs, _, out, _ = computed("panda")  # the Panda's kernels, compiled once
    model = rtb.models.DH.Panda()
    model.tool = np.asarray(robot.tool)  # the zoo's TCP (Franka: 0.1034 m; RTB: 0.103 m)
    for q, H, J in zip(qs[:5], out["Htip"][:5], out["Jtip"][:5], strict=True):
        np.testing.assert_allclose(H, model.hessian0(q), rtol=0, atol=1e-12)
        # Haviland & Corke: H[k, :3, j] = z_a x Jv_b (a = min, b = max); H[k, 3:, j] = z_k x z_j
        z = J[3:]
        for k in range(7):
            for j in range(7):
                a, b = min(k, j), max(k, j)
                np.testing.assert_allclose(H[k, :3, j], np.cross(z[:, a], J[:3, b]), atol=1e-13)
                ang = np.cross(z[:, k], z[:, j]) if k < j else np.zeros(3)
                np.testing.assert_allclose(H[k, 3:, j], ang, atol=1e-13)


def test_derivatives_finite_at_singular_configuration():
    robot = jk.robots.load("two_link_planar", dtype=np.float64)
    q = jnp.zeros(2)  # stretched: singular
    qd = jnp.array([0.3, -0.7])

    @jax.jit(compiler_options=FAST_COMPILE)
    def kernel(q):
        g = jax.grad(lambda qq: jnp.sum(jk.jacobian_dot_qd(robot, qq, qd) ** 2))(q)
        return jk.jacobian_dot(robot, q, qd), jk.kinematic_hessian(robot, q), g

    Jd, H, g = kernel(q)
    # Jv = [[-s1 - s12, -s12], [c1 + c12, c12]] (a1 = a2 = 1), so at q = 0, with w = qd1 + qd2:
    # Jv-dot = [[-(qd1 + w), -w], [0, 0]]
    w = 0.3 - 0.7
    expected = np.array([[-(0.3 + w), -w], [0.0, 0.0]])
    np.testing.assert_allclose(np.asarray(Jd)[:2], expected, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.asarray(Jd)[2:], 0.0, rtol=0, atol=1e-15)
    assert np.all(np.isfinite(np.asarray(H)))
    assert np.all(np.isfinite(np.asarray(g)))


def test_analytical_jacobian_dot_at_representation_singularity():
    robot = jk.robots.load("two_link_planar", dtype=np.float64)
    # zyz is singular for every planar pose (theta = 0): eager raises, jit gives NaN.
    with pytest.raises(jk.RepresentationSingularityError, match="zyz"):
        jk.analytical_jacobian_dot(robot, jnp.array([0.2, 0.3]), jnp.ones(2), "zyz")
    out = jax.jit(
        lambda q: jk.analytical_jacobian_dot(robot, q, jnp.ones(2), "zyz"),
        compiler_options=FAST_COMPILE,
    )(jnp.array([0.2, 0.3]))
    assert np.all(np.isnan(np.asarray(out)))
    Jad, margin = jk.analytical_jacobian_dot(
        robot, jnp.array([0.2, 0.3]), jnp.ones(2), "rpy", return_margin=True
    )
    assert float(margin) == pytest.approx(1.0)
    assert np.all(np.isfinite(np.asarray(Jad)))


def test_errors_name_shapes_and_fix():
    robot = jk.robots.load("ur5", dtype=np.float64)
    with pytest.raises(jk.ShapeError, match=r"qd must have shape \(6,\)"):
        jk.jacobian_dot(robot, np.zeros(6), np.zeros(5))
    with pytest.raises(jk.ShapeError, match=r"jax\.vmap"):
        jk.kinematic_hessian(robot, np.zeros((3, 6)))
    with pytest.raises(jk.JaxkinError, match="reference"):
        jk.jacobian_dot(robot, np.zeros(6), np.zeros(6), reference="body")
    with pytest.raises(jk.JaxkinError, match="representation"):
        jk.analytical_jacobian_dot(robot, np.zeros(6), np.zeros(6), "xyz")


def test_analytical_jacobian_dot_costs_no_second_derivative_of_the_representation():
    """The analytical J-dot is traced as the geometric J-dot plus the representation's rate
    terms (``B(phi)^-1 (Jdot_w - Bdot J_a,w)``), not as a derivative of the chain rule through
    ``jacfwd`` of the representation map (a second derivative of atan2 / log: about twice the
    equations, and twice again under ``jax.grad``). Structure, not the clock: at most as many
    equations as the geometric J-dot and the analytical Jacobian together."""
    robot = jk.robots.load("two_link_planar", dtype=np.float64)
    q, qd = jnp.array([0.2, 0.3]), jnp.array([0.5, -1.0])

    def eqns(fn, *args):
        return len(jaxpr_eqns(fn, *args))

    jdot = eqns(lambda q, qd: jk.jacobian_dot(robot, q, qd), q, qd)
    for rep in REPRESENTATIONS:
        budget = jdot + eqns(lambda q, r=rep: jk.analytical_jacobian(robot, q, r), q)
        for fn in (jk.analytical_jacobian_dot, jk.analytical_jacobian_dot_qd):
            n = eqns(lambda q, qd, f=fn, r=rep: f(robot, q, qd, r, return_margin=True), q, qd)
            assert n <= budget, (fn.__name__, rep, n, budget)
