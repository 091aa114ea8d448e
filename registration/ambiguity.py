"""When the touches do not settle the pose: what explains an inconsistency, what separates candidates.

This module imports numpy only and nothing of fixturecad: it is
inlined into the generated standalone ``register.py``.
"""

import numpy as np

from .least_squares import levenberg_marquardt, levenberg_marquardt_batch
from .patches import patch_points
from .pose import check_fixture2meas
from .problem import Problem
from .solve import Solutions, judged_all, local_starts
from .touches import point_touches
from .verdict import Solution, chi_square_passes, judged, same_as_any

SCREEN_STARTS = 4  # candidate poses of the whole set an explanation is looked for from, lowest cost first


def explanations(problem, features, solutions, initial_pose=None, told=()):
    """Every single touch whose removal, or whose move to another feature (a mislabelled touch), leaves
    touches that an admissible pose fits, with the poses it leads to.

    Each touch is left out in turn and the rest refined from a robust (Cauchy)
    fit of the whole set from its best candidate pose, which an outlier hardly
    pulls, and from the ``SCREEN_STARTS`` lowest-cost candidate poses
    (``solutions``). When no removal fits from these, an outlier far off
    may have pulled every candidate (and the robust fit) away: each touch is
    left out again and the rest solved from scratch (from ``initial_pose``
    when given). A point or ball touch whose removal explains it is also put
    on every other feature, refined from the poses its removal leads to (a
    label that fits implies a removal that does), but for the touches ``told``
    (indices), whose every feature a complete search tried already. Returns
    [(touch index, the feature it is moved to or None when left out, Solution
    passing the residual test at rank 6 with admissible touches, the touch's
    distance mm from its labelled feature at that pose)].
    """
    candidates = [(s.rotation, s.translation) for s in solutions[:SCREEN_STARTS]]
    starts = []
    for pose in [_robust_pose(problem, *candidates[0])] + candidates:
        if not same_as_any(pose, starts):
            starts.append(pose)
    touches = list(dict.fromkeys(int(k) for k in problem.row_touch))
    left_out = _left_out_fits(problem, touches, starts)
    if not any(left_out.values()):
        left_out = _fits_afresh(problem, touches, initial_pose)
    found = []
    for touch, fits in left_out.items():
        tries = [(None, fits)]
        group = next(g for g in problem.groups if touch in g.index)
        if fits and group.points is not None and touch not in told:
            poses = [(s.rotation, s.translation) for s in fits]
            tries += [(fid, _fits_from(_moved(problem.without(touch), group, feature, touch), poses))
                      for fid, feature in features.items() if fid != group.feature.id]
        for relabel, fitting in tries:
            for solution in fitting:
                rows, _ = problem.sensor_rows(solution.rotation, solution.translation)
                found.append((touch, relabel, solution, float(np.linalg.norm(rows[problem.row_touch == touch]))))
    return found


def _fits_afresh(problem, touches, initial_pose):
    """Every admissible rank-6 pose passing the residual test of the problem without each of ``touches``, solved
    from scratch as :func:`.solve.solve` does without its complete search (which would cost seconds for every
    touch left out): from the closed-form starts, or from ``initial_pose`` alone when given; every touch's starts
    refined at once. {touch: fits}."""
    reduced = {touch: problem.without(touch) for touch in touches}
    if initial_pose is not None:
        T = check_fixture2meas(initial_pose)
        starts = {touch: [(T[:3, :3], T[:3, 3])] for touch in touches}
    else:
        starts = {touch: local_starts(reduced[touch]) for touch in touches}
    left = np.concatenate([np.full(len(starts[touch]), touch, int) for touch in touches])
    if not len(left):
        return {touch: [] for touch in touches}
    Rs, ts, costs = levenberg_marquardt_batch(problem, np.array([R for touch in touches for R, _ in starts[touch]]),
                                              np.array([t for touch in touches for _, t in starts[touch]]), left)
    fits, first = {}, 0
    for touch in touches:
        k = range(first, first + len(starts[touch]))
        refined = [(Rs[i], ts[i], None, None, float(costs[i])) for i in k]
        fits[touch] = list(judged_all(reduced[touch], Solutions(), starts[touch], refined, good_only=True))
        first = k.stop
    return fits


def _robust_pose(problem, R, t, iterations=5):
    """(R, t) of a Cauchy-weighted fit from (R, t): a few touches far off hardly pull it."""
    r = problem.evaluate(R, t)[0]
    scale = 3.0 * problem.sigma
    for _ in range(iterations):
        R, t, r, _ = levenberg_marquardt(problem, R, t, weights=1.0 / (1.0 + (r / scale) ** 2), max_iterations=20)
    return R, t


def _fits_from(problem, starts):
    """The distinct admissible rank-6 poses passing the residual test refined from ``starts``."""
    return _left_out_fits(problem, [None], starts)[None]


