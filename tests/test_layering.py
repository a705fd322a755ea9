"""Each concept in one place (issue 22, items 4 and 5): the checks in ``_checks`` (the notion of
"traced" in ``_traces``, below the model), one unrolled Cholesky, one frame-pose kernel, one
argument order for the kernels, and a model that does not need ``build`` to load. Source scans
and small numeric checks: no robot is compiled here."""

import ast
import inspect
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxkin as jk
from jaxkin import _forward, _jacobian_pass, _linalg, jacobians, kinematics, model, velocity

SRC = Path(jk.__file__).parent


def _files_containing(pattern: str) -> list[str]:
    rx = re.compile(pattern)
    return sorted(p.name for p in SRC.glob("*.py") if rx.search(p.read_text()))


# --- item 4: checks outside _checks ----------------------------------------------------------
def test_is_traced_is_written_once():
    assert _files_containing(r"core\.Tracer") == ["_traces.py"]


def test_non_finite_and_path_refusals_are_written_in_checks_only():
    assert _files_containing(r"contains NaN or inf") == ["_checks.py"]
    assert _files_containing(r"\(N, 4, 4\) with N >= 2") == ["_checks.py"]


def test_path_check_names_the_argument_of_each_caller():
    with pytest.raises(jk.ShapeError, match=r"jk.classify_motion: Ts must have shape \(N, 4, 4\)"):
        jk.classify_motion(np.eye(4)[None])
    robot = jk.robots.load("two_link_planar")
    with pytest.raises(jk.ShapeError, match=r"resolved_rate_control: T_path must have shape"):
        jk.resolved_rate_control(robot, jnp.zeros(2), jnp.eye(4)[None], 0.01)


def test_ik_refuses_a_non_finite_q0_by_name():
    robot = jk.robots.load("two_link_planar")
    T = jk.fk(robot, jnp.array([0.3, 0.4]))
    with pytest.raises(jk.JaxkinError, match=r"jk.solve_ik: q0 contains NaN or inf\."):
        jk.solve_ik(robot, T, q0=jnp.array([jnp.nan, 0.0]))


# --- item 5a: one unrolled Cholesky -----------------------------------------------------------
def test_unrolled_cholesky_is_written_once():
    assert _files_containing(r"L\[i\]\[k\] =") == ["_linalg.py"]


def test_unrolled_cholesky_matches_lapack_and_flags_indefinite_matrices():
    rng = np.random.default_rng(0)
    B = rng.normal(size=(5, 5))
    A = B @ B.T + 0.1 * np.eye(5)
    L, ok = _linalg.unrolled_cholesky(lambda i, k: jnp.asarray(A[i, k]), 5)
    got = np.array([[0.0 if x is None else float(x) for x in row] for row in L])
    np.testing.assert_allclose(got, np.linalg.cholesky(A), rtol=1e-5, atol=1e-6)
    assert bool(ok)
    C = A - 10.0 * np.eye(5)  # indefinite: some pivot <= 0; the floor keeps L finite
    L, ok = _linalg.unrolled_cholesky(lambda i, k: jnp.asarray(C[i, k]), 5, floor=1e-30)
    assert not bool(ok)
    assert all(np.isfinite(float(x)) for row in L for x in row if x is not None)


def test_polar_rotation_matches_the_svd_and_flags_reflections_and_singular_matrices():
    """The restarts' base fit (``jaxkin.ik``): the rotation nearest M, against numpy's SVD
    (``U V^T``) on matrices of condition numbers up to 1e6 and any scale; flagged where
    ``det M <= 1e-9 |M|_F^3``: a reflection (``det <= 0``), rank < 3, or nearly so."""
    rng = np.random.default_rng(1)
    n = 400
    U = np.linalg.qr(rng.normal(size=(n, 3, 3)))[0]
    V = np.linalg.qr(rng.normal(size=(n, 3, 3)))[0]
    V[::3, :, 2] *= -1  # every third one a reflection: det M < 0
    S = 10.0 ** rng.uniform(-6, 0, size=(n, 3))
    S[:, 0] = 1.0
    S[n // 2 :, 2] = 0.0  # rank 2
    M = np.einsum("nij,nj,nkj->nik", U, S * 10.0 ** rng.uniform(-3, 3, size=(n, 1)), V)
    R, ok = map(np.asarray, jax.jit(jax.vmap(_linalg.polar_rotation))(M))
    margin = np.linalg.det(M) / np.linalg.norm(M, axis=(1, 2)) ** 3 / 1e-9
    full = np.arange(n) < n // 2
    clear = np.abs(margin - 1) > 0.01  # away from the threshold's rounding
    assert np.all(ok[clear] == (margin[clear] > 1)) and not np.any(ok[~full])
    assert np.sum(ok) > n // 4 and np.sum(full & (margin < 0)) > 10  # both kinds were drawn
    want = np.einsum("nij,njk->nik", U, V.transpose(0, 2, 1))  # a rotation wherever ok
    np.testing.assert_allclose(R[ok], want[ok], atol=1e-9)


# --- item 5b: one kernel for the pose of a frame -----------------------------------------------
def test_ik_and_analysis_take_a_frame_pose_from_its_kernel():
    """No ``fp.R[f]`` / ``fp.p[f]`` picked out of a full forward pass (calibration's residuals
    keep theirs: its compiled fit is bit-identical only with the full pass)."""
    pick = r"fp\.[Rp]\[(f|robot\.frame_index)"
    assert _files_containing(pick) == ["calibration.py"]
    assert "forward_pass" not in (SRC / "ik.py").read_text()
    src = (SRC / "calibration.py").read_text()
    assert src.count("frame_pose(") == 1 and src.count("forward_pass(") == 1


# --- item 5c: one argument order ----------------------------------------------------------------
KERNELS = [
    _forward.frame_transform,
    _forward.frame_transforms,
    _forward.frame_pose,
    _forward.frame_poses,
    _forward.forward_pass,
    _forward.scalar_pass,
    _forward.scan_pass,
    _forward.shared_scalar_pass,
    _forward.all_frame_transforms,
    _jacobian_pass.jacobian_pass,
    _jacobian_pass.jacobians_pass,
    _jacobian_pass.geometric_pass,
    _jacobian_pass.autodiff_jacobian,
    _jacobian_pass.analytical_jacobian_pass,
]


def _robot_q_frame_order(kernel) -> None:
    names = list(inspect.signature(kernel).parameters)
    assert names[0] == "robot", (kernel, names)
    takes_q = any(n.startswith("q") for n in names)  # the sampler takes no configuration
    assert names[1].startswith("q") or not takes_q, (kernel, names)
    assert not any(n in ("f", "frame", "frames") for n in names[3:]), (kernel, names)


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.__name__)
def test_kernels_take_robot_q_then_the_frame(kernel):
    _robot_q_frame_order(kernel)


