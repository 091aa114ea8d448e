"""Every pose the touches admit, refined and judged, best first.

Without a nominal pose the complete search (:mod:`.search`) gives one pose per
region of poses that may pass; each is refined by Levenberg-Marquardt on every
touch (the part's deviations included) and judged. Where the search cannot
complete, the closed-form starts (:mod:`.starts`) stand in, and the result
says so.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .least_squares import levenberg_marquardt, levenberg_marquardt_batch
from .pose import check_fixture2meas
from .search import mahalanobis, search, threshold_mm2
from .starts import best_starts, initial_poses
from .verdict import (EXTENT_TOLERANCE_MM, EXTENT_WIDENING_MAX_MM, SAME_POSE_CHI2, Solution, chi_square_passes,
                      inadmissible, judged, same_as_which)

LOCAL_STARTS = 96  # closed-form starts refined when the search does not complete


class Solutions(list):
    """Solutions best first, and how they were looked for: ``search`` is ``complete`` (every pose that
    passes lies within ``extent_mm`` of one of them), ``nominal`` (from the nominal pose given), ``local``
    (from the closed-form starts, asked for) or ``incomplete`` (the search stopped: ``reason``);
    ``cells``: the search's cells kept per level."""

    search = "local"
    reason = ""
    extent_mm = None
    cells = ()

    @property
    def complete(self):
        return self.search == "complete"


def solve(problem, initial_pose=None, complete=True, found=None, good_only=False):
    """All distinct solutions, best first (:class:`Solutions`).

    ``initial_pose``: refine from it only. ``complete``: without a nominal pose, search every pose that
    passes (:mod:`.search`; ``found``: its :class:`.search.Regions`, searched already); else refine the
    closed-form starts only (the explanations' quick refits). ``good_only``: only the good solutions (the
    others are not judged).
    """
    solutions = Solutions()
    starts, extents, weak = [], [], None
    if initial_pose is not None:
        T = check_fixture2meas(initial_pose)
        starts, solutions.search = [(T[:3, :3], T[:3, 3])], "nominal"
    elif complete:
        found = search(problem, threshold_mm2(problem), _weak_stop(problem)) if found is None else found
        starts, extents, solutions.cells = found.poses, found.extents_mm, found.cells
        solutions.search = "complete" if found.complete else "incomplete"
        solutions.reason = found.reason
        weak = found.weak
        if weak is not None:
            solutions.append(weak)  # the pose the search stopped at, refined and judged: the answer stands on it
    if initial_pose is None and weak is None and not (solutions.complete and starts):
        # The closed-form starts: where the search did not complete, or found that no pose passes (then the
        # best fits, for what the verdict says of them).
        starts = starts + local_starts(problem)
    # Every start refined, at once where there are several (one alone is refined on its own: cheaper, and it gives
    # its rows).
    if len(starts) < 2:
        refined = [(R2, t2, r, J, float(r @ r))
                   for R2, t2, r, J in (levenberg_marquardt(problem, R, t) for R, t in starts)]
    else:
        refined = [(R2, t2, None, None, cost)
                   for R2, t2, cost in zip(*levenberg_marquardt_batch(problem, *map(np.array, zip(*starts))))]
    return judged_all(problem, solutions, starts, refined, extents, found, good_only)


def local_starts(problem):
    """The closed-form starts (:mod:`.starts`) refined when there is no complete search: (R, t) pairs."""
    return best_starts(problem, initial_poses(problem))[0][:LOCAL_STARTS]


