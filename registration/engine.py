"""Registration engine: the pose of a fixture from labelled touches.

The front door, :func:`register_touches`: touches become touch groups
(:mod:`.touches`) whose rows come from the contact model (:mod:`.contacts`),
whitened under the sensor noise model (:mod:`.noise`) and, on a printed part,
for the part's deviations from its drawing (:mod:`.deviations`), stacked
into one problem (:mod:`.problem`). Without a nominal pose, closed forms and
sweeps give starts (:mod:`.starts`); Levenberg-Marquardt refines each
(:mod:`.least_squares`, :mod:`.solve`); every distinct converged pose is
judged by a chi-square test and whether its touches could have happened
(:mod:`.verdict`). The result is

* ``unique``: one admissible pose passes;
* ``ambiguous``: several do, with the touch that best separates them
  (:mod:`.ambiguity`);
* ``inconsistent``: none does, with every touch whose removal (or other
  label) explains it and the pose it leads to, and the printed feature whose
  deviation does (:mod:`.ambiguity`); a pose only when one explanation gives one;
* ``underdetermined``: the touches leave motions free, named relative to the
  features (:mod:`.motions`);

with the covariance ``(J^T C^-1 J)^-1``, at the true pose the Cramer-Rao
bound of the noise model (:mod:`.uncertainty`). Covariances are over
(rotation vector rad, fixture origin mm), both in the measurement frame.

This module imports numpy only and nothing of fixturecad: it is
inlined into the generated standalone ``register.py``.
"""

import numpy as np

from .ambiguity import explanations, features_beyond_tolerance, separating_touch
from .least_squares import levenberg_marquardt
from .motions import free_motions
from .defaults import DEFAULT_SIGMA_MM, SENSOR_LEVER_MM
from .problem import Problem
from .planning import next_touches
from .redundancy import redundancy
from .solve import solve
from .touches import build_groups
from .unlabelled import (assigned, assigned_problem, check_unlabelled, faces_holding, nearest_assignment,
                         solve_unlabelled, surface_features)
from .uncertainty import covariance, covariance_from_information, sigmas
from .verdict import Solution, distinct, judged


