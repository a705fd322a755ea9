"""Private: the one notion of "traced", below :mod:`jaxkin.model` and :mod:`jaxkin._checks`.

:mod:`jaxkin._checks` imports :class:`~jaxkin.model.Robot`, and the robot needs to know whether
its leaves are traced (its value key), so the test lives here, where both import it;
:mod:`jaxkin._checks` re-exports it for every other module.
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np


def is_tracer(x: Any) -> bool:
    """True when ``x`` itself is a JAX tracer (one array: the cheap test of hot paths)."""
    return isinstance(x, jax.core.Tracer)


def is_traced(*trees: Any) -> bool:
    """True when some leaf of ``trees`` is a JAX tracer (the call is inside a transformation)."""
    return any(is_tracer(x) for x in jax.tree_util.tree_leaves(trees))


def inside_trace() -> bool:
    """True while JAX is tracing (``jit``/``vmap``/``grad``), even when no argument is traced."""
    try:
        from jax._src import core

        return not core.trace_state_clean()
    except Exception:  # pragma: no cover - private API moved: assume nested
        return True


def staged() -> bool:
    """True while the caller's computation is staged out for compilation (inside its ``jit``,
    ``make_jaxpr``, a ``scan`` or ``cond`` body, at any depth of ``vmap``/``jvp``/``grad``): an
    operation on constants then gives a tracer. False outside any trace and under an eager
    ``vmap``/``jvp``/``grad``, whose operations run one by one. :func:`jaxkin.solve_ik` traces
    its solve inline when staged (a nested jit under ``jvp`` would be traced a second time for
    its tangents) and keeps its own compiled solver otherwise."""
    return inside_trace() and is_traced(jax.lax.add(np.int32(0), np.int32(0)))
