"""Every distinct local solution from the starts, best first.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .fits import sphere_centre_candidates
from .least_squares import MAX_ITERATIONS, levenberg_marquardt
from .pose import check_fixture2meas, vector_from_rotation
from .starts import best_starts, initial_poses
from .search import leaf_starts, translation_starts
from .verdict import (CHI2_CONFIDENCE, SAME_POSE_CHI2, SAME_POSE_TRANSLATION_MM, Solution, chi_square_quantile, judged,
                      same_pose)

LEAF_ITERATIONS = 20  # LM iterations from a refined leaf of the complete search
REFINED_WHEN_NONE_PASS = 3  # candidates refined with the part's deviations when none passes as noise

def solve(problem, initial_pose=None, batch=6, complete=True):
    """All distinct local solutions from the starts, best first (:class:`Solutions`).

    Starts are refined ``batch`` at a time, best predicted first, until one
    batch yields an admissible solution that passes the residual test.
    ``complete``: without a nominal pose, look for every pose that passes
    (:mod:`.search`), where it applies; else the closed-form starts only. On a
    printed part the search runs on the touches alone, the part's deviations
    taken as independent noise (much cheaper rows), and each pose found is
    then refined and judged with them.
    """
    if problem.tolerance is None:
        return _search(problem, initial_pose, batch, complete)
    length = problem.scale()
    found = _search(problem.as_noise(), initial_pose, batch, complete)
    solutions = Solutions()
    solutions.complete = found.complete
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


class Solutions(list):
    """Solutions best first; ``complete``: found by the certified search (:mod:`.search`), so that no pose
    that passes is missing from them."""

    complete = False


def _search(problem, initial_pose, batch, complete):
    far = False
    threshold = problem.sigma**2 * chi_square_quantile(CHI2_CONFIDENCE, max(problem.size - 6, 1))  # cost, mm^2
    if initial_pose is not None:
        complete = False
        T = check_fixture2meas(initial_pose)
        starts, first_batch = [(T[:3, :3], T[:3, 3])], 1
    else:
        starts = leaf_starts(problem, threshold) if complete else None
        complete = starts is not None
        if complete:
            first_batch = len(starts)
        if not starts:  # not certified, or no pose passes: the best fits, for what the verdict says of them
            found = initial_poses(problem)
            starts, first_batch = best_starts(problem, found)
            far = found.far
    length = problem.scale()
    solutions = Solutions()
    solutions.complete = complete
    # The first batch holds every local minimum of the sweep (every leaf): all solutions are looked for.
    bounds = [0, max(first_batch, 1)]
    while bounds[-1] < len(starts):
        bounds.append(bounds[-1] + batch)
    for first, last in zip(bounds[:-1], bounds[1:]):
        for R, t in starts[first:last]:
            known = [(s.rotation, s.translation) for s in solutions]
            # Far starts (no sweep) may take many slow steps: never abandon them. Leaves come refined: a
            # few steps finish them (more only creep along a weak pose's valley).
            R, t, r, J = levenberg_marquardt(problem, R, t, known=known, may_give_up=not far,
                                             max_iterations=LEAF_ITERATIONS if complete else MAX_ITERATIONS)
            if any(same_pose((R, t), pose) for pose in known):
                continue
            solutions.append(judged(problem, Solution(R, t, r, J), length))
            if solutions[-1].passes and solutions[-1].admissible and solutions[-1].weak:
                break  # a pose that passes but is too weak to claim: the verdict is underdetermined
        if any(s.passes and s.admissible for s in solutions):
            break
    weak = any(s.passes and s.admissible and s.weak for s in solutions)
    if not complete and initial_pose is None and not weak:
        # Poses that share a found pose's rotation: the one search a local search can afford everywhere.
        for found in [s for s in solutions if s.passes and s.admissible]:
            for t in translation_starts(problem, found.rotation, found.translation, threshold):
                known = [(s.rotation, s.translation) for s in solutions]
                R, t, r, J = levenberg_marquardt(problem, found.rotation, t, known=known)
                if not any(same_pose((R, t), pose) for pose in known):
                    solutions.append(judged(problem, Solution(R, t, r, J), length))
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
    return _told_apart(solutions, problem.sigma)


def _told_apart(solutions, sigma):
    """The solutions less those that pass but lie inside a better passing one's confidence region: a flat
    valley's minima are one pose with its uncertainty, not several."""
    kept = Solutions()
    kept.complete = solutions.complete
    for s in solutions:
        if s.passes and s.admissible and s.rank == 6 and any(
                k.passes and k.admissible and k.rank == 6 and _mahalanobis(k, s, sigma) < SAME_POSE_CHI2
                for k in kept):
            continue
        kept.append(s)
    return kept


def _mahalanobis(a, b, sigma):
    """The squared Mahalanobis distance of pose b from pose a under a's information."""
    E = b.rotation @ a.rotation.T
    d = np.concatenate([vector_from_rotation(E), b.translation - E @ a.translation])
    return float(d @ (a.jacobian.T @ a.jacobian) @ d) / sigma**2
