"""Strict JAX for the whole suite: float64, rank promotion raises, warnings are errors.

The float32 tests build float32 robots and inputs explicitly (x64 stays on globally here, which is
what a float64 user has; jaxkin itself never flips the flag).
"""

import os
import shutil
import tempfile

import jax
import pytest
from hypothesis import HealthCheck, Phase, settings

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")


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
