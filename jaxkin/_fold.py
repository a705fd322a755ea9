"""Scalar algebra that folds constants while tracing (private; used by the forward pass).

A value is either a Python ``float`` (a constant known at trace time) or a JAX scalar (0-d under
``jit``; shape (N,) under ``vmap``). Products with exact 0 vanish, products with +-1 become
copies or negations, and sums drop zeros, so a forward pass over a robot whose placements are
mostly +-90 degree rotations compiles to far fewer operations. Every operation is elementwise:
XLA fuses the whole kernel into one loop over the batch (no 3x3 ``dot`` ops).

Matrices are tuples of rows, vectors tuples of entries.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

Scalar = Any  # float | jax.Array (0-d)
Vec = tuple  # (Scalar, Scalar, Scalar)
Mat = tuple  # ((Scalar,) * 3,) * 3


def is_const(x: Scalar) -> bool:
    return isinstance(x, float)


def _strong_float(x: Scalar) -> bool:
    """A strongly typed floating JAX value, concrete or traced: a Python constant combined
    with it takes its dtype."""
    return isinstance(x, jax.Array) and not x.weak_type and x.dtype.kind == "f"  # tracers too


def _alike(a: Scalar, b: Scalar) -> bool:
    """Both strongly typed floating JAX values (concrete or traced) of one dtype and shape:
    ``lax`` takes them as they are."""
    return _strong_float(a) and _strong_float(b) and a.dtype == b.dtype and a.shape == b.shape


# ``jnp``'s operators promote their arguments (and a Python constant through one more dispatch, a
# conversion) before the primitive runs, and each is a jitted function: op by op a dispatch,
# while tracing a pass through jit's machinery per operation. For operands already alike
# (concrete or traced), ``lax`` runs the same primitive on them directly: op by op about a third
# less time per operation, a vmapped trace of a humanoid hand's Jacobian 0.23 -> 0.15 s, the same
# values and the same lowered programs. A Python constant beside a strongly typed float is cast to
# its dtype here. Other operands (weakly typed, mixed dtypes or shapes) keep ``jnp``'s operators.
def _times(a: Scalar, b: Scalar) -> Scalar:
    if is_const(b) and _strong_float(a):
        return lax.mul(a, np.asarray(b, a.dtype))
    return lax.mul(a, b) if _alike(a, b) else a * b


def _plus(a: Scalar, b: Scalar) -> Scalar:
    if is_const(b) and _strong_float(a):
        return lax.add(a, np.asarray(b, a.dtype))
    return lax.add(a, b) if _alike(a, b) else a + b


def mul(a: Scalar, b: Scalar) -> Scalar:
    if is_const(a):
        if is_const(b):
            return a * b
        a, b = b, a
    if is_const(b):
        if b == 0.0:
            return 0.0
        if b == 1.0:
            return a
        if b == -1.0:
            return neg(a)
    return _times(a, b)


def add(*terms: Scalar) -> Scalar:
    const = 0.0
    traced = []
    for t in terms:
        if is_const(t):
            const += t
        else:
            traced.append(t)
    if not traced:
        return const
    out = traced[0]
    for t in traced[1:]:
        out = _plus(out, t)
    return _plus(out, const) if const != 0.0 else out


def neg(a: Scalar) -> Scalar:
    return lax.neg(a) if _strong_float(a) else -a


def sub(a: Scalar, b: Scalar) -> Scalar:
    if is_const(b) and b == 0.0:
        return a
    if is_const(a) and a == 0.0:
        return neg(b)
    if is_const(a) and is_const(b):
        return a - b
    return lax.sub(a, b) if _alike(a, b) else a - b


def dot3(u: Vec, v: Vec) -> Scalar:
    return add(mul(u[0], v[0]), mul(u[1], v[1]), mul(u[2], v[2]))


def matmul(A: Mat, B: Mat) -> Mat:
    return tuple(
        tuple(add(*(mul(A[i][k], B[k][j]) for k in range(3))) for j in range(3)) for i in range(3)
    )


def matvec(A: Mat, v: Vec) -> Vec:
    return tuple(dot3(A[i], v) for i in range(3))


def vadd(u: Vec, v: Vec) -> Vec:
    return tuple(add(u[i], v[i]) for i in range(3))


def vsub(u: Vec, v: Vec) -> Vec:
    return tuple(sub(u[i], v[i]) for i in range(3))


def vscale(u: Vec, s: Scalar) -> Vec:
    return tuple(mul(u[i], s) for i in range(3))


def cross(u: Vec, v: Vec) -> Vec:
    return (
        sub(mul(u[1], v[2]), mul(u[2], v[1])),
        sub(mul(u[2], v[0]), mul(u[0], v[2])),
        sub(mul(u[0], v[1]), mul(u[1], v[0])),
    )


def transpose(A: Mat) -> Mat:
    return tuple(tuple(A[j][i] for j in range(3)) for i in range(3))


def rotation_about(axis: Vec, c: Scalar, s: Scalar) -> Mat:
    """Rodrigues ``c I + s K + (1 - c) a a^T``; exact elementary rotations for +-x, +-y, +-z."""
    if all(is_const(a) for a in axis):
        nz = [i for i in range(3) if axis[i] != 0.0]
        if len(nz) == 1 and abs(axis[nz[0]]) == 1.0:
            i = nz[0]
            sg = axis[i]
            ss = mul(s, sg)
            j, k = (i + 1) % 3, (i + 2) % 3
            M = [[0.0] * 3 for _ in range(3)]
            M[i][i] = 1.0
            M[j][j] = c
            M[k][k] = c
            M[k][j] = ss
            M[j][k] = neg(ss)
            return tuple(tuple(r) for r in M)
    ax, ay, az = axis
    omc = sub(1.0, c)
    K = ((0.0, neg(az), ay), (az, 0.0, neg(ax)), (neg(ay), ax, 0.0))
    return tuple(
        tuple(
            add(c if i == j else 0.0, mul(s, K[i][j]), mul(omc, mul(axis[i], axis[j])))
            for j in range(3)
        )
        for i in range(3)
    )


def materialize(x: Scalar, dtype) -> jax.Array:
    """A JAX scalar of ``dtype`` (constants become literals)."""
    if is_const(x):
        return jnp.asarray(x, dtype=dtype)
    return x.astype(dtype) if x.dtype != dtype else x


def stack_matrix(rows, dtype) -> jax.Array:
    """Stack a nested list/tuple of scalars into one array of ``dtype`` (an empty list is a
    (0,) array: the rows of a (6, 0) Jacobian of a robot with no moving joint)."""
    if isinstance(rows, (tuple, list)) and len(rows) == 0:
        return jnp.zeros((0,), dtype)
    if isinstance(rows, (tuple, list)):
        return jnp.stack([stack_matrix(r, dtype) for r in rows])
    return materialize(rows, dtype)


CONCAT_OPERANDS = 8
"""The most operands of one concatenate the kernels emit (:func:`stack_vector`, the Jacobians'
column blocks and frames): XLA's CPU compiler fuses nothing into a concatenate with more
(``kMaxConcatenateArguments``) and compiles each operand as a loop of its own, each recomputing
whatever elementwise work (a forward pass) it shares with the others."""


def stack_vector(values, dtype) -> jax.Array:
    """``jnp.stack(values)`` (a (k,) array of scalars) as nested stacks of at most
    :data:`CONCAT_OPERANDS` operands each (rows of 8, zero-padded, reshaped and sliced back),
    so XLA fuses the stacking into one loop with what computes the values."""
    items = [materialize(v, dtype) for v in values]
    k = len(items)
    if k <= CONCAT_OPERANDS:
        return jnp.stack(items)
    w = CONCAT_OPERANDS
    items += [jnp.zeros_like(items[0])] * (-k % w)
    rows = [jnp.stack(items[i : i + w]) for i in range(0, len(items), w)]
    while len(rows) > w:
        rows += [jnp.zeros_like(rows[0])] * (-len(rows) % w)
        rows = [jnp.stack(rows[i : i + w]).reshape(-1) for i in range(0, len(rows), w)]
    return jnp.stack(rows).reshape(-1)[:k]