def _left_out_fits(problem, touches, starts):
    """:func:`_fits_from` for the problem without each of ``touches`` (None: with every touch), all refined at
    once: {touch: fits}."""
    left = np.repeat([-1 if k is None else k for k in touches], len(starts))
    Rs, ts = (np.tile(np.array(x), (len(touches),) + (1,) * np.ndim(x[0])) for x in zip(*starts))
    Rs, ts, costs = levenberg_marquardt_batch(problem, Rs, ts, left)
    fits = {}
    for touch, poses in zip(touches, np.split(np.arange(len(left)), len(touches))):
        reduced = problem if touch is None else problem.without(touch)
        length, found = reduced.scale(), []
        for k in poses:
            if not chi_square_passes(costs[k], reduced.size, 6, reduced.sigma):
                continue  # (no rank passes it then: judged, it would not be good)
            r, J = reduced.evaluate(Rs[k], ts[k])
            solution = judged(reduced, Solution(Rs[k], ts[k], r, J), length)
            if solution.good and not same_as_any((Rs[k], ts[k]), [(s.rotation, s.translation) for s in found]):
                found.append(solution)
        fits[touch] = found
    return fits


def _moved(reduced, group, feature, touch):
    """``reduced`` (without ``touch``) with that touch of ``group`` put on ``feature`` instead."""
    k = int(np.flatnonzero(group.index == touch)[0])
    radius = float(np.reshape(group.sensor["r"], -1)[k]) if group.ctype.sensor == "S" else 0.0
    moved = point_touches(feature, group.points[k], [touch], radius)
    if group.approach is not None:
        moved.approach = group.approach[k:k + 1]
    return Problem(reduced.groups + [moved], reduced.sigma, reduced.lever, reduced.tolerance)


def features_beyond_tolerance(problem, solutions, starts=4):
    """Feature deviations beyond the tolerance that explain touches failing the residual test.

    Each mode of each touched feature is let free in turn
    (:meth:`FixtureTolerance.widened`) and the pose refitted from each of the
    best ``starts`` solutions; a mode is named when a refit passes. Returns [(feature id, mode name, its estimated
    coordinate mm or rad, the feature's departure from the drawing mm, refit
    Solution)] of the modes whose departure leaves the zone, the smallest first.
    """
    from .deviations import estimated_deviations
    from .tolerance import deviated, departure_mm

    found = []
    length = problem.scale()
    for fid in dict.fromkeys(g.feature.id for g in problem.groups):
        modes = problem.tolerance.modes[fid]
        for k, name in enumerate(modes.names):
            tolerance = problem.tolerance.widened(fid, k)
            freed = Problem(problem.groups, problem.sigma, problem.lever, tolerance)
            for solution in solutions[:starts]:
                R, t, r, J = levenberg_marquardt(freed, solution.rotation, solution.translation)
                refit = judged(freed, Solution(R, t, r, J), length)
                if refit.good:
                    break
            else:
                continue
            delta = estimated_deviations(freed, tolerance, R, t)[tolerance.slices[fid]]
            departure = departure_mm(tolerance.features[fid], deviated(modes, delta))
            if departure > problem.tolerance.zone_mm / 2:
                found.append((fid, name, float(delta[k]), departure, refit))
    return sorted(found, key=lambda item: item[3])


SEPARATING_MARGIN_MM = 1.0  # a separating touch keeps this far inside its patch's edge under every candidate
SEPARATION_LEAST_MM = 1e-6  # a touch that tells the candidates apart by less than this tells them apart by rounding


def separating_touch(features, solutions):
    """The point touch that tells every candidate pose from every other.

    Over points on every feature's finite patch (:func:`.patches.patch_points`:
    where the feature exists on the solid), the probe goes to where the best
    candidate predicts the point (``point_meas_mm``) and meets the part near
    the feature's closest point under whichever candidate is true; each such
    touch is scored by how far it lies off the feature under each other
    candidate, and the smallest of these distances, over every pair, is
    maximised (``separation_mm``). Only points that lie over the patch, at
    least ``SEPARATING_MARGIN_MM`` inside its edge, under every candidate are
    offered: whichever pose is true, the probe meets the part there. None when
    no such point separates them (two planes that the candidates turn onto
    each other at a right angle, and surfaces they turn onto themselves).
    """
    if len(solutions) < 2:
        return None
    a = solutions[0]
    best = None
    for feature in features.values():
        try:
            pts = patch_points(feature)
        except ValueError:  # an empty or unbounded patch offers no touch
            continue
        meas = pts @ a.rotation.T + a.translation
        over = np.ones(len(pts), bool)
        touched = []  # where the probe meets the part, measurement frame, under each candidate
        for b in solutions:
            local = (meas - b.translation) @ b.rotation
            over &= np.asarray(feature.contains(local, -SEPARATING_MARGIN_MM))
            touched.append(feature.closest_point(local) @ b.rotation.T + b.translation)
        gap = np.full(len(pts), np.inf)
        for i, point in enumerate(touched):
            for j, b in enumerate(solutions):
                if i != j:
                    gap = np.minimum(gap, np.abs(feature.signed_distance((point - b.translation) @ b.rotation)))
        gap = np.where(over, gap, -np.inf)
        k = int(np.argmax(gap))
        if np.isfinite(gap[k]) and (best is None or gap[k] > best["separation_mm"]):
            best = {
                "feature": feature.id,
                "point_fixture_mm": pts[k].tolist(),
                "point_meas_mm": meas[k].tolist(),
                "separation_mm": float(gap[k]),
            }
    return best if best is not None and best["separation_mm"] > SEPARATION_LEAST_MM else None
