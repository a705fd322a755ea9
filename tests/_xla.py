"""Shared test helpers: XLA options that cut the compile time of one-off jitted test kernels, and
op counts of a kernel's jaxpr and compiled HLO (speed guarded by structure, not by the clock).

Compiling jaxkin's unrolled kernels costs seconds per robot; these options halve that without
changing results (no fast-math). Empty if this jax/XLA does not know one of them.
"""

import collections
import functools
import re

import jax
import jax.extend.core


def _fast_compile_options() -> dict:
    options = {
        "xla_backend_optimization_level": 0,
        "xla_llvm_disable_expensive_passes": True,
        "xla_cpu_parallel_codegen_split_count": 1,
        "xla_cpu_use_fusion_emitters": False,
    }
    try:
        jax.jit(lambda x: x + 1.0).lower(1.0).compile(compiler_options=options)
    except Exception:
        return {}
    return options


FAST_COMPILE = _fast_compile_options()


@functools.cache
def sampler(robot, n: int):
    """``key -> jk.sample_configurations(robot, n, key)`` as one compiled program (called eagerly,
    each ``jax.random`` primitive compiles on its own, with XLA's slower default options)."""
    import jaxkin as jk

    draw = functools.partial(jk.sample_configurations, robot, n)
    return jax.jit(draw, compiler_options=FAST_COMPILE)


def op_by_op(test):
    """``test`` run under ``jax.disable_jit()``: for a property over random robots (put it below
    ``@given``). Each example's robot is used once, and compiling programs for it (jaxkin's eager
    calls compile one per robot value and function) costs seconds; op by op, every primitive is
    compiled once per shape for the whole session and the example costs only its dispatch. The
    values are those of the same operations (what compiled code computes is tested elsewhere)."""

    @functools.wraps(test)
    def run(*args, **kwargs):
        with jax.disable_jit():
            return test(*args, **kwargs)

    return run


def jaxpr_eqns(fn, *args) -> list:
    """Every equation of the jaxpr of ``fn(*args)``, sub-jaxprs (jit, scan, custom rules)
    included: what a kernel traces, independent of XLA."""
    eqns: list = []

    def walk(jaxpr):
        for eqn in jaxpr.eqns:
            eqns.append(eqn)
            for sub in jax.extend.core.jaxprs_in_params(eqn.params):
                walk(sub)

    walk(jax.make_jaxpr(fn)(*args).jaxpr)
    return eqns


def jaxpr_counts(fn, *args) -> collections.Counter:
    """How many equations of each primitive :func:`jaxpr_eqns` finds."""
    return collections.Counter(e.primitive.name for e in jaxpr_eqns(fn, *args))


def hlo_counts(fn, *args) -> collections.Counter:
    """How many instructions of each opcode the compiled (optimised) HLO of ``jax.jit(fn)`` holds,
    fused computations included (``fusion`` counts the fused kernels XLA emits)."""
    text = jax.jit(fn).lower(*args).compile().as_text()
    return collections.Counter(re.findall(r"=\s*[^\s=]+\s+([a-z][a-z0-9\-]*)\(", text))
