"""Private: small dense linear algebra unrolled into scalar operations, for kernels under ``vmap``.

Under ``vmap`` every scalar is a vector over the batch and XLA fuses the whole factorisation into
one elementwise loop, about ten times faster on CPU than a batched LAPACK call on 6x6 matrices.
Used by the LM step of :mod:`jaxkin.ik` (and its restarts' base fit) and the rank test of
:mod:`jaxkin.ik_gradients`.
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


POLAR_ITERATIONS = 10
"""Scaled Newton steps of :func:`polar_rotation`: quadratic convergence once the scaling has
brought the singular values near 1, to rounding for condition numbers up to about 1e12."""


def polar_rotation(M: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The rotation nearest a (3, 3) matrix ``M`` (its orthogonal polar factor ``U V^T`` for
    ``M = U S V^T``): the ``R`` that maximises ``trace(R^T M)``, as Kabsch's fit of point sets
    needs. ``(R, ok)``: ``ok`` is False where ``det M <= 1e-9 |M|_F^3``: ``M``'s polar factor is
    a reflection (``det M <= 0``) or ``M`` is singular or nearly so; ``R`` is then not to be
    used.

    Scaled Newton iteration ``X <- (z X + X^-T / z) / 2``, ``z = sqrt(|X^-1|_F / |X|_F)`` (Higham),
    a fixed :data:`POLAR_ITERATIONS` steps, ``X^-T`` from the cofactors: elementwise, so under
    ``vmap`` the batch runs as one loop (a batched SVD of 3 x 3 matrices is a LAPACK call per
    matrix, and the restarts' fit runs inside the LM loop).
    """
    dtype = M.dtype
    norm = jnp.sqrt(jnp.sum(M * M))
    tiny = jnp.finfo(dtype).eps ** 2
    det0 = _det3(M)
    ok = det0 > 1e-9 * norm**3 + tiny
    X = jnp.where(ok, M / jnp.where(ok, norm, 1.0), jnp.eye(3, dtype=dtype))
    for _ in range(POLAR_ITERATIONS):
        cof = jnp.stack([jnp.cross(X[1], X[2]), jnp.cross(X[2], X[0]), jnp.cross(X[0], X[1])])
        det = jnp.sum(X[0] * cof[0])
        inv_t = cof / det  # X^-T
        z = jnp.sqrt(jnp.sqrt(jnp.sum(inv_t * inv_t)) / jnp.sqrt(jnp.sum(X * X)))
        X = 0.5 * (z * X + inv_t / z)
    return X, ok


def _det3(M: jax.Array) -> jax.Array:
    return jnp.sum(M[0] * jnp.cross(M[1], M[2]))
