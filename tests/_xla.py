"""Shared test helper: XLA options that cut the compile time of one-off jitted test kernels.

Compiling jaxkin's unrolled kernels costs seconds per robot; these options halve that without
changing results (no fast-math). Empty if this jax/XLA does not know one of them.
"""

import jax


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