def _eager_wrappers() -> list:
    """Every building block compiled through ``_jit.eager`` (module attributes carrying the
    wrapped kernel), from every jaxkin module."""
    import pkgutil
    from importlib import import_module

    found = []
    for info in pkgutil.iter_modules([str(SRC)]):
        mod = import_module(f"jaxkin.{info.name}")
        found += [v for v in vars(mod).values() if callable(v) and hasattr(v, "static_argnames")]
    return found


def test_eager_kernels_take_robot_q_then_the_frame_too():
    """The compiled building blocks keep the kernels' order: ``_jit.eager`` is told which
    arguments are static by name, so no kernel puts its options before ``q``."""
    wrappers = _eager_wrappers()
    assert len(wrappers) >= 12, wrappers
    for w in wrappers:
        _robot_q_frame_order(w.kernel)
        names = list(inspect.signature(w.kernel).parameters)
        assert set(w.static_argnames) <= set(names), (w.kernel, w.static_argnames)


def test_eager_keys_on_the_named_static_arguments():
    from jaxkin import _jit

    calls = []

    def kernel(robot, q, frame, point, reference):
        calls.append((frame, reference))
        return q * frame + (0.0 if point is None else point.sum())

    wrapped = _jit.eager(kernel, ("frame", "reference"))
    robot = jk.robots.load("two_link_planar")
    _jit.eager_cache_clear()
    try:
        q = jnp.array([1.0, 2.0])
        np.testing.assert_array_equal(wrapped(robot, q, 2, None, "local"), 2 * q)
        np.testing.assert_array_equal(wrapped(robot, q + 1, 2, None, "local"), 2 * (q + 1))
        np.testing.assert_array_equal(wrapped(robot, q, 3, jnp.ones(3), "local"), 3 * q + 3)
        assert calls == [(2, "local"), (3, "local")]  # traced once per static value
        assert _jit.eager_cache_info()["entries"] == 2
        with pytest.raises(TypeError, match="takes 4 arguments after the robot"):
            wrapped(robot, q, 2)
    finally:
        _jit.eager_cache_clear()


# --- item 5e: kernels in a private layer ------------------------------------------------------
PUBLIC_ALL = {
    kinematics: {"fk", "fk_all", "uses_scan"},
    jacobians: {
        "REFERENCES",
        "analytical_jacobian",
        "change_reference",
        "frame_jacobian",
        "geometric_jacobian",
        "jacobian_fwd",
        "jacobian_rev",
    },
    velocity: {
        "MOTION_KINDS",
        "classify_motion",
        "classify_twist",
        "point_velocity",
        "twist",
        "velocity_results",
    },
}


@pytest.mark.parametrize("module", list(PUBLIC_ALL), ids=lambda m: m.__name__)
def test_public_modules_export_what_users_call(module):
    assert set(module.__all__) == PUBLIC_ALL[module]


def test_no_public_module_exports_a_kernel():
    """The unchecked kernels live in ``_forward`` and ``_jacobian_pass`` (as optax keeps its
    implementation under ``_src``): no public module lists one in ``__all__``, so the API pages
    (autodoc follows ``__all__``) show what users call."""
    import pkgutil
    from importlib import import_module

    kernels = set(_forward.__all__) | set(_jacobian_pass.__all__)
    assert {k.__name__ for k in KERNELS} <= kernels
    for info in pkgutil.walk_packages(jk.__path__, prefix="jaxkin."):
        if any(part.startswith("_") for part in info.name.split(".")):
            continue
        exported = set(getattr(import_module(info.name), "__all__", ()))
        assert not exported & kernels, (info.name, exported & kernels)


# --- item 5d: model does not need build ---------------------------------------------------------
def test_model_imports_build_only_inside_its_two_builder_aliases():
    tree = ast.parse((SRC / "model.py").read_text())
    importers = {
        fn.name
        for fn in ast.walk(tree)
        if isinstance(fn, ast.FunctionDef)
        for node in ast.walk(fn)
        if isinstance(node, ast.ImportFrom) and node.module == "build"
    }
    assert importers == {"from_dh", "from_joints"}
    top = [n for n in tree.body if isinstance(n, ast.ImportFrom) and n.module == "build"]
    assert top == []


def test_astype_resolves_its_dtype_in_model():
    robot = jk.robots.load("two_link_planar")
    assert robot.astype(np.float32).base.dtype == np.float32
    assert model.resolve_dtype(None) == np.dtype(jnp.result_type(float))
    with pytest.raises(jk.ModelError, match="float32 or float64"):
        robot.astype(np.int32)
    assert jax.tree_util.tree_structure(robot.astype(np.float32)) == jax.tree_util.tree_structure(
        robot
    )
