"""Private: jit an entry point that owns a loop, with the robot's constants folded when possible.

A robot whose leaves are concrete (the usual case: ``solve_ik(robot, ...)`` called from Python)
is passed to ``jax.jit`` as a *static* argument (a ``Robot`` is an immutable value that hashes by
value), so the forward pass folds its constants (see :func:`jaxkin.kinematics.scalar_pass`): a
faster kernel that also compiles several times faster than one over traced parameters. One
compile per robot value and option set; a changed robot (e.g. a calibrated one) compiles once
more, and an equal robot loaded again reuses the compiled solver.

:func:`eager` does the same for the building blocks (``fk``, Jacobians, twists, derivatives)
called outside any transformation (see its docstring).

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

import collections
import functools
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._traces import inside_trace, is_traced

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


# ----------------------------------------------------------------------------- eager calls
EAGER_CACHE_SIZE = 128
"""How many compiled building blocks ``(kernel, robot value, static options)`` are kept; the least
recently used is dropped first, so the cache neither keeps robots alive for ever nor grows
without bound."""

_eager_cache: collections.OrderedDict = collections.OrderedDict()


def eager(kernel: Callable, robot: Any, static: tuple, *arrays: Any) -> Any:
    """``kernel(robot, *static, *arrays)``, compiled and cached when called outside any trace.

    Inside a user's ``jit``/``vmap``/``grad`` (a traced robot or array, or an active trace) the
    kernel is traced inline, as part of the caller's computation. Called eagerly, the kernel is
    compiled by ``jax.jit`` with the robot closed over (its constants folded: see
    :func:`jaxkin.kinematics.scalar_pass`) and cached under ``(kernel, robot, static)``; the
    robot is an immutable value, so an equal robot shares the executable and a changed one
    (``robot.replace(...)``) gets its own. ``jax.jit`` compiles once per array shape and dtype.
    ``arrays`` may be host numpy arrays (handed to the executable as they are: cheaper than a
    JAX array made first).
    At most :data:`EAGER_CACHE_SIZE` keys are kept. Inside ``jax.disable_jit()`` the kernel runs
    op by op and nothing is cached (cheaper for a robot used once, e.g. a property test over
    random robots).
    """
    if inside_trace() or not robot.is_concrete or is_traced(arrays) or _jit_disabled():
        return kernel(robot, *static, *_device(arrays))
    key = (kernel, robot, static)
    try:
        compiled = _eager_cache.pop(key, None)
    except TypeError:  # an unhashable static option: no cache
        return kernel(robot, *static, *_device(arrays))
    if compiled is None:
        options = compiler_options() or None
        compiled = jax.jit(functools.partial(kernel, robot, *static), compiler_options=options)
    _eager_cache[key] = compiled  # most recently used last
    while len(_eager_cache) > EAGER_CACHE_SIZE:
        _eager_cache.popitem(last=False)
    return compiled(*arrays)


def _device(arrays: tuple) -> tuple:
    """Host arrays (``check_q(..., host=True)``) as JAX arrays, for kernels run op by op."""
    return tuple(jnp.asarray(a) if isinstance(a, np.ndarray) else a for a in arrays)


def _jit_disabled() -> bool:
    """True inside ``jax.disable_jit()``: kernels then run op by op and nothing is cached."""
    return bool(jax.config.jax_disable_jit)


def eager_cache_clear() -> None:
    """Drop every compiled building block (tests; memory)."""
    _eager_cache.clear()


def eager_cache_info() -> dict:
    """``{"entries": keys held, "executables": compiled (shape, dtype) variants in all}``; for
    tests and the curious."""
    return {
        "entries": len(_eager_cache),
        "executables": sum(v._cache_size() for v in _eager_cache.values()),
    }
