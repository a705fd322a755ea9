"""Strict JAX for the whole suite: float64, rank promotion raises, warnings are errors.

The float32 tests build float32 robots and inputs explicitly (x64 stays on globally here, which is
what a float64 user has; jaxkin itself never flips the flag).
"""

import os

import jax
import pytest
from hypothesis import HealthCheck, Phase, settings

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

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


def pytest_collection_modifyitems(config, items):
    """Heaviest test files first, so that the two xdist workers finish together
    (tests/_schedule.py); the order within a file is kept."""
    from _schedule import weight

    items.sort(key=lambda item: -weight(str(item.path)))