def judged_all(problem, solutions, starts, refined, extents=(), found=None, good_only=False):
    """:func:`solve`'s answer from its ``starts`` and their refinements ``refined`` ((R, t, rows or None,
    Jacobian or None, cost) each), taken in order (a pose refined already is one solution), added to
    ``solutions`` (:class:`Solutions`); ``extents`` (mm): the first starts' regions' of the complete search
    ``found``."""
    length = problem.scale()
    reach = []
    # The touches a region's extent follows, point and ball touches: one of them off its patch by more than the
    # region reaches shows that no pose of it is admissible. (Only where there are regions: not on a nominal pose.)
    followed = problem.point_touches() if extents else None
    for k, ((R, t), (R2, t2, r, J, cost)) in enumerate(zip(starts, refined)):
        if good_only and not chi_square_passes(cost, problem.size, 6, problem.sigma):
            continue  # (it fails the test at rank 6: not good at any rank)
        listed = same_as_which((R2, t2), [(s.rotation, s.translation) for s in solutions])
        if listed is None:
            if r is None:
                r, J = problem.evaluate(R2, t2)
            solutions.append(judged(problem, Solution(R2, t2, r, J), length))
        solution = solutions[-1 if listed is None else listed]
        if k < len(extents):
            # A region refined to a pose listed already reaches about that pose: it widens that pose's judgement.
            wide, region_reach = _wide(problem, followed, extents[k], (R, t), (R2, t2))
            solution.wide |= wide
            reach.append(region_reach)
    if good_only:
        solutions[:] = [s for s in solutions if s.good]
    solutions.sort(key=lambda s: (not (s.passes and s.admissible), s.cost))
    if solutions.complete and not extents and any(s.good for s in solutions):
        # The search left no region, yet a start's pose passes: the search missed it, and may have missed more.
        solutions.search, solutions.reason = "incomplete", "a pose passes that the search did not find"
    if solutions.complete:
        solutions.extent_mm = max(reach, default=0.0)
        if found.left and any(s.wide for s in solutions):
            # The region leaves out some sensors' rows: they may fix the pose within it, or leave two poses
            # there; the search cannot tell which, so it claims neither (exit 6, not underdetermined).
            solutions.search = "incomplete"
            solutions.reason = (f"{found.left} sensor touch{'es' if found.left > 1 else ''} not searched in full, and "
                                f"the rest leave a region {solutions.extent_mm:.2f} mm wide")
            for s in solutions:
                s.wide = False
    return told_apart(solutions, problem.sigma)


def _weak_stop(problem):
    """The search's ``stop``: the :class:`.verdict.Solution` refined from (R, t) when it passes, on its patches,
    but with rank under 6 or too weakly determined to judge (the verdict's ``weak``), or, given the ``extent_mm``
    of a settled region about (R, t), when that region is wide (:func:`_wide`); else None. One such pose makes the
    answer underdetermined (:func:`.engine.register_touches`), whatever else passes: no further search can change
    it."""
    def stop(R, t, extent_mm=None):
        R2, t2, r, J = levenberg_marquardt(problem, R, t)
        s = judged(problem, Solution(R2, t2, r, J), problem.scale())
        if extent_mm is not None:
            s.wide = _wide(problem, problem.point_touches(), extent_mm, (R, t), (R2, t2))[0]
        return s if s.passes and ((s.admissible and (s.rank < 6 or s.weak)) or s.wide) else None
    return stop


def _wide(problem, followed, extent_mm, start, pose):
    """Whether some pose of a region that may pass lies too far from ``pose`` to be judged by it: the region's
    reach about ``pose`` (its ``extent_mm`` about ``start``, where the search left it, and how far refinement moved
    the touches) beyond a patch's widening, unless ``pose`` puts a point or ball touch (of ``followed``) farther
    off its patch than the region reaches (then none is admissible); and that reach (mm)."""
    reach = extent_mm + _moved_mm(problem, start, pose)
    return reach > EXTENT_WIDENING_MAX_MM and not inadmissible(
        followed, *pose, tolerance=EXTENT_TOLERANCE_MM + EXTENT_WIDENING_MAX_MM + reach, approaches=False), reach


def _moved_mm(problem, a, b):
    """The largest distance (mm) between where poses a and b put the measured point touches on the fixture."""
    points = [g.points for g in problem.groups if g.points is not None]
    if not points:
        return 0.0
    p = np.concatenate(points)
    return float(np.max(np.linalg.norm((p - a[1]) @ a[0] - (p - b[1]) @ b[0], axis=1)))


def told_apart(solutions, sigma):
    """The solutions less those that pass but lie inside a better passing one's confidence region: a flat
    valley's minima are one pose with its uncertainty, not several."""
    kept = Solutions()
    for name in ("search", "reason", "extent_mm", "cells"):
        setattr(kept, name, getattr(solutions, name))

    def inside(k, s):  # whether s lies inside good k's confidence region
        return k.good and mahalanobis(k.rotation, k.translation, k.jacobian.T @ k.jacobian / sigma**2,
                                      s.rotation[None], s.translation[None])[0] < SAME_POSE_CHI2

    for s in solutions:
        same = next((k for k in kept if inside(k, s)), None) if s.good else None
        if same is None:
            kept.append(s)
        else:
            same.wide |= s.wide  # its region's poses lie about the pose it is
    return kept
