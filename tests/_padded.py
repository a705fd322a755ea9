"""Column-wise functions of a Jacobian on padded shapes, for properties over random robots run op
by op (``_xla.op_by_op``, ``jax.disable_jit()``).

Op by op, every primitive compiles once per shape: a (6, nv) Jacobian passed as it is compiles
the function's operations once per number of joints drawn. A function whose column k depends
only on column k of ``J`` (``jk.change_reference``, ``jk.analytical_from_geometric``) gives the
same columns on ``J`` padded with zero columns to a multiple of 8; its operations
then compile once per block, for every robot up to that size.
"""

import numpy as np

from jaxkin._jit import padded_to_block


def padded(fn, J, *args, **kwargs) -> np.ndarray:
    """``fn(J, *args, **kwargs)`` (numpy) computed on ``J`` (6, nv) with zero columns appended up
    to a block of 8 (``jaxkin._jit.padded_to_block``), the padding cut off again:
    for ``fn`` acting column by column (the padding columns cannot reach the real ones)."""
    J = np.asarray(J)
    return np.asarray(fn(padded_to_block(J), *args, **kwargs))[:, : J.shape[1]]
