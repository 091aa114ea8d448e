"""Touch plans designed on the Fisher information: where a point probe should touch.

Candidates are points of the surface features' finite patches, a margin in
from every patch edge. Each candidate touch is one row of the contact model
(:mod:`.contacts`, through :class:`.problem.Problem` at the nominal pose);
a plan's information is ``J^T J / sigma^2``. The plan is grown greedily, the
candidate that most improves the criterion first, then improved by exchange
(Fedorov): a planned touch is swapped for a candidate while that helps.

Criteria, on the information with rotations scaled by the touch spread
(``length_mm``, so that rad and mm weigh alike):

* ``d``: the determinant (the volume of the confidence ellipsoid, the usual
  choice: invariant to units);
* ``a``: the trace of the covariance (the mean squared error);
* ``e``: the smallest eigenvalue (the worst direction).

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py`` (the next touch of a registration).
"""

from dataclasses import dataclass

import numpy as np

from .mobility import matrix_rank
from .pose import skew
from .patches import patch_points
from .problem import Problem
from .touches import build_groups

CRITERIA = ("d", "a", "e")
CANDIDATES_PER_FEATURE = 160  # patch points kept per feature (evenly strided)
EXCHANGE_PASSES = 4
RIDGE = 1e-9  # relative regularisation while a plan is still rank-deficient


@dataclass
class Candidates:
    """Candidate touches: feature id, point (fixture frame, mm) and outward normal of each, and its row."""

    features: list
    points: np.ndarray
    normals: np.ndarray
    rows: np.ndarray  # (n, 6): each touch's row on twists at the nominal pose
    length_mm: float


