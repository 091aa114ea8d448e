"""When the touches do not settle the pose: what explains an inconsistency, what separates candidates.

This module imports numpy only and nothing of fixturecad: it is
inlined into the generated standalone ``register.py``.
"""

import numpy as np

from .least_squares import levenberg_marquardt
from .patches import patch_points
from .problem import Problem
from .solve import solve
from .verdict import Solution, judged

def robust_flag(problem, solution):
    """A touch whose removal makes the touches consistent, found by a Cauchy-weighted refit.

    The robust (Cauchy) fit ranks the touches by residual; the worst are left
    out in turn. Returns (touch index, refit Solution, its distance mm from its feature at the
    refit pose) or None.
    """
    sigma = problem.sigma
    R, t = solution.rotation, solution.translation
    scale = 3.0 * sigma
    r = solution.residuals
    for _ in range(5):
        weights = 1.0 / (1.0 + (r / scale) ** 2)
        R, t, r, _ = levenberg_marquardt(problem, R, t, weights=weights, max_iterations=20)
    per_touch = {}
    for touch, value in zip(problem.row_touch, r):
        per_touch[int(touch)] = per_touch.get(int(touch), 0.0) + float(value) ** 2
    # Leave out the worst touches in turn and solve again from scratch.
    for touch in sorted(per_touch, key=lambda k: -per_touch[k]):
        reduced = problem.without(touch)
        if reduced.size <= 6:
            continue
        good = [s for s in solve(reduced) if s.passes and s.admissible and s.rank == 6]
        if good:
            # How far the touch is off at the refit pose (the robust fit's weights shrank its residual).
            rows, _ = problem.sensor_rows(good[0].rotation, good[0].translation)
            return touch, good[0], float(np.linalg.norm(rows[problem.row_touch == touch]))
    return None


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
                if refit.passes and refit.admissible and refit.rank == 6:
                    break
            else:
                continue
            delta = estimated_deviations(freed, tolerance, R, t)[tolerance.slices[fid]]
            departure = departure_mm(tolerance.features[fid], deviated(modes, delta))
            if departure > problem.tolerance.zone_mm / 2:
                found.append((fid, name, float(delta[k]), departure, refit))
    return sorted(found, key=lambda item: item[3])


SEPARATING_MARGIN_MM = 1.0  # a separating touch keeps this far inside its patch's edge under every candidate


def separating_touch(features, solutions):
    """The point touch that best tells the best candidate pose from all the others.

    Over points on every feature's finite patch (:func:`.patches.patch_points`:
    where the feature exists on the solid), the touch the best candidate
    predicts (``point_meas_mm``) is scored by how far it would lie off that
    feature under each other candidate; the smallest of these distances is
    maximised (``separation_mm``). Only points that lie over the patch, at
    least ``SEPARATING_MARGIN_MM`` inside its edge, under every candidate are
    offered: whichever pose is true, the probe meets the part there.
    """
    if len(solutions) < 2:
        return None
    a, others = solutions[0], solutions[1:]
    best = None
    for feature in features.values():
        try:
            pts = patch_points(feature)
        except ValueError:  # an empty or unbounded patch offers no touch
            continue
        meas = pts @ a.rotation.T + a.translation
        gap = np.full(len(pts), np.inf)
        over = np.asarray(feature.contains(pts, -SEPARATING_MARGIN_MM))
        for b in others:
            local_b = (meas - b.translation) @ b.rotation
            gap = np.minimum(gap, np.abs(feature.signed_distance(local_b)))
            over &= np.asarray(feature.contains(local_b, -SEPARATING_MARGIN_MM))
        gap = np.where(over, gap, -np.inf)
        k = int(np.argmax(gap))
        if np.isfinite(gap[k]) and (best is None or gap[k] > best["separation_mm"]):
            best = {
                "feature": feature.id,
                "point_fixture_mm": pts[k].tolist(),
                "point_meas_mm": meas[k].tolist(),
                "separation_mm": float(gap[k]),
            }
    return best
