"""The robot zoo: every entry loads, is documented, and its Jacobians agree with each other and with
central finite differences on SE(3).

* Every entry of ``jk.robots.names()`` loads in float64 and float32 (every leaf in that dtype), has
  a ``"zero"`` configuration, finite ``fk``/``fk_all`` at every named configuration (float32
  within tests/README.md's float32 bound of float64), named configurations within finite joint
  limits (except the documented ``OUTSIDE_TRAVEL`` reference poses), and a non-empty source;
  unknown names and parameters raise jaxkin errors that list what exists.
* For every zoo robot and every reference ("world_aligned", "local", "world"), at random
  configurations within the limits (fixed seed per robot) and at the named configurations: the
  hand-built geometric Jacobian (Table 4.1), ``jk.jacobian_fwd`` and ``jk.jacobian_rev`` agree to
  1e-12, and ``local = blkdiag(R^T, R^T) world_aligned``, ``world = [Jv + skew(p) Jw; Jw]``.
* At the random configurations all of them agree with central finite differences of forward
  kinematics (h = 1e-6, to 1e-7): linear rows from the frame origin's positions, angular rows from
  ``log_so3(R(q + h e_k) R(q - h e_k)^T) / (2 h)``; "local" rotates both into the frame's axes,
  "world" uses ``v + skew(p) omega`` (the velocity of the point at the world origin).
* ``reference=(...)`` (a tuple or list of references) gives a tuple of Jacobians in that order,
  each equal bit for bit to the call with that reference alone (the zoo kernel takes
  ``jacobian_fwd``/``jacobian_rev`` that way: one differentiation traced, not three); a bad or
  empty one is refused by name before anything is traced.

The float64 kernels of one robot are compiled once (``float64_results``, cached) and shared by the
tests that need them, to keep the file fast.
"""

from __future__ import annotations

import functools
import zlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _xla import FAST_COMPILE

import jaxkin as jk

ZOO = jk.robots.names()
INDUSTRIAL = ("scara", "stanford", "puma560", "ur5", "panda")
REFERENCES = ("world_aligned", "local", "world")
N_CONFIGS = 5
FD_STEP = 1e-6

# Named configurations that are the DH reference pose (q = 0) but lie outside the mechanical travel;
# each entry's docstring says so. The test checks they really are outside, so this list stays true.
OUTSIDE_TRAVEL = {("panda", "zero"), ("panda", "qz"), ("stanford", "zero")}


# ----------------------------------------------------------------------------------- helpers
def _seed(name: str) -> int:
    return zlib.crc32(name.encode())  # stable across processes (unlike hash())


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


_log_so3_batch = jax.jit(jax.vmap(jk.spatial.log_so3), compiler_options=FAST_COMPILE)
LOG_BATCH = 8  # rotations per call of _log_so3_batch: one shape, one compile for every robot


def _log_so3(dR: np.ndarray) -> np.ndarray:
    """``log_so3`` of each rotation (k, 3, 3), in calls of ``LOG_BATCH`` (identity padding)."""
    k = dR.shape[0]
    pad = np.broadcast_to(np.eye(3), (-k % LOG_BATCH, 3, 3))
    batches = np.concatenate([dR, pad]).reshape(-1, LOG_BATCH, 3, 3)
    return np.concatenate([np.asarray(_log_so3_batch(jnp.asarray(b))) for b in batches])[:k]


def _configurations(robot: jk.Robot, n: int, seed: int) -> np.ndarray:
    """``n`` configurations within the limits (unbounded joints in [-pi, pi]), drawn by numpy:
    nothing compiled per number of joints (the sampler is not under test here)."""
    lo = np.maximum(np.asarray(robot.lower, dtype=float), -np.pi)
    hi = np.minimum(np.asarray(robot.upper, dtype=float), np.pi)
    return np.random.default_rng(seed).uniform(lo, hi, (n, robot.dof))


