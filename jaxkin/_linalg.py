"""Private: small dense linear algebra unrolled into scalar operations, for kernels under ``vmap``.

Under ``vmap`` every scalar is a vector over the batch and XLA fuses the whole factorisation into
one elementwise loop, about ten times faster on CPU than a batched LAPACK call on 6x6 matrices.
Used by the LM step of :mod:`jaxkin.ik` and the rank test of :mod:`jaxkin.ik_gradients`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp


def unrolled_cholesky(
    entry: Callable[[int, int], jax.Array], m: int, floor: Any = None
) -> tuple[list[list[Any]], jax.Array]:
    """The Cholesky factor of a symmetric (m, m) matrix, entry by entry: ``(L, ok)``.

    ``entry(i, k)`` gives the matrix's (i, k) entry for ``k <= i`` (asked once each, in row
    order, so it may build the entry from other scalars). ``L[i][k]`` (``k <= i``) are the
    scalars of the lower factor, ``A = L L^T``; the entries above the diagonal are None. ``ok``
    is True when every pivot (the value whose square root is a diagonal entry) is > 0, i.e. the
    matrix is positive definite. Pivots are raised to ``floor`` first when given (``L`` stays
    finite for any input); otherwise a pivot <= 0 gives NaN in ``L``.
    """
    L: list[list[Any]] = [[None] * m for _ in range(m)]
    ok = jnp.ones((), bool)
    for i in range(m):
        for k in range(i + 1):
            a = entry(i, k)
            s = a - sum((L[i][j] * L[k][j] for j in range(k)), start=jnp.zeros_like(a))
            if i == k:
                ok = ok & (s > 0)
                L[i][k] = jnp.sqrt(s if floor is None else jnp.maximum(s, floor))
            else:
                L[i][k] = s / L[k][k]
    return L, ok
