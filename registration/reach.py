"""Which touches a probe can reach: its path out along the surface normal, tested against the fixture's mesh.

A point probe's path is the ray from the touched point outwards; a ball tip's
is the ball swept from its centre (``radius_mm`` out along the normal) to
infinity, which no triangle may come nearer than the radius. The planner
(:mod:`.planning`) keeps only reachable candidates; the build stores the
reachable point-probe candidates in features.json, so that the standalone
``register.py`` (which has no mesh) plans among the same touches.

This module imports numpy only.
"""

import numpy as np

from .elements import cross

CHUNK = 64  # touches tested at once (memory: touches x nearby triangles)


def reachable(triangles, points, normals, radius_mm=0.0, clearance_mm=0.0) -> np.ndarray:
    """Whether a probe coming along the outward unit ``normals`` (n, 3) reaches each surface point (n, 3)
    without passing through the solid, whose mesh is ``triangles`` (m, 3, 3), mm.

    A point probe (``radius_mm`` 0): the ray from just off the surface meets no triangle. A ball tip of
    radius ``radius_mm``: no triangle comes nearer its swept path than the radius less ``clearance_mm``
    (the mesh's chord error: a triangle may stand that far off the true surface the ball rests on).
    """
    triangles, points, normals = (np.asarray(a, dtype=np.float64) for a in (triangles, points, normals))
    a, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    centres = triangles.mean(axis=1)
    radii = np.linalg.norm(triangles - centres[:, None], axis=2).max(axis=1)
    scale = float(np.ptp(triangles.reshape(-1, 3), axis=0).max())
    # A point probe's ray starts just off the surface, so as not to meet the triangles it touches.
    lift = radius_mm if radius_mm > 0 else 1e-3 * scale
    reach = max(radius_mm - clearance_mm, 0.0)
    out = np.ones(len(points), bool)
    for start in range(0, len(points), CHUNK):
        o = points[start:start + CHUNK] + lift * normals[start:start + CHUNK]
        d = normals[start:start + CHUNK]
        rel = centres[None] - o[:, None]
        along = np.einsum("ntj,nj->nt", rel, d)
        near = (along > -radii - radius_mm) & (
            np.einsum("ntj,ntj->nt", rel, rel) - along**2 < (radii + radius_mm) ** 2)
        ray, tri = np.nonzero(near)
        blocked = _crossing(o[ray], d[ray], a[tri], e1[tri], e2[tri])
        if radius_mm > 0:
            blocked |= _path_distance(o[ray], d[ray], triangles[tri], 4.0 * scale) < reach
        out[start:start + CHUNK] = np.bincount(ray[blocked], minlength=len(o)) == 0
    return out


def _crossing(o, d, a, e1, e2) -> np.ndarray:
    """Whether each ray o + t d (t > 0) crosses its triangle (a, a + e1, a + e2): Moller-Trumbore."""
    p = cross(d, e2)
    det = np.einsum("kj,kj->k", e1, p)
    ok = np.abs(det) > 1e-12
    det = np.where(ok, det, 1.0)
    s = o - a
    u = np.einsum("kj,kj->k", s, p) / det
    q = cross(s, e1)
    v = np.einsum("kj,kj->k", d, q) / det
    t = np.einsum("kj,kj->k", e2, q) / det
    return ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)


def _path_distance(o, d, triangles, length_mm) -> np.ndarray:
    """Distance from each segment o + t d, t in [0, length_mm], to its triangle (k, 3, 3) when they do not
    cross: the nearer of the start point to the triangle and the segment to the triangle's edges."""
    end = o + length_mm * d
    edges = [(triangles[:, i], triangles[:, (i + 1) % 3]) for i in range(3)]
    best = np.min([_segments(o, end, p, q) for p, q in edges], axis=0)
    # The start point's foot on the triangle's plane, when it falls inside the triangle.
    a, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    n = cross(e1, e2)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    height = np.einsum("kj,kj->k", o - a, n)
    foot = o - height[:, None] * n - a
    g11, g12, g22 = (np.einsum("kj,kj->k", x, y) for x, y in ((e1, e1), (e1, e2), (e2, e2)))
    r1, r2 = np.einsum("kj,kj->k", foot, e1), np.einsum("kj,kj->k", foot, e2)
    det = np.maximum(g11 * g22 - g12**2, 1e-300)
    u, v = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det
    inside = (u >= 0) & (v >= 0) & (u + v <= 1)
    return np.where(inside, np.minimum(best, np.abs(height)), best)


def _segments(p1, q1, p2, q2) -> np.ndarray:
    """Distances (k,) between segments p1-q1 and p2-q2 (k, 3), the closest points clamped to both."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = np.einsum("kj,kj->k", d1, d1), np.einsum("kj,kj->k", d2, d2)
    b, c, f = np.einsum("kj,kj->k", d1, d2), np.einsum("kj,kj->k", d1, r), np.einsum("kj,kj->k", d2, r)
    denom = a * e - b * b
    s = np.where(denom > 1e-12 * a * e, np.clip((b * f - c * e) / np.maximum(denom, 1e-300), 0, 1), 0.0)
    t = (b * s + f) / np.maximum(e, 1e-300)
    # t outside [0, 1]: clamp it and recompute s for that end of the second segment.
    s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    t = np.clip(t, 0, 1)
    return np.linalg.norm(p1 + s[:, None] * d1 - p2 - t[:, None] * d2, axis=1)