def fd_jacobians(
    poses_plus: np.ndarray, poses_minus: np.ndarray, T: np.ndarray, h: float = FD_STEP
) -> dict[str, np.ndarray]:
    """Central finite-difference geometric Jacobians (6, dof) of one frame, every reference.

    ``poses_plus[k]`` / ``poses_minus[k]`` are the frame's poses (4, 4) at ``q +- h e_k``, ``T``
    its pose at ``q``. Linear rows: ``(p(q + h e_k) - p(q - h e_k)) / (2 h)``; angular rows:
    ``log_so3(R(q + h e_k) R(q - h e_k)^T) / (2 h)`` (world axes). "local" rotates both into the
    frame's axes; "world" is ``[v + skew(p) omega; omega]``.
    """
    Jv = (poses_plus[:, :3, 3] - poses_minus[:, :3, 3]).T / (2 * h)
    dR = np.einsum("kij,klj->kil", poses_plus[:, :3, :3], poses_minus[:, :3, :3])
    Jw = _log_so3(dR).T / (2 * h)
    R, p = T[:3, :3], T[:3, 3]
    return {
        "world_aligned": np.concatenate([Jv, Jw]),
        "local": np.concatenate([R.T @ Jv, R.T @ Jw]),
        "world": np.concatenate([Jv + _skew(p) @ Jw, Jw]),
    }


def fd_configurations(q: np.ndarray, h: float = FD_STEP) -> np.ndarray:
    """(2 dof, dof): q + h e_k for every k, then q - h e_k."""
    steps = h * np.eye(q.shape[0])
    return np.concatenate([q + steps, q - steps])


def _zoo_kernel(robot: jk.Robot, qs: jax.Array, qs_fd: jax.Array):
    """One compiled call per robot: tip Jacobians {(method, reference): (m, 6, dof)}, tip poses
    (fk) and all frames (fk_all) at ``qs``; tip poses at the finite-difference configurations
    ``qs_fd``."""

    def one(q):
        out = {}
        for ref in REFERENCES:
            out["geometric", ref] = jk.geometric_jacobian(robot, q, reference=ref)
        # every reference from one differentiation each (traced once, not three times; the
        # tuple equals the separate calls bit for bit: test_reference_tuple_...)
        fwd = jk.jacobian_fwd(robot, q, reference=REFERENCES)
        rev = jk.jacobian_rev(robot, q, reference=REFERENCES)
        for ref, Jf, Jr in zip(REFERENCES, fwd, rev, strict=True):
            out["fwd", ref], out["rev", ref] = Jf, Jr
        return out

    def tip(q):
        return jk.fk(robot, q)

    def frames(q):
        return jk.fk_all(robot, q)

    return jax.vmap(one)(qs), jax.vmap(tip)(qs), jax.vmap(frames)(qs), jax.vmap(tip)(qs_fd)


# the robot static (closed over): its constants fold, and the kernel compiles about 5x faster than
# over a traced robot (the traced path has its own tests in test_model.py and test_scale.py)
_zoo_kernel = jax.jit(_zoo_kernel, static_argnums=0, compiler_options=FAST_COMPILE)


def _poses_kernel(robot: jk.Robot, qs: jax.Array):
    return jax.vmap(lambda q: jk.fk(robot, q))(qs), jax.vmap(lambda q: jk.fk_all(robot, q))(qs)


_poses_kernel = jax.jit(_poses_kernel, static_argnums=0, compiler_options=FAST_COMPILE)


@functools.cache
def float64_results(name: str) -> dict:
    """Everything the float64 checks need for one robot, from one compiled call (cached)."""
    robot = jk.robots.load(name, dtype=np.float64)
    qs = _configurations(robot, N_CONFIGS, _seed(name))
    named = np.stack(list(robot.configurations.values()))
    configs = np.concatenate([qs, named])
    qs_fd = np.concatenate([fd_configurations(q) for q in qs])
    jac, T, Ts, T_fd = jax.tree_util.tree_map(
        np.asarray, _zoo_kernel(robot, jnp.asarray(configs), jnp.asarray(qs_fd))
    )
    n = N_CONFIGS
    return dict(
        robot=robot,
        qs=qs,
        configs=configs,
        jac=jac,
        T=T,
        T_fd=T_fd,
        named=named,
        T_named=T[n:],
        Ts_named=Ts[n:],
    )


# ----------------------------------------------------------------------------------- the list
def test_industrial_entries_registered():
    assert set(INDUSTRIAL) <= set(ZOO)
    assert ZOO == sorted(ZOO)


