"""Private: jit an entry point that owns a loop, with the robot's constants folded when possible.

A robot whose leaves are concrete (the usual case: ``solve_ik(robot, ...)`` called from Python)
is passed to ``jax.jit`` as a *static* argument (a ``Robot`` is an immutable value that hashes by
value), so the forward pass folds its constants (see :func:`jaxkin.kinematics.scalar_pass`): a
faster kernel that also compiles several times faster than one over traced parameters. One
compile per robot value and option set; a changed robot (e.g. a calibrated one) compiles once
more, and an equal robot loaded again reuses the compiled solver.

A robot with traced leaves (the entry point called inside the user's ``jit``/``vmap``/``grad``
over the robot) is passed through unchanged: the implementation is traced into the caller's
computation, and new parameter values never retrace.

XLA's CPU "fusion emitters" (on by default in recent jaxlib) compile the long elementwise kernels
of these loops pathologically: the calibration regressor of the Niryo One took 31 s to compile
and 5 s to run, against 6 s and 3 ms with them off; the IK loop compiles about twice as fast
without them at the same speed. Entry points therefore compile with
``xla_cpu_use_fusion_emitters=False`` when the installed XLA knows that option (a no-op on GPU).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import jax

from ._checks import inside_trace, is_traced

_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


@functools.cache
def compiler_options() -> dict:
    """The compiler options of jaxkin's entry points ({} if this XLA rejects them)."""
    try:
        jax.jit(lambda x: x + 1.0).lower(1.0).compile(compiler_options=_OPTIONS)
    except Exception:  # pragma: no cover - depends on the installed jaxlib
        return {}
    return dict(_OPTIONS)


def robot_jit(impl: Callable, static_argnames: tuple[str, ...] = ()) -> Callable:
    """``impl(robot, *args, **static)`` jitted with ``robot`` static when it is concrete.

    At top level the jit carries :func:`compiler_options`; inside the caller's trace (where JAX
    allows no compiler options on a nested jit) a plain nested jit is used, compiled as part of
    the caller's computation. ``call.get_jitted()`` returns the top-level ``jax.jit`` object (for
    ``.lower`` in benchmarks).
    """
    state: dict[str, Any] = {}
    static = ("robot", *static_argnames)

    def jitted_fn(nested: bool = False):
        key = "nested" if nested else "top"
        if key not in state:
            options = None if nested else (compiler_options() or None)
            state[key] = jax.jit(impl, static_argnames=static, compiler_options=options)
        return state[key]

    @functools.wraps(impl)
    def call(robot, *args, **kwargs):
        if not is_traced(robot):
            return jitted_fn(nested=inside_trace())(robot, *args, **kwargs)
        return impl(robot, *args, **kwargs)

    call.get_jitted = jitted_fn  # type: ignore[attr-defined]
    return call
