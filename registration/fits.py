"""Closed forms: a plane's normal, a sphere's centre, the rigid motion between point sets.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .elements import cross

def plane_normal(points):
    """Closed form: unit normal of the plane through points (n >= 3), or None if collinear."""
    centred = points - points.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    if len(s) < 3 or s[1] < 1e-6 * max(s[0], 1e-12) or s[1] < 1e-6:
        return None
    return vt[2]


def sphere_centres(points, radius):
    """Closed form: candidate centres of a sphere of known radius through points (n >= 3)."""
    points = np.asarray(points, float)
    if len(points) >= 4:
        A = np.hstack([2.0 * points, np.ones((len(points), 1))])
        b = np.sum(points**2, axis=1)
        sol, _, rank, _ = np.linalg.lstsq(A, b, rcond=None)
        if rank == 4:
            return [sol[:3]]
    a, b, c = points[:3]
    n = cross(b - a, c - a)
    if np.linalg.norm(n) < 1e-9:
        return []
    # Circumcentre of the three points, then up and down the normal to the radius.
    ab, ac = b - a, c - a
    centre = a + (cross(n, ab) * (ac @ ac) + cross(ac, n) * (ab @ ab)) / (2.0 * (n @ n))
    rc = np.linalg.norm(centre - a)
    if rc > radius:
        return [centre]
    h = np.sqrt(radius**2 - rc**2)
    u = n / np.linalg.norm(n)
    return [centre + h * u, centre - h * u]


def kabsch(fixed_points, measured_points):
    """Closed form: the rotation and translation best mapping fixture points onto measured ones."""
    a, b = np.asarray(fixed_points, float), np.asarray(measured_points, float)
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    H = (a - ca).T @ (b - cb)
    U, S, Vt = np.linalg.svd(H)
    if S[1] < 1e-9 * max(S[0], 1e-300):
        return None, None
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cb - R @ ca


def frame_from(normal, axis):
    """Orthonormal frame (3, 3), columns: the normal, the axis made perpendicular to it, their cross."""
    second = axis - (axis @ normal) * normal
    second /= np.linalg.norm(second)
    return np.column_stack([normal, second, cross(normal, second)])


def combinations(lists, limit=16):
    combos = [[]]
    for options in lists:
        combos = [c + [o] for c in combos for o in options][:limit]
    return combos


def sphere_centre_candidates(point_groups):
    """(fixture centre, [measured centre candidates]) of touched spheres, best determined first."""
    out = []
    for g in point_groups:
        if g.feature.kind == "sphere" and g.count >= 3:
            radius = g.rho[0] if g.ctype.sensor == "S" else g.feature.radius
            candidates = sphere_centres(g.points, radius)
            if candidates:
                out.append((len(candidates), g.feature.center, candidates))
    out.sort(key=lambda item: item[0])
    return [(f, m) for _, f, m in out]
