"""Mobility: the rank and the null space of stacked constraint rows, with one tolerance.

The registration's Jacobians, the catalogue's wrenches and the analysis of a
set of contacts all decide rank here.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

RANK_TOLERANCE = 1e-7  # singular values below this fraction of the largest count as zero


def _scaled(matrix, length_mm):
    """Rotation columns (rad) scaled by a length (mm) so that they weigh like the translation columns."""
    matrix = np.asarray(matrix, float)
    return matrix if length_mm is None else matrix / np.array([length_mm] * 3 + [1.0] * 3)


def matrix_rank(matrix, length_mm=None) -> int:
    """Rank of rows (k, 6) over twists (omega, v); ``length_mm`` balances the rotation columns."""
    if len(matrix) == 0:
        return 0
    s = np.linalg.svd(_scaled(matrix, length_mm), compute_uv=False)
    return int(np.sum(s > RANK_TOLERANCE * max(s[0], 1e-300)))


def matrix_ranks(stack) -> np.ndarray:
    """Ranks (b,) of a stack of row sets (b, k, n) at once, with the same tolerance (zero rows pad)."""
    stack = np.asarray(stack, float)
    if stack.shape[1] == 0:
        return np.zeros(len(stack), int)
    s = np.linalg.svd(stack, compute_uv=False)
    return np.sum(s > RANK_TOLERANCE * np.maximum(s[:, :1], 1e-300), axis=1)


def null_space(matrix, length_mm=None) -> np.ndarray:
    """Vectors (m, n) the rows (k, n) leave free (twists, for n = 6), orthonormal in the scaled coordinates."""
    matrix = np.asarray(matrix, float)
    scaled = np.vstack([_scaled(matrix, length_mm), np.zeros((1, matrix.shape[1]))])
    free = np.linalg.svd(scaled)[2][matrix_rank(matrix, length_mm):]
    return free if length_mm is None else free / np.array([length_mm] * 3 + [1.0] * 3)


def weakest_motion(matrix, length_mm=None) -> np.ndarray:
    """The twist (1, n) the rows (k, n) determine worst: the last right singular vector, scaled coordinates."""
    weakest = np.linalg.svd(_scaled(matrix, length_mm))[2][-1:]
    return weakest if length_mm is None else weakest / np.array([length_mm] * 3 + [1.0] * 3)
