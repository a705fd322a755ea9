"""Strict JAX for the whole suite: float64, rank promotion raises, warnings are errors.

The float32 tests build float32 robots and inputs explicitly (x64 stays on globally here, which is
what a float64 user has; jaxkin itself never flips the flag).
"""

import os

import jax
import pytest
from hypothesis import HealthCheck, settings

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")

settings.register_profile(
    "ci",
    max_examples=40,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
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