def register_touches(features, touches, initial_pose=None, sigma_mm=DEFAULT_SIGMA_MM, ball_radius_mm=0.0,
                     contacts=(), approaches=None, lever_mm=SENSOR_LEVER_MM, tolerance=None, plan_next=False,
                     target_sigma=None, candidates=None, unlabelled=None, faces=None):
    """Register a fixture from touches, labelled or not; return the result dict (see module doc).

    Parameters
    ----------
    features : dict id -> feature
    touches : dict id -> array-like, shape (n, 3), mm, measurement frame
    initial_pose : array-like, shape (4, 4), optional nominal ``fixture2meas``: the pose is refined from it alone
        (unlabelled touches each on its nearest feature there, then at the pose refined, while that changes),
        unless the determined pose it leads to fails the test or leaves a touch off its patch (then every pose is
        searched, as without it)
    sigma_mm : float, sensor placement noise (mm, each axis) for the chi-square test and covariance
    ball_radius_mm : float, radius of a ball tip (0 for a point probe); touches are ball centres
    contacts : list of dict, touches of other contact types (see ``contact_touch``)
    approaches : dict id -> array-like, shape (n, 3), optional probe approach directions;
        a pose at which a probe would have touched a surface from inside is rejected
    lever_mm : float, sensor size: plane, line and fixed-surface sensors tilt by
        sigma_mm / lever_mm rad about their contact points (see the module doc)
    plan_next : bool, also give ``next_touch``: the touch that separates ambiguous candidates, or else the
        point-probe touch that most raises the determinant of the information (one that removes a free
        motion when the pose is underdetermined), :mod:`.planning`
    target_sigma : (mm, deg) or None, also say in ``target`` whether the pose's standard deviations
        (RMS translation, rotation) meet these and, if not, how many more planned touches are predicted to
        (``more_touches``, None beyond ``MAX_MORE_TOUCHES``)
    unlabelled : array-like, shape (n, 3), mm, measurement frame, optional: point touches (ball centres with a
        ball radius) on some plane, sphere or cylinder, not said which; numbered after the labelled touches and
        the contacts. Every pose that passes under some assignment of them is looked for (:mod:`.unlabelled`)
    faces : dict id -> feature, optional: every face of the part (features.json's ``faces``,
        :func:`.features.faces_from_json`): the unlabelled touches lie anywhere on the part, on one of these,
        instead of on the sensing surfaces
    candidates : dict id -> array-like, shape (n, 3), mm, fixture frame, optional: the reachable touches the
        next touch and the planned touches are chosen among (features.json's ``touch_candidates``,
        :func:`.planning.stored_candidates`); without them only a separating touch is named

    Returns
    -------
    dict with ``pose`` (4x4 nested list, fixture2meas; None when inconsistent and not explained by one touch
    or one printed feature leading to one pose), ``status`` ("unique",
    "ambiguous", "inconsistent" or "underdetermined"), ``rms_residual_mm``,
    ``solutions`` (each ``pose``, ``rms_residual_mm``, of the whitened rows; every admissible pose that
    passes the chi-square test, best first), ``covariance`` (6x6 over rotation
    vector rad and fixture origin mm, None when underdetermined),
    ``sigma_translation_mm``, ``sigma_rotation_deg``, ``free_motions`` (names),
    ``separating_touch`` (ambiguous: where one more touch tells the candidates
    apart), ``flagged`` (inconsistent: every touch whose removal, or whose
    ``relabel`` onto another feature, leaves touches an admissible pose fits,
    each with that ``pose``, its ``rms_residual_mm`` and the touch's
    ``residual_mm`` off its feature there), ``culprit`` (the touch index when
    only one touch explains it, else None), ``inadmissible`` (touches off their
    patch or touched from inside at ``pose``), ``touches``, ``rows``, ``rank``,
    ``redundancy`` (how well the touches check each other, :mod:`.redundancy`), ``assignment`` (with
    unlabelled touches: each one's ``touch``, ``feature`` and ``residual_mm`` at ``pose``, and on a face that
    features lie on, their ids, ``holds``; each of ``solutions`` has its own);
    with no pose, ``rms_residual_mm``, ``inadmissible``, ``rank`` and
    ``redundancy`` are those of the lowest-cost candidate.
    """
    groups = build_groups(features, touches, ball_radius_mm, contacts, approaches)
    points = check_unlabelled(unlabelled)
    index = np.arange(len(points)) + sum(g.count for g in groups)
    # What the unlabelled touches may lie on; the problems, verdicts and explanations know both (the planned
    # touches stay on the sensing features, among the candidates).
    surfaces = (surface_features(features) if faces is None else list(faces.values())) if len(points) else []
    planned, features = features, {**features, **(faces or {})}
    holds = faces_holding(faces, planned) if faces and len(points) else {}
    given = (groups, features, surfaces, points, index, ball_radius_mm, sigma_mm, lever_mm, tolerance)
    problem, solutions = _solved(*given, initial_pose)
    if initial_pose is not None and solutions[0].rank == 6 and not solutions[0].good:
        # The fit from the nominal pose fails the test or leaves a touch off its patch (a stale pose, or a minimum
        # beside the true one): every pose is searched instead, as without one, and ``search`` says so.
        initial_pose = None
        problem, solutions = _solved(*given, None)
    best = solutions[0]
    result = {"flagged": [], "culprit": None, "fixture_flagged": [], "free_motions": [], "separating_touch": None}
    good = [s for s in solutions if s.good]
    checked = None  # the answer judged with all touches, when it comes from a refit without one
    if best.rank < 6:
        status = "underdetermined"
        result["free_motions"] = free_motions(problem, best, features)
    elif any(s.weak for s in good) or any(s.wide and s.passes for s in solutions):
        # A pose that passes but too poorly determined to tell on which patch a touch lies, or a region of poses
        # that may pass wider than that, whatever its listed pose's rank or patches: no pose is claimed.
        status = "underdetermined"
        best = next(s for s in good + solutions if s.weak or (s.wide and s.passes))
        result["free_motions"] = free_motions(problem, best, features, weak=True)
    elif len(good) == 1:
        status = "unique"
        best = good[0]
    elif len(good) > 1:
        status = "ambiguous"
        best = good[0]
        result["separating_touch"] = separating_touch(planned, good)
    else:
        # Two kinds of explanation, both listed: a touch that is off or mislabelled, a feature printed beyond
        # its tolerance.
        off = features_beyond_tolerance(problem, solutions) if problem.tolerance is not None else []
        result["fixture_flagged"] = [{"feature": fid, "mode": mode, "deviation": value, "departure_mm": mm}
                                     for fid, mode, value, mm, _ in off]
        # Unlabelled touches that the complete search put on every feature: none is tried on another again.
        told = set(index.tolist()) if len(points) and initial_pose is None and solutions.search == "complete" else set()
        explained = explanations(problem, features, solutions, initial_pose, told=told)
        missed = _missed(problem, explained)
        if missed:
            # The search missed them: poses that fit every touch after all.
            status, best, good = "unique" if len(missed) == 1 else "ambiguous", missed[0], missed
            if len(missed) > 1:
                result["separating_touch"] = separating_touch(planned, missed)
        else:
            status = "inconsistent"
            feature_of = {int(i): g.feature.id for g in problem.groups for i in g.index}
            result["flagged"] = [{"touch": touch, "feature": feature_of[touch], "relabel": relabel,
                                  "residual_mm": size, "pose": s.fixture2meas.tolist(), "rms_residual_mm": s.rms}
                                 for touch, relabel, s, size in explained]
            culprits = {touch for touch, _, _, _ in explained}
            result["culprit"] = culprits.pop() if len(culprits) == 1 else None
            # The answer only when one touch explains it, leading to one pose (refitted without it, or else on
            # the feature it fits on), or else one printed feature's deviation; never a pose that fails the test.
            if result["culprit"] is not None:
                left_out = [s for _, relabel, s, _ in explained if relabel is None]
                good = distinct(left_out or [s for _, _, s, _ in explained])
            else:
                good = [] if explained else [item[-1] for item in off]
            best = good[0] if len(good) == 1 else None
            if best is not None:
                checked = Solution(best.rotation, best.translation, *problem.evaluate(best.rotation, best.translation),
                                   best.rank)
    answer = best if best is not None else solutions[0]  # with no answer, what is said of the lowest-cost pose
    for s in [answer, *good]:
        if s.assignment is None:  # refitted by the explanations, under the best pose's assignment
            s.assignment = solutions[0].assignment
    shown = (good or [best]) if best is not None else []
    cov = covariance(answer.jacobian, answer.translation, problem.sigma) if best is not None and answer.rank == 6 else None
    s_t, s_r = sigmas(cov)
    result.update(
        {
            "pose": None if best is None else best.fixture2meas.tolist(),
            "status": status,
            "inadmissible": sorted(answer.outside),
            "rms_residual_mm": answer.rms,
            "solutions": [{"pose": s.fixture2meas.tolist(), "rms_residual_mm": s.rms,
                           **({"assignment": assigned(features, s, points, index, ball_radius_mm, holds)}
                              if len(points) else {})}
                          for s in shown],
            "covariance": None if cov is None else cov.tolist(),
            "sigma_translation_mm": s_t,
            "sigma_rotation_deg": s_r,
            "touches": int(sum(g.count for g in problem.groups)),
            "rows": problem.size,
            "rank": answer.rank,
            "redundancy": redundancy(problem, checked or answer),
            "search": solutions.search,
            "search_reason": solutions.reason,
            "search_extent_mm": solutions.extent_mm,
        }
    )
    if len(points):
        result["assignment"] = assigned(features, answer, points, index, ball_radius_mm, holds)
    if best is None:
        return result  # no pose to plan the next touch or a target from
    if plan_next:
        result["next_touch"] = result["separating_touch"] or (
            None if candidates is None else _next_touch(planned, best, candidates))
    if target_sigma is not None:
        result["target"] = _target(planned, best, problem.sigma, target_sigma, (s_t, s_r), candidates)
    return result


