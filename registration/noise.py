"""The sensor noise model: where a sensor's placement error turns, and the rows' whitening.

Every touch is made by a sensor element placed with a small random rigid
error about its contact point, a translation of standard deviation sigma (mm,
each axis) and a rotation of sigma / lever (rad, each axis; ``lever_mm``, by
default ``SENSOR_LEVER_MM``). A point probe or a ball tip is moved by the
translation only, so its rows keep the iid noise sigma. Moving the sensor by
a twist is moving the fixture by the opposite twist, so a touch's row
covariance is ``C = J S J^T`` with J its rows' fixture twist Jacobian and S
the placement covariance (:func:`row_whitening`). Rows are whitened touch by
touch and scaled back to mm (covariance sigma^2 I).

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .defaults import SENSOR_LEVER_MM
from .elements import cross, element


def placement_centre(kind, geometry, contact_point=None):
    """The point (..., 3) mm a sensor's placement error turns about: its contact point.

    A point probe's point or a ball tip's centre (turning about it moves
    nothing); otherwise the known contact point ``o``, the given
    ``contact_point``, or the sensor's own point (``q`` of a plane, ``p`` of a
    line or a cylinder).
    """
    if kind == "P" or (kind == "S" and "o" not in geometry):
        return geometry["c"]
    if "o" in geometry:
        return geometry["o"]
    if contact_point is not None:
        return np.asarray(contact_point, dtype=np.float64)
    return geometry[element(kind).anchor_key]


def row_whitening(jacobian, centres, lever_mm=SENSOR_LEVER_MM):
    """Per-touch whitening of the rows under the sensor noise model, shape (N, k, k).

    ``jacobian`` (N, k, 6): the rows' twist Jacobian of each touch (twists
    about the frame origin); ``centres`` (N, 3) mm: the sensor placement
    centres in the same frame. The placement error (translation sigma,
    rotation sigma / lever about the centre) is the twist ``A (dtheta, delta)``
    with ``A = [[I, 0], [skew(o), I]]``; the row covariance is
    ``sigma^2 (G G^T / lever^2 + J_v J_v^T)``, ``G = J_w + J_v skew(o)``. The
    whitening W = L^-1 (``C / sigma^2 = L L^T``) makes ``W r`` of covariance
    sigma^2 I; it does not depend on sigma.
    """
    J = np.asarray(jacobian, dtype=np.float64)
    o = np.broadcast_to(centres, (J.shape[0], 3))
    Jw, Jv = J[..., :3], J[..., 3:]
    # J_v skew(o): row j times skew(o) is o x j reversed, i.e. cross(j, o).
    G = Jw + cross(Jv, o[:, None, :])
    C = np.einsum("nki,nli->nkl", G, G) / lever_mm**2 + np.einsum("nki,nli->nkl", Jv, Jv)
    k = C.shape[-1]
    if k == 1:
        return 1.0 / np.sqrt(np.maximum(C, 1e-300))
    scale = np.maximum(np.einsum("nkk->n", C) / k, 1e-300)[:, None, None]
    L = np.linalg.cholesky(C + 1e-12 * scale * np.eye(k))
    return np.linalg.inv(L)


def is_point_sensor(side):
    """A point probe or a ball tip: only shifted by its placement error, its rows' gradients
    along it orthonormal, so :func:`row_whitening` is the identity and is skipped."""
    return side.kind == "P" or (side.kind == "S" and "o" not in side.geometry)


def whitened(values, jacobian, centres, lever_mm):
    """Rows (N, k) and Jacobian (N, k, 6) whitened touch by touch (:func:`row_whitening`)."""
    W = row_whitening(jacobian, centres, lever_mm)
    if W.shape[-1] == 1:
        return values * W[..., 0], jacobian * W
    return np.einsum("nkl,nl->nk", W, values), np.einsum("nkl,nlc->nkc", W, jacobian)
