"""Touch plans designed on the Fisher information: where a point probe or a ball tip should touch.

Candidates are points of the surface features' finite patches, a margin in
from every patch edge (and reachable, :mod:`.reach`, when the caller has the
mesh). Each candidate touch is one row of the contact model (:mod:`.contacts`,
through :class:`.problem.Problem` at the nominal pose; a ball tip's touch is
its centre's, the radius out along the normal); a plan's information is
``J^T J / sigma^2``. The plan is grown greedily, the candidate that most
improves the criterion first, then improved by exchange (Fedorov): a planned
touch is swapped for a candidate while that helps.

Criteria, on the information with rotations scaled by the touch spread
(``length_mm``, so that rad and mm weigh alike):

* ``d``: the determinant (the volume of the confidence ellipsoid, the usual
  choice: invariant to units);
* ``a``: the trace of the covariance (the mean squared error);
* ``e``: the smallest eigenvalue (the worst direction).

The determinant leaves the split between the translation and the rotation
bound to chance: a D-optimal plan is then improved by swaps that lower one
bound and raise neither, and, given a reference plan (the fixture's default
plan), is never worse than it in either bound (see :func:`design`).

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py`` (the next touch of a registration).
"""

from dataclasses import dataclass

import numpy as np

from .mobility import RANK_TOLERANCE, matrix_rank
from .pose import skew
from .patches import patch_points
from .problem import Problem
from .touches import build_groups

CRITERIA = ("d", "a", "e")
DEFAULT_MARGIN_MM = 1.0  # from every patch edge, a point probe's (a ball's: its radius more)
CANDIDATES_PER_FEATURE = 160  # patch points kept per feature (evenly strided)
EXCHANGE_PASSES = 4
IMPROVE_PASSES = 20  # passes of swaps that lower a bound and raise neither
RIDGE = 1e-9  # relative regularisation while a plan is still rank-deficient


@dataclass
class Candidates:
    """Candidate touches: feature id, contact point (fixture frame, mm) and outward normal of each, and its
    row; a ball tip's touch is its centre's, ``ball_radius_mm`` out along the normal."""

    features: list
    points: np.ndarray
    normals: np.ndarray
    rows: np.ndarray  # (n, 6): each touch's row on twists at the nominal pose
    length_mm: float
    ball_radius_mm: float = 0.0

    @property
    def centres(self) -> np.ndarray:
        """The probe's point (a ball's centre) at each touch, (n, 3) mm, fixture frame."""
        return self.points + self.ball_radius_mm * self.normals