REASSIGN_ROUNDS = 4  # fits from a nominal pose, each unlabelled touch on its nearest feature at the last one's pose


def _solved(groups, features, surfaces, points, index, ball_radius_mm, sigma_mm, lever_mm, tolerance, initial_pose):
    """(problem, solutions): every pose that passes under some assignment of the unlabelled touches, or, from a
    nominal pose, the pose refined from it, each unlabelled touch on the feature it lies nearest to there and then
    at the pose refined, while that changes (the first fit's where none passes)."""
    if len(points) and initial_pose is None:
        solutions = solve_unlabelled(groups, features, surfaces, points, index, ball_radius_mm, sigma_mm, lever_mm,
                                     tolerance)
        return solutions[0].problem, solutions
    assignment = nearest_assignment(surfaces, points, initial_pose, ball_radius_mm) if len(points) else ()
    first = None
    for _ in range(REASSIGN_ROUNDS):
        problem = assigned_problem(groups, features, points, index, assignment, ball_radius_mm, sigma_mm, lever_mm,
                                   tolerance)
        if not problem.groups:
            raise ValueError("no touches given: every feature's list of touches is empty")
        solutions = solve(problem, initial_pose)
        for s in solutions:
            s.assignment, s.problem = assignment, problem
        first = first or (problem, solutions)
        if solutions[0].good or not len(points):
            return problem, solutions
        # A touch put on the wrong feature at a nominal pose off by a few degrees pulls the fit away: each is put
        # on its nearest again at the pose refined, while that changes (ICP's step); kept only where a fit passes.
        initial_pose = solutions[0].fixture2meas
        again = nearest_assignment(surfaces, points, initial_pose, ball_radius_mm)
        if again == assignment:
            break
        assignment = again
    return first


