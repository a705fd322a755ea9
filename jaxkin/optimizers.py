"""The default optax optimiser of jaxkin's fitting loops (IK's optax path, calibration)."""

from __future__ import annotations

import functools

__all__ = ["default_optimizer"]


@functools.cache
def default_optimizer():
    """L-BFGS with a backtracking line search (compiles about twice as fast as optax's default
    zoom search), one object for the process: optimisers hash by identity in jit's cache. Shared by
    :mod:`jaxkin.ik` (``method="optax"``) and :mod:`jaxkin.calibration`."""
    import optax

    return optax.lbfgs(linesearch=optax.scale_by_backtracking_linesearch(max_backtracking_steps=20))