@pytest.mark.parametrize("name", ZOO)
def test_entry_documented(name):
    entry = jk.robots.info(name)
    assert entry.name == name
    assert isinstance(entry.source, str) and entry.source.strip()
    assert isinstance(entry.description, str) and entry.description.strip()


# ----------------------------------------------------------------------------------- loading
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("name", ZOO)
def test_loads_with_dtype_and_fk_finite_at_named_configurations(name, dtype):
    robot = jk.robots.load(name, dtype=dtype)
    assert isinstance(robot, jk.Robot)
    assert robot.dtype == np.dtype(dtype)
    for leaf in jax.tree_util.tree_leaves(robot):
        assert leaf.dtype == np.dtype(dtype), (name, leaf.dtype)
    configs = robot.configurations
    assert "zero" in configs
    np.testing.assert_array_equal(configs["zero"], np.zeros(robot.dof))
    for cname, q in configs.items():
        assert q.shape == (robot.dof,), cname
    Q = np.stack(list(configs.values()))
    ref = float64_results(name)
    np.testing.assert_array_equal(Q, ref["named"].astype(dtype))
    if dtype == np.float64:
        T, Ts = ref["T_named"], ref["Ts_named"]
    else:
        T, Ts = _poses_kernel(robot, jnp.asarray(Q, dtype=dtype))
        assert T.dtype == np.dtype(dtype) and Ts.dtype == np.dtype(dtype)
        T, Ts = np.asarray(T), np.asarray(Ts)
    assert T.shape == (len(configs), 4, 4)
    assert Ts.shape == (len(configs), robot.n_frames, 4, 4)
    assert np.all(np.isfinite(T)), name
    assert np.all(np.isfinite(Ts)), name
    np.testing.assert_array_equal(T, Ts[:, -1])  # fk's default frame: fk_all's last (the tip)
    if dtype == np.float32:
        # float32 against float64 (tests/README.md float32 bound: 4 eps32 (1 + max|q|) reach dof)
        Ts64 = ref["Ts_named"]
        eps32 = float(np.finfo(np.float32).eps)
        reach = max(1.0, float(np.max(np.linalg.norm(Ts64[..., :3, 3], axis=-1))))
        tol = 4 * eps32 * (1 + float(np.max(np.abs(Q)))) * reach * robot.dof
        np.testing.assert_allclose(Ts.astype(np.float64), Ts64, rtol=0, atol=tol, err_msg=name)


@pytest.mark.parametrize("name", ZOO)
def test_named_configurations_within_limits(name):
    robot = jk.robots.load(name)
    lo = np.asarray(robot.lower)
    hi = np.asarray(robot.upper)
    assert np.all(lo <= hi)
    for cname, q in robot.configurations.items():
        inside = bool(np.all((q >= lo) & (q <= hi)))
        if (name, cname) in OUTSIDE_TRAVEL:
            assert not inside, f"{name} {cname!r} is listed as outside its travel but is inside"
        else:
            assert inside, f"{name} configuration {cname!r} = {q} is outside [{lo}, {hi}]"


def test_unknown_robot_lists_available_names():
    with pytest.raises(jk.UnknownRobotError) as info:
        jk.robots.load("no_such_robot")
    message = str(info.value)
    assert "no_such_robot" in message
    for name in ZOO:
        assert name in message
    with pytest.raises(jk.UnknownRobotError):
        jk.robots.info("no_such_robot")
    assert issubclass(jk.UnknownRobotError, jk.JaxkinError)


