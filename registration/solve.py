"""Every distinct local solution from the starts, best first.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .fits import sphere_centre_candidates
from .least_squares import levenberg_marquardt
from .pose import check_fixture2meas
from .starts import best_starts, initial_poses
from .verdict import SAME_POSE_TRANSLATION_MM, Solution, judged, same_pose

REFINED_WHEN_NONE_PASS = 3  # candidates refined with the part's deviations when none passes as noise

def solve(problem, initial_pose=None, batch=6):
    """All distinct local solutions from the starts, best first (list of Solution).

    Starts are refined ``batch`` at a time, best predicted first, until one
    batch yields an admissible solution that passes the residual test. On a
    printed part the search runs on the touches alone, the part's deviations
    taken as independent noise (much cheaper rows), and each pose found is
    then refined and judged with them.
    """
    if problem.tolerance is None:
        return _search(problem, initial_pose, batch)
    length = problem.scale()
    solutions = []
    found = _search(problem.as_noise(), initial_pose, batch)
    # Refine what may be a solution (the candidates that pass, or else the best few); judge the rest as they are.
    plausible = [s for s in found if s.passes] or found[:REFINED_WHEN_NONE_PASS]
    for candidate in found:
        known = [(s.rotation, s.translation) for s in solutions]
        R, t = candidate.rotation, candidate.translation
        if any(candidate is s for s in plausible):
            R, t, r, J = levenberg_marquardt(problem, R, t, known=known)
        else:
            r, J = problem.evaluate(R, t)
        if not any(same_pose((R, t), pose) for pose in known):
            solutions.append(judged(problem, Solution(R, t, r, J), length))
    solutions.sort(key=lambda s: (not (s.passes and s.admissible), s.cost))
    return solutions


def _search(problem, initial_pose, batch):
    far = False
    if initial_pose is not None:
        T = check_fixture2meas(initial_pose)
        starts, first_batch = [(T[:3, :3], T[:3, 3])], 1
    else:
        found = initial_poses(problem)
        starts, first_batch = best_starts(problem, found)
        far = found.far
    length = problem.scale()
    solutions = []
    # The first batch holds every local minimum of the sweep: all solutions are looked for.
    bounds = [0, max(first_batch, 1)]
    while bounds[-1] < len(starts):
        bounds.append(bounds[-1] + batch)
    for first, last in zip(bounds[:-1], bounds[1:]):
        for R, t in starts[first:last]:
            known = [(s.rotation, s.translation) for s in solutions]
            # Far starts (no sweep) may take many slow steps: never abandon them.
            R, t, r, J = levenberg_marquardt(problem, R, t, known=known, may_give_up=not far)
            if any(same_pose((R, t), pose) for pose in known):
                continue
            solutions.append(judged(problem, Solution(R, t, r, J), length))
        if any(s.passes and s.admissible for s in solutions):
            break
    # Closed-form alternatives: a sphere touched three times has two candidate
    # centres; re-seed each solution with the other one.
    point_groups = [g for g in problem.groups if g.points is not None]
    for f, ms in sphere_centre_candidates(point_groups):
        if len(ms) < 2:
            continue
        for found in [s for s in solutions if s.passes and s.admissible]:
            for m in ms:
                R, t = found.rotation, m - found.rotation @ f
                if np.linalg.norm(t - found.translation) < SAME_POSE_TRANSLATION_MM:
                    continue
                known = [(s.rotation, s.translation) for s in solutions]
                R, t, r, J = levenberg_marquardt(problem, R, t, known=known)
                if any(same_pose((R, t), pose) for pose in known):
                    continue
                solutions.append(judged(problem, Solution(R, t, r, J), length))
    solutions.sort(key=lambda s: (not (s.passes and s.admissible), s.cost))
    return solutions