def candidate_points(features, ids, margin_mm, keep=None, also=None) -> dict:
    """Contact points by feature id, (n, 3) mm fixture frame: the patch points of the surface features
    ``ids`` at least ``margin_mm`` in (evenly strided), with the touches ``also`` ([(feature id, point)], e.g.
    a plan's) that lie that far in, all kept by ``keep``.

    ``keep``: optional predicate (points (n, 3), normals (n, 3)) -> bool (n,), e.g. reachability.
    Raises ValueError naming a feature whose patch holds no point that far in.
    """
    out = {}
    for fid in ids:
        feature = features[fid]
        if not feature.surface:
            raise ValueError(f"feature {fid} is a {feature.kind}: a probe touches planes, spheres and cylinders")
        p = patch_points(feature)
        p = p[feature.contains(p, tol_mm=-margin_mm)]  # at least margin_mm inside the patch
        p = p[::max(1, len(p) // CANDIDATES_PER_FEATURE)]
        q = np.array([point for f, point in also or () if f == fid], dtype=np.float64).reshape(-1, 3)
        p = np.vstack([p, q[feature.contains(q, tol_mm=-margin_mm)]])
        if keep is not None and len(p):
            p = p[keep(p, feature.normal_at(p))]
        if not len(p):
            raise ValueError(f"no reachable point of {fid} lies {margin_mm:g} mm inside its patch: lower --margin")
        out[fid] = p
    return out


def candidates(features, points, ball_radius_mm=0.0) -> Candidates:
    """Candidate touches at the contact points by feature id (:func:`candidate_points`), made by a point
    probe or a ball tip of radius ``ball_radius_mm``: their rows at the nominal pose."""
    normals = {fid: features[fid].normal_at(p) for fid, p in points.items()}
    flat = np.vstack(list(points.values()))
    spread = float(np.sqrt(np.mean(np.sum((flat - flat.mean(0)) ** 2, axis=1))))
    rows = _rows(features, {fid: p + ball_radius_mm * normals[fid] for fid, p in points.items()}, ball_radius_mm)
    return Candidates([fid for fid, p in points.items() for _ in p], flat, np.vstack(list(normals.values())), rows,
                      max(spread, 1.0), ball_radius_mm)


def _rows(features, centres, ball_radius_mm=0.0, rotation=np.eye(3), translation=np.zeros(3)) -> np.ndarray:
    """Each touch's row (n, 6) at a pose, in the order of ``centres`` (dict id -> (k, 3), fixture frame)."""
    problem = Problem(build_groups(features, {fid: c @ rotation.T + translation for fid, c in centres.items()},
                                   ball_radius_mm))
    _, J = problem.evaluate(rotation, translation)
    # Touches are numbered in the candidates' order; rows come by contact type: one row each, put back in order.
    return J[np.argsort(problem.row_touch, kind="stable")]


def indices(cands, touches):
    """Candidate indices of touches [(feature id, contact point (3,))], None unless every one is a candidate."""
    found = []
    for fid, point in touches:
        match = np.flatnonzero(np.all(cands.points == np.asarray(point, dtype=np.float64), axis=1) &
                               (np.array(cands.features) == fid))
        if not len(match):
            return None
        found.append(int(match[0]))
    return found


def candidate_record(points, margin_mm) -> dict:
    """features.json's ``touch_candidates``: the reachable point-probe touches the next touch is chosen among."""
    return {"margin_mm": float(margin_mm), "points": {fid: p.tolist() for fid, p in points.items()}}


def stored_candidates(document):
    """The contact points by feature id of a features.json document's ``touch_candidates`` (None: absent)."""
    record = document.get("touch_candidates")
    return None if record is None else {fid: np.array(p, dtype=np.float64) for fid, p in record["points"].items()}


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


def design(cands: Candidates, count, criterion="d", point=None, reference=None) -> list:
    """Indices of ``count`` candidates chosen to maximise the criterion (``point``: the position error of that
    point of interest (3,), mm, fixture frame); ValueError if they cannot locate.

    From seven touches on, the plan survives the loss of any one touch when it can (:func:`robust`). With
    criterion ``d``, the plan is then improved by swaps that lower its translation or rotation bound and
    raise neither. Given ``reference`` (the candidate indices of a plan of ``count`` touches, e.g. the
    default plan's), the plan returned is no worse than the reference in either bound: of the designed plan
    and the reference improved by such swaps (better than the reference in at least one bound unless no
    single swap improves it), the one of larger determinant among those no worse, a robust one first.
    """
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
    if criterion != "d":
        return chosen
    chosen = _improve(outer, chosen, cands)
    if reference is None:
        return chosen
    limit = _bounds(outer[reference].sum(0))
    plans = [p for p in (chosen, _improve(outer, reference, cands)) if np.all(_bounds(outer[p].sum(0)) <= limit)]
    return max(plans, key=lambda p: (count <= 6 or robust(cands.rows[p], cands.length_mm),
                                     float(criterion_values(outer[p].sum(0), "d"))))


def _bounds(information) -> np.ndarray:
    """(translation, rotation) variance traces (..., 2) of (scaled) informations (..., 6, 6): the squared
    bounds up to units; inf where the information has rank below 6."""
    eigen = np.linalg.eigvalsh(information)
    ok = eigen[..., 0] > RANK_TOLERANCE**2 * eigen[..., -1]
    out = np.full(information.shape[:-2] + (2,), np.inf)
    covariance = np.linalg.inv(information[ok])
    out[ok] = np.stack([np.trace(covariance[..., 3:, 3:], axis1=-2, axis2=-1),
                        np.trace(covariance[..., :3, :3], axis1=-2, axis2=-1)], axis=-1)
    return out


def _improve(outer, chosen, cands):
    """Swaps that lower the translation or the rotation bound and raise neither, the one of largest
    determinant first, while any helps; a plan every touch of which is checked by the others stays so."""
    chosen = list(chosen)
    checked = len(chosen) > 6 and robust(cands.rows[chosen], cands.length_mm)
    information = outer[chosen].sum(0)
    for _ in range(IMPROVE_PASSES):
        improved = False
        for slot in range(len(chosen)):
            now = _bounds(information)
            trial = information - outer[chosen[slot]] + outer
            bounds = _bounds(trial)
            better = np.all(bounds <= now, axis=1) & np.any(bounds < now * (1 - 1e-9), axis=1)
            better[chosen] = False
            values = np.where(better, criterion_values(trial, "d"), -np.inf)
            for k in np.argsort(-values)[:int(better.sum())]:
                plan = chosen[:slot] + [int(k)] + chosen[slot + 1:]
                if not checked or robust(cands.rows[plan], cands.length_mm):
                    chosen, information, improved = plan, trial[k], True
                    break
        if not improved:
            break
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


def next_touches(features, solution, points, count=1):
    """The ``count`` point-probe touches, chosen one after another among the candidate contact points
    (dict id -> (n, 3), fixture frame: features.json's ``touch_candidates``, reachable), that most raise the
    determinant of the information the solution's touches already give (a free motion removed first when
    there is one).

    Returns [(candidate index, feature id, point fixture frame (3,), outward normal fixture frame (3,))] and
    the information after each, (count, 6, 6), scaled rotations per the candidates' spread.
    """
    cands = candidates(features, points)
    rows = _rows(features, points, 0.0, solution.rotation, solution.translation)
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
