"""Mobility: the rank of stacked constraint rows, with one tolerance.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

RANK_TOLERANCE = 1e-7  # singular values below this fraction of the largest count as zero



def jacobian_rank(jacobian, length):
    """Rank of a stacked Jacobian with rotation columns scaled by ``length`` mm."""
    if len(jacobian) == 0:
        return 0
    scaled = jacobian / np.array([length] * 3 + [1.0] * 3)
    s = np.linalg.svd(scaled, compute_uv=False)
    return int(np.sum(s > RANK_TOLERANCE * max(s[0], 1e-300)))
