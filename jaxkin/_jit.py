"""Private: jit an entry point that owns a loop, with the robot's constants folded when possible.

A robot whose leaves are concrete (the usual case: ``solve_ik(robot, ...)`` called from Python)
is passed to ``jax.jit`` as a *static* argument (a ``Robot`` is an immutable value that hashes by
value), so the forward pass folds its constants (see :func:`jaxkin._forward.scalar_pass`): a
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
import inspect
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


_ONE_SHOT_OPTIONS = {
    "xla_backend_optimization_level": 0,
    "xla_llvm_disable_expensive_passes": True,
    "xla_cpu_parallel_codegen_split_count": 1,
}


@functools.cache
def one_shot_compiler_options() -> dict:
    """:func:`compiler_options` plus LLVM's optimisation off, for a program that runs once (e.g.
    ``jk.testing.assert_jacobian_consistent``'s): the same HLO and IEEE operations (no
    fast-math), compiled several times faster and run about half as fast; results may differ in
    the last bit (FMA contraction). :func:`compiler_options` alone if this XLA rejects them."""
    options = {**compiler_options(), **_ONE_SHOT_OPTIONS}
    try:
        jax.jit(lambda x: x + 1.0).lower(1.0).compile(compiler_options=options)
    except Exception:  # pragma: no cover - depends on the installed jaxlib
        return compiler_options()
    return options


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


def eager(kernel: Callable, static_argnames: tuple[str, ...] = ()) -> Callable:
    """``kernel(robot, *args)`` as a building block: compiled and cached when called outside any
    trace, traced inline inside one. Used as ``_fk = eager(frame_transform, ("frame",))``, then
    ``_fk(robot, q, f)``, with every argument given by position.

    ``static_argnames`` name the kernel's options (frame indices, ``reference``, ...): hashable
    values the executable is specialised on, wherever the kernel takes them, so every kernel
    keeps the one argument order ``(robot, q, frame, ...)``; the other arguments are arrays (or
    None). As ``jax.jit``'s own ``static_argnames``, but with the robot closed over and the cache
    bounded.

    Inside a user's ``jit``/``vmap``/``grad`` (a traced robot or array, or an active trace) the
    kernel is traced inline, as part of the caller's computation. Called eagerly, the kernel is
    compiled by ``jax.jit`` with the robot closed over (its constants folded: see
    :func:`jaxkin._forward.scalar_pass`) and cached under ``(kernel, robot, static values)``; the
    robot is an immutable value, so an equal robot shares the executable and a changed one
    (``robot.replace(...)``) gets its own. ``jax.jit`` compiles once per array shape and dtype.
    The arrays may be host numpy arrays (handed to the executable as they are: cheaper than a
    JAX array made first).
    At most :data:`EAGER_CACHE_SIZE` keys are kept. Inside ``jax.disable_jit()`` the kernel runs
    op by op and nothing is cached (cheaper for a robot used once, e.g. a property test over
    random robots).
    """
    names = list(inspect.signature(kernel).parameters)[1:]  # after the robot
    static_pos = tuple(names.index(n) for n in static_argnames)
    array_pos = tuple(i for i in range(len(names)) if i not in static_pos)

    @functools.wraps(kernel)
    def call(robot: Any, *args: Any) -> Any:
        if len(args) != len(names):
            raise TypeError(f"{kernel.__name__} takes {len(names)} arguments after the robot.")
        arrays = tuple(args[i] for i in array_pos)
        if inside_trace() or not robot.is_concrete or is_traced(arrays) or _jit_disabled():
            return kernel(robot, *_device(args))
        static = tuple(args[i] for i in static_pos)
        key = (kernel, robot, static)
        try:
            compiled = _eager_cache.pop(key, None)
        except TypeError:  # an unhashable static option: no cache
            return kernel(robot, *_device(args))
        if compiled is None:
            options = compiler_options() or None
            bound = _bind(kernel, robot, dict(zip(static_pos, static, strict=True)), len(names))
            compiled = jax.jit(bound, compiler_options=options)
        _eager_cache[key] = compiled  # most recently used last
        while len(_eager_cache) > EAGER_CACHE_SIZE:
            _eager_cache.popitem(last=False)
        return compiled(*arrays)

    call.kernel = kernel  # type: ignore[attr-defined]
    call.static_argnames = tuple(static_argnames)  # type: ignore[attr-defined]
    return call


def _bind(kernel: Callable, robot: Any, static: dict, n: int) -> Callable:
    """``kernel`` with the robot and the static options (by position) fixed: a function of the
    arrays alone, in order."""

    def run(*arrays: Any) -> Any:
        rest = iter(arrays)
        return kernel(robot, *(static[i] if i in static else next(rest) for i in range(n)))

    return run


def _device(arrays: tuple) -> tuple:
    """Host arrays (``check_q(..., host=True)``) as JAX arrays, for kernels run op by op or
    traced inline. Outside a trace by ``jax.device_put`` of a copy: ``jnp.asarray`` of a numpy
    array there runs a ``stage`` primitive that JAX compiles once per shape and dtype."""
    if inside_trace():
        return tuple(jnp.asarray(a) if isinstance(a, np.ndarray) else a for a in arrays)
    return tuple(jax.device_put(np.array(a)) if isinstance(a, np.ndarray) else a for a in arrays)


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


OP_BY_OP_BLOCK = 8
"""Block width of the arrays padded by :func:`padded_to_block`."""


def op_by_op() -> bool:
    """Whether JAX runs operations one by one here (``jax.disable_jit()``)."""
    return bool(jax.config.jax_disable_jit)


def block_width(n: int) -> int:
    """``n`` rounded up to a multiple of :data:`OP_BY_OP_BLOCK` (at least one block)."""
    return max(1, -(-n // OP_BY_OP_BLOCK)) * OP_BY_OP_BLOCK


def padded_to_block(x, width: int | None = None) -> jax.Array:
    """``x`` with zeros appended to its last axis up to ``width`` entries (default:
    :func:`block_width`); on the host when ``x`` is concrete.

    Run op by op, every primitive compiles once per shape: Jacobian columns (or a ``q`` that the
    forward pass reads entry by entry, so that its padding is never read) padded to a block have
    one shape for every robot of up to 8 (16, ...) velocity entries, and compile once, not once
    per number of joints. Each real entry is the same arithmetic as without padding; cut the
    padding off at the end."""
    n = x.shape[-1]
    if width is None:
        width = block_width(n)
    pad = [(0, 0)] * (len(x.shape) - 1) + [(0, width - n)]
    if is_traced(x):
        return jnp.pad(x, pad)
    return jax.device_put(np.pad(np.asarray(x), pad))
