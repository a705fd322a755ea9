"""Column-wise functions of a Jacobian on padded shapes, for properties over random robots run op
by op (``_xla.op_by_op``, ``jax.disable_jit()``).

Op by op, every primitive compiles once per shape: a (6, nv) Jacobian passed as it is compiles
the function's operations once per number of joints drawn. A function whose column k depends
only on column k of ``J`` (``jk.change_reference``, ``jk.analytical_from_geometric``) gives the
same columns on ``J`` padded with zero columns to a multiple of :data:`BLOCK`; its operations
then compile once per block, for every robot up to that size.
"""

import numpy as np

BLOCK = 8


def padded(fn, J, *args, **kwargs) -> np.ndarray:
    """``fn(J, *args, **kwargs)`` (numpy) computed on ``J`` (6, nv) with zero columns appended up
    to a multiple of :data:`BLOCK`, the padding cut off again: for ``fn`` acting column by column
    (the padding columns cannot reach the real ones)."""
    J = np.asarray(J)
    nv = J.shape[1]
    wide = np.zeros((J.shape[0], max(1, -(-nv // BLOCK)) * BLOCK), dtype=J.dtype)
    wide[:, :nv] = J
    return np.asarray(fn(wide, *args, **kwargs))[:, :nv]
