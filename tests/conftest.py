"""Strict JAX for the whole suite: float64, rank promotion raises, warnings are errors; quick
compiles.

The float32 tests build float32 robots and inputs explicitly (x64 stays on globally here, which is
what a float64 user has; jaxkin itself never flips the flag).
"""

import atexit
import os
import shutil
import sys
import tempfile

QUICK_COMPILE_FLAGS = (
    "--xla_backend_optimization_level=0",
    "--xla_llvm_disable_expensive_passes=true",
    "--xla_cpu_parallel_codegen_split_count=1",
    "--xla_cpu_use_fusion_emitters=false",
)
"""XLA flags of every process of the run (see :func:`_quick_compiles`)."""


def _quick_compiles() -> None:
    """LLVM's optimisation off for every compile of the run (set before JAX starts its backend).

    The suite's time is mostly compiling, and most programs it compiles run once on a few
    configurations: XLA still optimises the HLO as for users (same fusions, same operations, no
    fast-math) but LLVM generates its code at ``-O0``, several times faster to compile and about
    half as fast to run. Fusions are emitted by XLA's older elemental emitter, as jaxkin's own
    jits already do (``jaxkin._jit.compiler_options``), for the test-local jits and the
    primitives run op by op too (a tenth to a half less compile time for those). Results may
    differ in the last bit where ``-O3`` contracts a multiply and an add into an FMA, or where
    the two emitters round differently; tests/test_compile_options.py checks that the options a
    user's process compiles with give the numbers the suite checks. Subprocesses (the CLI, README,
    doctests, notebooks) inherit ``XLA_FLAGS``. ``JAXKIN_TESTS_XLA_DEFAULTS=1`` runs the suite
    with XLA's own defaults.
    """
    if os.environ.get("JAXKIN_TESTS_XLA_DEFAULTS"):
        return
    flags = os.environ.get("XLA_FLAGS", "").split()
    missing = [flag for flag in QUICK_COMPILE_FLAGS if flag not in flags]
    os.environ["XLA_FLAGS"] = " ".join(flags + missing)


_quick_compiles()


def _short_locations() -> None:
    """No Python tracebacks in the locations of the programs the run lowers.

    JAX records, by default, up to 100 frames of the caller's traceback as the MLIR location of
    each operation it lowers: text that no test reads, which XLA carries through its passes and
    which makes the persistent cache's keys differ between call sites of the same program. With
    none (the frame and primitive names stay), compile-heavy files take 4-9% less CPU time. Set
    through the environment before JAX starts, so subprocesses inherit it; a value the
    environment already names is kept.
    """
    os.environ.setdefault("JAX_INCLUDE_FULL_TRACEBACKS_IN_LOCATIONS", "false")
    os.environ.setdefault("JAX_TRACEBACK_IN_LOCATIONS_LIMIT", "0")


_short_locations()

import jax  # noqa: E402  (after XLA_FLAGS)
import pytest  # noqa: E402
from hypothesis import HealthCheck, Phase, settings  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


def _one_thread_intra_op_pool() -> None:
    """JAX's CPU client made while this thread runs on one CPU, then the CPUs given back: XLA's
    intra-op pool gets one thread (its size is the number of CPUs the process may use when the
    client starts), on the CPU of this xdist worker (``gwN``: the N-th).

    jaxlib 0.10's LAPACK kernels (SVD, Cholesky, LU, ...) split a large batch into tasks on
    that pool and block until they finish; when as many independent batched LAPACK calls run
    at once as the pool has threads, no thread is left to run the tasks and the process hangs
    (CI hung so on 2026-11-26: both pool threads of a worker in ``ParallelBatchMap`` under
    ``lapack_dgesdd_ffi``, in test_analysis's vmapped SVDs). With one thread, jaxlib runs each
    batch inline. Only the pool is pinned: the process's other threads and its subprocesses
    keep every CPU. ``JAXKIN_TESTS_ALL_CPUS=1`` leaves the pool as JAX sizes it.
    """
    if os.environ.get("JAXKIN_TESTS_ALL_CPUS") or not hasattr(os, "sched_setaffinity"):
        return
    cpus = sorted(os.sched_getaffinity(0))
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(worker[2:]) if worker[2:].isdigit() else 0
    os.sched_setaffinity(0, {cpus[index % len(cpus)]})  # this thread only (Linux)
    try:
        jax.devices("cpu")  # the client and its thread pools start now
    finally:
        os.sched_setaffinity(0, cpus)