def test_unknown_names_suggest_the_names_that_start_with_or_contain_them():
    """``erd/ur5`` is a prefix of ``erd/ur5_robot``: that is suggested first, not the closest
    spelling (``erd/ur3``); names of every collection are suggested for a bare name."""
    erd, mjcf = jk.robots.erd_names(), jk.robots.mjcf_names()
    assert jk.robots.close_names("erd/ur5", ["erd/ur3", "erd/ur5_robot", "erd/ur50"]) == [
        "erd/ur50",
        "erd/ur5_robot",
        "erd/ur3",
    ]
    assert jk.robots.close_names("UR5_ROBOT", ["erd/ur5_robot", "ur5"]) == ["erd/ur5_robot"]
    assert jk.robots.close_names("", ZOO) == [] and jk.robots.close_names(3, ZOO) == []
    if "erd/ur5_robot" in erd:
        with pytest.raises(jk.UnknownRobotError, match=r"Did you mean 'erd/ur5_robot' or ") as e:
            jk.robots.load("erd/ur5")
        assert "erd/ur3'" not in str(e.value)
        with pytest.raises(jk.UnknownRobotError, match=r"'ur5_robot'\. Did you mean 'erd/ur5_"):
            jk.robots.info("ur5_robot")
    if "mjcf/jaco_arm" in mjcf:
        with pytest.raises(jk.UnknownRobotError, match=r"Did you mean 'mjcf/jaco_arm' or "):
            jk.robots.load("mjcf/jaco")


@pytest.mark.parametrize("name", ZOO)
def test_robots_written_in_python_have_no_path(name):
    entry = jk.robots.info(name)
    assert entry.path is None and entry.tip is None and entry.base is None


def test_info_path_is_the_file_and_loads_the_same_robot():
    """``info(name).path`` is a file that the loader turns into the robot ``load(name)`` gives
    (``tip``/``base``: the part the zoo loads, None for the whole file); ``source`` is words."""
    wanted = ("erd/ur5_robot", "erd/panda", "erd/kinova", "erd/xarm7")
    erd = [n for n in wanted if n in jk.robots.erd_names()]
    for name in erd:
        entry = jk.robots.info(name)
        assert entry.path.is_file() and entry.path.suffix == ".urdf", name
        assert str(entry.path) in entry.source and "example-robot-data" in entry.source
        robot = jk.load_urdf(entry.path, tip=entry.tip, base=entry.base, name=name)
        assert robot == jk.robots.load(name), name
    if "erd/ur5_robot" in erd:  # loaded whole: the path alone gives it
        entry = jk.robots.info("erd/ur5_robot")
        assert entry.tip is None and entry.base is None
        assert jk.load_urdf(entry.path, name="erd/ur5_robot") == jk.robots.load("erd/ur5_robot")
    if "erd/panda" in erd:
        assert jk.robots.info("erd/panda").tip == "panda_hand_tcp"
    for name in ("mjcf/reacher", "mjcf/jaco_arm"):
        if name in jk.robots.mjcf_names():
            entry = jk.robots.info(name)
            assert entry.path.is_file() and entry.path.suffix == ".xml", name
            robot = jk.load_mjcf(entry.path, tip=entry.tip, base=entry.base, name=name)
            assert robot == jk.robots.load(name), name


@pytest.mark.parametrize("name", ["ur5", "two_link_planar"])
def test_unknown_parameter_raises(name):
    with pytest.raises(jk.JaxkinError) as info:
        jk.robots.load(name, no_such_parameter=1.0)
    assert "no_such_parameter" in str(info.value)


def test_symbolic_parameters_are_used():
    robot = jk.robots.load("two_link_planar", a1=2.0, a2=0.5)
    T = np.asarray(jk.fk(robot, np.zeros(2)))
    np.testing.assert_allclose(T[:3, 3], [2.5, 0.0, 0.0], rtol=0, atol=1e-15)