def _missed(problem, explained):
    """The distinct poses the explanations lead to that, refined with every touch, pass: ones the search missed."""
    refined = [judged(problem, Solution(*levenberg_marquardt(problem, s.rotation, s.translation)), problem.scale())
               for _, _, s, _ in explained]
    return distinct([s for s in refined if s.good])


MAX_MORE_TOUCHES = 30  # planned touches tried before a target is called out of reach


def _next_touch(features, solution, candidates):
    planned, _ = next_touches(features, solution, candidates)
    _, fid, point, normal = planned[0]
    R, t = solution.rotation, solution.translation
    return {"feature": fid, "point_fixture_mm": point.tolist(), "point_meas_mm": (R @ point + t).tolist(),
            "approach_meas": (-(R @ normal)).tolist()}


def _target(features, solution, sigma_mm, target, now, candidates):
    """Whether (sigma translation mm, rotation deg) meets ``target`` (None: no limit) and how many planned
    touches would (None without candidates)."""
    def meets(s_t, s_r):
        return s_t is not None and all(limit is None or value <= limit for value, limit in zip((s_t, s_r), target))

    met = meets(*now)
    more = 0 if met else None
    if not met and candidates is not None:
        _, information = next_touches(features, solution, candidates, MAX_MORE_TOUCHES)
        for k, F in enumerate(information, start=1):
            if meets(*sigmas(covariance_from_information(F, solution.translation, sigma_mm))):
                more = k
                break
    return {"sigma_translation_mm": target[0], "sigma_rotation_deg": target[1], "met": met, "more_touches": more}