_one_thread_intra_op_pool()


def _shared_compilation_cache() -> str | None:
    """One persistent compilation cache per run, shared by every process of the run.

    The two xdist workers, the CLI and notebook subprocesses and the test files compile many
    identical programs (the same robots' kernels, the same primitives op by op): what one
    process compiled, the others load. A private (0700) temporary directory made by the first
    process of the run (xdist's controller, or the only process with ``-n 0``) and passed to
    the others through ``JAX_COMPILATION_CACHE_DIR`` (which JAX reads at import), every
    executable stored (minimum compile time 0). Removed at the end of the run by the process
    that made it; returns its path there, ``None`` elsewhere. A directory already named by
    the environment is used as it is and kept.
    """
    if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        made = None
    else:
        made = tempfile.mkdtemp(prefix="jaxkin-tests-xla-")
        os.environ["JAX_COMPILATION_CACHE_DIR"] = made
        os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update(
        "jax_persistent_cache_min_compile_time_secs",
        float(os.environ.get("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")),
    )
    return made


_CACHE_MADE_HERE = _shared_compilation_cache()


def _worker_exits_without_teardown() -> None:
    """An xdist worker leaves, once its session is over, without freeing what it compiled.

    A worker holds thousands of compiled programs (kernels, and every primitive run op by op) at
    the end of the run, and Python's shutdown destroys them one by one (seconds: 2,000 small
    programs take ~4 s to free), while the run waits for both workers to exit. Results reach the
    controller through xdist's channel before shutdown starts, so the worker's last act is to
    flush its output and ``os._exit`` in the first exit handler (registered after JAX's, so run
    before it). Only in xdist workers, and not under coverage (whose data a worker writes at
    exit): a plain ``pytest -n 0`` run shuts down normally.
    """
    if not os.environ.get("PYTEST_XDIST_WORKER") or "coverage" in sys.modules:
        return

    def leave() -> None:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)

    atexit.register(leave)


_worker_exits_without_teardown()

# "ci" (default): reproducible (derandomized) and bounded; no shrinking, since each example of a
# random topology costs about a second of JAX dispatch and shrinking would take minutes. Use
# HYPOTHESIS_PROFILE=dev to shrink a failure, "thorough" for long randomized runs.
settings.register_profile(
    "ci",
    max_examples=12,  # CI's 20-minute budget; HYPOTHESIS_PROFILE=thorough runs 500
    deadline=None,
    derandomize=True,
    phases=[Phase.explicit, Phase.reuse, Phase.generate],
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    print_blob=True,
)
settings.register_profile(
    "dev", max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile(
    "thorough", max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture(autouse=True)
def _x64_on():
    # A test may switch x64 off temporarily (precision-warning tests); make sure it comes back.
    yield
    jax.config.update("jax_enable_x64", True)


def pytest_configure(config):
    # An entry read while the other worker is still writing it fails to decompress (or a write
    # fails: a full disk): JAX warns and compiles instead (same result), which must not fail the
    # test that hit it.
    for verb in ("reading", "writing"):
        config.addinivalue_line(
            "filterwarnings", f"ignore:Error {verb} persistent compilation cache entry:UserWarning"
        )


def pytest_unconfigure(config):
    if _CACHE_MADE_HERE:
        shutil.rmtree(_CACHE_MADE_HERE, ignore_errors=True)


def pytest_collection_modifyitems(config, items):
    """Heaviest test files first, so that the two xdist workers finish together
    (tests/_schedule.py); the order within a file is kept."""
    from _schedule import weight

    items.sort(key=lambda item: -weight(str(item.path)))