def candidates(features, ids, margin_mm, keep=None) -> Candidates:
    """Candidate touches on the patches of the surface features ``ids``, at least ``margin_mm`` in.

    ``keep``: optional predicate (points (n, 3), normals (n, 3)) -> bool (n,), e.g. reachability.
    Raises ValueError naming a feature whose patch holds no point that far in.
    """
    names, points, normals = [], [], []
    for fid in ids:
        feature = features[fid]
        if feature.kind not in ("plane", "sphere", "cylinder"):
            raise ValueError(f"feature {fid} is a {feature.kind}: a point probe touches planes, spheres and cylinders")
        p = patch_points(feature)
        p = p[feature.contains(p, tol_mm=-margin_mm)]  # at least margin_mm inside the patch
        p = p[::max(1, len(p) // CANDIDATES_PER_FEATURE)]
        n = feature.normal_at(p) if len(p) else np.zeros((0, 3))
        if keep is not None and len(p):
            ok = keep(p, n)
            p, n = p[ok], n[ok]
        if not len(p):
            raise ValueError(f"no reachable point of {fid} lies {margin_mm:g} mm inside its patch: lower --margin")
        names += [fid] * len(p)
        points.append(p)
        normals.append(n)
    points, normals = np.vstack(points), np.vstack(normals)
    touches = {}
    for fid, point in zip(names, points):
        touches.setdefault(fid, []).append(point)
    problem = Problem(build_groups(features, {k: np.array(v) for k, v in touches.items()}))
    _, J = problem.evaluate(np.eye(3), np.zeros(3))
    # Touches are numbered in the candidates' order; rows come by contact type: one row each, put back in order.
    J = J[np.argsort(problem.row_touch, kind="stable")]
    spread = float(np.sqrt(np.mean(np.sum((points - points.mean(0)) ** 2, axis=1))))
    return Candidates(names, points, normals, J, max(spread, 1.0))


def criterion_values(information, criterion, weight=None) -> np.ndarray:
    """The value to maximise of each information matrix (..., 6, 6); ``point``: minus the variance of a point's
    position, ``weight`` (3, 6) its displacement per (scaled) twist."""
    if criterion == "point":
        eigen = np.linalg.eigvalsh(information)
        variance = np.trace(weight @ np.linalg.pinv(information) @ weight.T, axis1=-2, axis2=-1)
        return np.where(eigen[..., 0] > 1e-12 * np.maximum(eigen[..., -1], 1e-300), -variance, -np.inf)
    if criterion == "d":
        sign, logdet = np.linalg.slogdet(information)
        return np.where(sign > 0, logdet, -np.inf)
    eigen = np.linalg.eigvalsh(information)
    if criterion == "e":
        return eigen[..., 0]
    return np.where(eigen[..., 0] > 0, -np.sum(1.0 / np.maximum(eigen, 1e-300), axis=-1), -np.inf)


def design(cands: Candidates, count, criterion="d", point=None) -> list:
    """Indices of ``count`` candidates chosen to maximise the criterion (``point``: the position error of that
    point of interest (3,), mm, fixture frame); ValueError if they cannot locate."""
    if criterion not in CRITERIA + ("point",):
        raise ValueError(f"unknown criterion {criterion!r}; choose from {', '.join(CRITERIA)} or point:X,Y,Z")
    scale = np.r_[np.full(3, 1.0 / cands.length_mm), np.ones(3)]  # rotations per touch spread
    rows = cands.rows * scale
    # A point x moves by omega x x + v under a twist: in scaled twists, by [-[x]x L, I].
    weight = None if point is None else np.hstack([-skew(point) / scale[:3], np.eye(3)])
    value = lambda F: criterion_values(F, criterion, weight)  # noqa: E731
    outer = np.einsum("ni,nj->nij", rows, rows)
    ridge = RIDGE * np.trace(outer.sum(0)) / 6 * np.eye(6)
    chosen = []
    information = np.zeros((6, 6))
    for _ in range(count):
        # While the plan is short of rank 6 the determinant is zero: grow the regularised one.
        values = (criterion_values(information + ridge + outer, "d") if len(chosen) < 6 else
                  value(information + outer))
        values[chosen] = -np.inf
        best = int(np.argmax(values))
        chosen.append(best)
        information = information + outer[best]
    for _ in range(EXCHANGE_PASSES):
        improved = False
        for slot in range(count):
            without = information - outer[chosen[slot]]
            values = value(without + outer)
            values[chosen] = -np.inf
            best = int(np.argmax(values))
            now = value(information)
            if values[best] > now + 1e-12 * abs(now):
                information = without + outer[best]
                chosen[slot] = best
                improved = True
        if not improved:
            break
    if matrix_rank(cands.rows[chosen], cands.length_mm) < 6:
        raise ValueError("these features cannot locate the part with point-probe touches: add features")
    if count > 6 and not robust(cands.rows[chosen], cands.length_mm):
        chosen = _robust_exchange(outer, chosen)
    return chosen


def _robust_exchange(outer, chosen):
    """Exchange for the worst case of losing one touch (the smallest determinant of the plan less any one
    touch), so that every touch is checked by the others when the count allows."""
    chosen = list(chosen)

    def worst(sets):  # (k, count) index sets -> the smallest log det over each set less one touch
        total = outer[sets].sum(axis=1)
        less = total[:, None] - outer[sets]
        return criterion_values(less, "d").min(axis=1)

    for _ in range(EXCHANGE_PASSES):
        improved = False
        for slot in range(len(chosen)):
            sets = np.repeat(np.array(chosen)[None], len(outer), axis=0)
            sets[:, slot] = np.arange(len(outer))
            values = worst(sets)
            values[chosen] = -np.inf
            best = int(np.argmax(values))
            if values[best] > worst(np.array([chosen]))[0]:
                chosen[slot] = best
                improved = True
        if not improved:
            break
    return chosen


def robust(rows, length_mm) -> bool:
    """Whether the plan keeps rank 6 when any one touch is lost."""
    return all(matrix_rank(np.delete(rows, k, axis=0), length_mm) == 6 for k in range(len(rows)))


def reachable(triangles, points, normals, chunk=64) -> np.ndarray:
    """Whether a probe coming along the outward normal reaches each point without passing through the
    solid: the ray from just off the surface outwards meets no triangle (n, 3, 3) of the mesh, mm.
    Triangles near each ray (by their bounding spheres) are tested by Moller-Trumbore."""
    a, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    centres = triangles.mean(axis=1)
    radii = np.linalg.norm(triangles - centres[:, None], axis=2).max(axis=1)
    scale = float(np.ptp(triangles.reshape(-1, 3), axis=0).max())
    out = np.ones(len(points), bool)
    for start in range(0, len(points), chunk):
        o = points[start:start + chunk] + 1e-3 * scale * normals[start:start + chunk]
        d = normals[start:start + chunk]
        rel = centres[None] - o[:, None]
        along = np.einsum("ntj,nj->nt", rel, d)
        near = (along > -radii) & (np.einsum("ntj,ntj->nt", rel, rel) - along**2 < radii**2)
        ray, tri = np.nonzero(near)
        dr = d[ray]
        p = np.cross(dr, e2[tri])
        det = np.einsum("kj,kj->k", e1[tri], p)
        ok = np.abs(det) > 1e-12
        ray, tri, dr, p, det = ray[ok], tri[ok], dr[ok], p[ok], det[ok]
        s = o[ray] - a[tri]
        u = np.einsum("kj,kj->k", s, p) / det
        q = np.cross(s, e1[tri])
        v = np.einsum("kj,kj->k", dr, q) / det
        t = np.einsum("kj,kj->k", e2[tri], q) / det
        hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        out[start:start + chunk] = np.bincount(ray[hit], minlength=len(o)) == 0
    return out


def _at_pose(features, cands, rotation, translation):
    """The candidates' rows at a solved pose, in the solution's twist coordinates."""
    touches = {}
    for fid, point in zip(cands.features, cands.points):
        touches.setdefault(fid, []).append(rotation @ point + translation)
    problem = Problem(build_groups(features, {k: np.array(v) for k, v in touches.items()}))
    _, J = problem.evaluate(rotation, translation)
    return J[np.argsort(problem.row_touch, kind="stable")]


def next_touches(features, solution, count=1, margin_mm=1.0):
    """The ``count`` point-probe touches, chosen one after another, that most raise the determinant of the
    information the solution's touches already give (a free motion removed first when there is one).

    Returns [(candidate index, feature id, point fixture frame (3,), outward normal fixture frame (3,))] and
    the information after each, (count, 6, 6), scaled rotations per the candidates' spread.
    """
    ids = [fid for fid, f in features.items() if f.kind in ("plane", "sphere", "cylinder")]
    cands = candidates(features, ids, margin_mm)
    rows = _at_pose(features, cands, solution.rotation, solution.translation)
    scale = np.r_[np.full(3, 1.0 / cands.length_mm), np.ones(3)]
    outer = np.einsum("ni,nj->nij", rows * scale, rows * scale)
    information = (solution.jacobian * scale).T @ (solution.jacobian * scale)
    ridge = RIDGE * np.trace(outer.sum(0)) / 6 * np.eye(6)
    chosen, after = [], []
    for _ in range(count):
        values = criterion_values(information + ridge + outer, "d")
        values[chosen] = -np.inf
        best = int(np.argmax(values))
        chosen.append(best)
        information = information + outer[best]
        after.append(information / np.outer(scale, scale))
    return [(k, cands.features[k], cands.points[k], cands.normals[k]) for k in chosen], np.array(after)