# ----------------------------------------------------------------------------------- Jacobians
@pytest.mark.parametrize("name", ZOO)
def test_jacobian_triangle_finite_differences_and_references(name):
    """geometric == jacfwd == jacrev (1e-12) == central FD on SE(3) (1e-7), every reference; and
    local = blkdiag(R^T, R^T) world_aligned, world = [Jv + skew(p) Jw; Jw] (1e-13)."""
    res = float64_results(name)
    qs, configs, jac, poses, poses_fd = (res[k] for k in ("qs", "configs", "jac", "T", "T_fd"))
    m, dof = configs.shape
    for ref in REFERENCES:
        geo = jac["geometric", ref]
        assert geo.shape == (m, 6, dof)
        np.testing.assert_allclose(jac["fwd", ref], geo, rtol=0, atol=1e-12, err_msg=ref)
        np.testing.assert_allclose(jac["rev", ref], geo, rtol=0, atol=1e-12, err_msg=ref)

    for k in range(m):
        R, p = poses[k, :3, :3], poses[k, :3, 3]
        wa = jac["geometric", "world_aligned"][k]
        local = np.concatenate([R.T @ wa[:3], R.T @ wa[3:]])
        world = np.concatenate([wa[:3] + _skew(p) @ wa[3:], wa[3:]])
        np.testing.assert_allclose(jac["geometric", "local"][k], local, rtol=0, atol=1e-13)
        np.testing.assert_allclose(jac["geometric", "world"][k], world, rtol=0, atol=1e-13)

    # Finite differences at the random configurations (the FD rotations are tiny, so log_so3
    # stays on its regular branch).
    for k, q in enumerate(qs):
        block = poses_fd[2 * dof * k : 2 * dof * (k + 1)]
        fd = fd_jacobians(block[:dof], block[dof:], poses[k])
        for ref in REFERENCES:
            np.testing.assert_allclose(
                jac["geometric", ref][k], fd[ref], rtol=0, atol=1e-7, err_msg=f"{ref} q={q}"
            )


def test_reference_tuple_equals_the_separate_calls_bit_for_bit():
    """``reference=(...)`` gives a tuple of Jacobians in the order asked (duplicates allowed; a
    list as a tuple), each equal bit for bit to the call with that reference alone;
    ``frame_jacobian`` returns ``(Js, T)``, ``T`` the single call's pose. (``geometric_jacobian``'s
    tuple: its doctest.) Small compiles: a few references per function, the smallest robot."""
    robot = jk.robots.load("two_link_planar", dtype=np.float64)
    q = np.array([0.3, -0.7])
    refs = ("local", "world", "local")  # Pinocchio's names LOCAL, WORLD; a duplicate
    together = jk.jacobian_fwd(robot, q, reference=refs)
    assert isinstance(together, tuple) and len(together) == len(refs)
    for ref, J in zip(refs, together, strict=True):
        alone = np.asarray(jk.jacobian_fwd(robot, q, reference=ref))
        np.testing.assert_array_equal(np.asarray(J), alone, err_msg=ref)
    as_list = jk.jacobian_fwd(robot, q, reference=list(refs))
    assert isinstance(as_list, tuple)
    np.testing.assert_array_equal(np.asarray(as_list), np.asarray(together))
    several = dict(frame=["link1", "link2"], point=np.array([0.1, 0.2, 0.0]))  # (2, 6, 2) each
    _, J_local = jk.jacobian_rev(robot, q, reference=("world", "local"), **several)
    alone = np.asarray(jk.jacobian_rev(robot, q, reference="local", **several))
    assert alone.shape == (2, 6, 2)
    np.testing.assert_array_equal(np.asarray(J_local), alone)
    Js, T = jk.jacobians.frame_jacobian(robot, q, reference=("world", "local"))
    assert isinstance(Js, tuple) and len(Js) == 2
    J_alone, T_alone = jk.jacobians.frame_jacobian(robot, q, reference="local")
    np.testing.assert_array_equal(np.asarray(Js[1]), np.asarray(J_alone))
    np.testing.assert_array_equal(np.asarray(T), np.asarray(T_alone))  # the frame's pose, once


@pytest.mark.parametrize(
    "fn", [jk.geometric_jacobian, jk.jacobian_fwd, jk.jacobian_rev, jk.jacobians.frame_jacobian]
)
def test_bad_reference_in_a_tuple_is_refused_before_tracing(fn):
    robot = jk.robots.load("two_link_planar", dtype=np.float64)
    q = np.zeros(2)
    with pytest.raises(jk.JaxkinError, match=r"reference must be one of .*got 'body'"):
        fn(robot, q, reference=("local", "body"))
    with pytest.raises(jk.JaxkinError, match=r"got an empty tuple\. Name at least one"):
        fn(robot, q, reference=())
    with pytest.raises(jk.JaxkinError, match=r"got an empty list"):
        fn(robot, q, reference=[])
    with pytest.raises(jk.JaxkinError, match=r"reference must be one of .*got 'body'"):
        fn(robot, q, reference="body")
