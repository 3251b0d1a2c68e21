"""Small dense linear algebra for the numba kernels, written as plain loops into caller
buffers (no allocation; summation in index order, so results do not depend on a BLAS).

Used by the GMIKF (gmis.gmikf) and the error-state INS (gmis.errins)."""

import numpy as np
from numba import njit


@njit(cache=True)
def mat_mul_into(a, b, out, rows, inner, cols):
    """out[:rows, :cols] = a[:rows, :inner] @ b[:inner, :cols]; out must not alias a, b."""
    for i in range(rows):
        for j in range(cols):
            s = 0.0
            for k in range(inner):
                s += a[i, k] * b[k, j]
            out[i, j] = s


@njit(cache=True)
def mat_mul_transposed_into(a, b, out, rows, inner, cols, symmetric):
    """out[:rows, :cols] = a[:rows, :inner] @ b[:cols, :inner]ᵀ; with symmetric (rows ==
    cols, result known symmetric) only the upper triangle is summed and mirrored."""
    for i in range(rows):
        for j in range(i if symmetric else 0, cols):
            s = 0.0
            for k in range(inner):
                s += a[i, k] * b[j, k]
            out[i, j] = s
            if symmetric:
                out[j, i] = s


@njit(cache=True, inline="always")
def mat3_vec_into(a, v, out):
    """out = a v for a 3×3 a and 3-vector v (no allocation, no BLAS call)."""
    for i in range(3):
        out[i] = a[i, 0] * v[0] + a[i, 1] * v[1] + a[i, 2] * v[2]


@njit(cache=True, inline="always")
def mat3_mul_into(a, b, out):
    """out = a b for 3×3 matrices; out must not alias a, b."""
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]


@njit(cache=True)
def cholesky_inplace(a, m):
    """Lower Cholesky factor of the leading m×m block of a, in place. False if not PD."""
    for j in range(m):
        s = a[j, j]
        for k in range(j):
            s -= a[j, k] * a[j, k]
        if s <= 0.0:
            return False
        a[j, j] = np.sqrt(s)
        for i in range(j + 1, m):
            s = a[i, j]
            for k in range(j):
                s -= a[i, k] * a[j, k]
            a[i, j] = s / a[j, j]
    return True


@njit(cache=True)
def cholesky_solve_inplace(l, m, b, ncol):
    """Solve (L Lᵀ) X = B for the leading m rows of b (m × ncol), in place."""
    for c in range(ncol):
        for i in range(m):
            s = b[i, c]
            for k in range(i):
                s -= l[i, k] * b[k, c]
            b[i, c] = s / l[i, i]
        for i in range(m - 1, -1, -1):
            s = b[i, c]
            for k in range(i + 1, m):
                s -= l[k, i] * b[k, c]
            b[i, c] = s / l[i, i]


@njit(cache=True, inline="always")
def back_substitute_row(l, m, b, row):
    """Solve Lᵀ y = b[row, :m] in place (L lower triangular, the leading m×m of l)."""
    for i in range(m - 1, -1, -1):
        s = b[row, i]
        for k in range(i + 1, m):
            s -= l[k, i] * b[row, k]
        b[row, i] = s / l[i, i]

