"""How well a registration is checked: the rows beyond the six a pose needs, and which touches the
others check (Baarda's reliability: redundancy numbers and the minimal detectable error).

A touch is checked when the other touches alone fix the pose: an error in it
then shows in the residuals. Its redundancy number ``r = 1 - h`` (``h`` its
leverage, the diagonal of the hat matrix ``J (J^T J)^-1 J^T``, the largest
of its rows) is the share of an error in it that shows; the
smallest error found with 80 % power by a 0.1 % test of that one touch is
``DETECTION_FACTOR * sigma / sqrt(r)``. A touch with ``r`` near 0 is not
checked: no other touch tells whether it is right.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

DETECTION_FACTOR = 4.13  # z(0.1 % two-sided) + z(80 % power) = 3.29 + 0.84, Baarda's delta_0
UNCHECKED_REDUNDANCY = 1e-6  # a redundancy number below this: the touch is not checked


def redundancy(problem, solution) -> dict:
    """``rows_beyond_six``, ``unchecked`` (touch indices no other touch checks) and ``detectable_mm``
    (by touch index: the smallest error of it that the residual test finds, None when unchecked)."""
    J = solution.jacobian
    touches = problem.row_touch
    out = {"rows_beyond_six": int(len(J) - solution.rank), "unchecked": [],
           "detectable_mm": [None] * (int(touches.max()) + 1 if len(touches) else 0)}
    if solution.rank < 6:
        return out
    # Leverage from an orthonormal basis of the column space: stable where (J^T J)^-1 is not.
    basis = np.linalg.svd(J, full_matrices=False)[0][:, :6]
    # Each touch's largest leverage over its rows, the touches in the rows' order.
    largest = np.full(len(out["detectable_mm"]), -np.inf)
    np.maximum.at(largest, touches, np.sum(basis**2, axis=1))
    index, first = np.unique(touches, return_index=True)
    order = index[np.argsort(first)]
    r = np.clip(1.0 - largest[order], 0.0, 1.0)
    checked = r >= UNCHECKED_REDUNDANCY
    out["unchecked"] = order[~checked].tolist()
    for touch, mm in zip(order[checked].tolist(), (DETECTION_FACTOR * problem.sigma / np.sqrt(r[checked])).tolist()):
        out["detectable_mm"][touch] = mm
    return out
