"""Shared test helper: the library's configuration sampler, as float64 numpy arrays."""

import numpy as np

import jaxkin as jk


def sample_configurations(robot: jk.Robot, n: int, seed: int) -> np.ndarray:
    """``n`` configurations (n, dof) from :func:`jaxkin.sample_configurations` with key ``seed``."""
    return np.array(jk.sample_configurations(robot, n, seed, dtype=np.float64))
