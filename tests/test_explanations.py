"""Inconsistent touches (issue 12): every touch whose removal, or whose other label, makes them consistent is
listed with the pose it leads to; a culprit is named only when it is the only one; no failing pose is the
answer. Checked against the geometry itself: each listed pose puts every other touch on its feature."""

import json

import numpy as np
import pytest
from scipy.stats import chi2

from fixturecad.registration.ambiguity import _fits_afresh
from fixturecad.registration.engine import register_touches
from fixturecad.registration.least_squares import levenberg_marquardt
from fixturecad.registration.pose import fixture2meas_from_rt, pose_errors, random_rotation
from fixturecad.registration.problem import Problem
from fixturecad.registration.solve import solve
from fixturecad.registration.synthetic import plan_touches
from fixturecad.registration.touchfile import format_result, report
from fixturecad.registration.touches import build_groups
from fixturecad.templates import make

SIGMA_MM = 0.005
OFF_MM = 0.5


def cube_touches(rng, counts=None):
    """The cube's default plan (its first ``counts`` touches per face) at a random pose, with noise."""
    template = make("cube")
    features = template.feature_map()
    entries = [dict(e, points=e["points"][:(counts or {}).get(e["feature"], len(e["points"]))])
               for e in template.touch_plans()["default"].touches]
    truth = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-100.0, 100.0, 3))
    touches, _ = plan_touches(entries, truth)
    touches = {k: v + rng.normal(scale=SIGMA_MM, size=v.shape) for k, v in touches.items()}
    return features, touches, truth


def spoil(features, touches, truth, feature, k):
    """Move touch ``k`` on ``feature`` OFF_MM out along the feature's normal; its engine index."""
    touches[feature][k] += OFF_MM * truth[:3, :3] @ features[feature].normal
    return [(f, i) for f, points in touches.items() for i in range(len(points))].index((feature, k))


def distances(features, touches, pose):
    """Every touch's distance (mm) from its feature at ``pose``, in the engine's order."""
    pose = np.array(pose)
    return np.concatenate([np.abs(features[f].signed_distance((v - pose[:3, 3]) @ pose[:3, :3]))
                           for f, v in touches.items()])


def passes_without(features, touches, leave_out, truth):
    """Whether the touches without ``leave_out`` pass scipy's 99.9 % chi-square test at their fit from the truth."""
    problem = Problem(build_groups(features, touches), SIGMA_MM).without(leave_out)
    _, _, r, _ = levenberg_marquardt(problem, truth[:3, :3], truth[:3, 3])
    return float(r @ r) / SIGMA_MM**2 <= chi2.ppf(0.999, problem.size - 6)


@pytest.mark.parametrize("seed,feature,k", [(1, "top", 2), (2, "front", 0), (3, "left", 3)])
def test_one_touch_off_is_the_one_culprit_and_its_refit_the_answer(seed, feature, k):
    rng = np.random.default_rng(seed)
    features, touches, truth = cube_touches(rng)
    bad = spoil(features, touches, truth, feature, k)
    result = register_touches(features, touches, sigma_mm=SIGMA_MM)
    assert result["status"] == "inconsistent"
    assert {f["touch"] for f in result["flagged"]} == {bad} and result["culprit"] == bad
    # No other touch explains it: without any other, the spoiled one still fails the test.
    assert not any(passes_without(features, touches, j, truth) for j in range(12) if j != bad)
    for flag in result["flagged"]:
        off = distances(features, touches, flag["pose"])
        assert np.delete(off, bad).max() < 5 * SIGMA_MM and flag["residual_mm"] == pytest.approx(OFF_MM, abs=0.03)
    dt, dr = pose_errors(np.array(result["pose"]), truth)
    assert dt < 0.02 and dr < 1e-3


def test_two_touches_that_could_each_explain_it_are_both_listed_and_no_pose_is_given():
    """Two touches on the left face: with either left out, the other alone fixes x and is not checked. The left
    touch that is off or the one that is right: the touches cannot tell."""
    rng = np.random.default_rng(4)
    features, touches, truth = cube_touches(rng, {"left": 2})
    bad = spoil(features, touches, truth, "left", 1)
    result = register_touches(features, touches, sigma_mm=SIGMA_MM)
    assert result["status"] == "inconsistent"
    both = {bad - 1, bad}
    assert {f["touch"] for f in result["flagged"]} == both and result["culprit"] is None
    assert all(passes_without(features, touches, j, truth) for j in both)
    for flag in result["flagged"]:
        assert np.delete(distances(features, touches, flag["pose"]), flag["touch"]).max() < 5 * SIGMA_MM
    # The refit without the good touch is 0.5 mm off along x: not given as the answer, nor any other pose.
    assert result["pose"] is None and result["solutions"] == [] and result["covariance"] is None
    text = format_result(result)
    assert "pose: none (several touches could each explain the inconsistency" in text
    assert "2 touches could each explain it: which one is wrong cannot be told" in text
    printed = json.loads(report(result, as_json=True))
    assert printed["pose"] is None and printed["controller"] is None


def test_two_touches_off_are_not_explained_by_one_and_give_no_pose():
    rng = np.random.default_rng(5)
    features, touches, truth = cube_touches(rng)
    spoil(features, touches, truth, "top", 0)
    spoil(features, touches, truth, "front", 1)
    result = register_touches(features, touches, sigma_mm=SIGMA_MM)
    assert result["status"] == "inconsistent"
    assert result["flagged"] == [] and result["culprit"] is None and result["pose"] is None
    assert "pose: none (no single touch, label or printed feature explains the inconsistency)" in format_result(result)


# The audited 4-3-2 cube plan: four touches on top along a line, three on front, two on left.
LINE_PLAN = {"top": [[10, 25, 50], [20, 25, 50], [30, 25, 50], [40, 25, 50]],
             "front": [[10, 0, 10], [40, 0, 15], [25, 0, 40]], "left": [[0, 15, 20], [0, 35, 30]]}


def line_plan_trial(index):
    """Trial ``index`` of a seeded run of the 4-3-2 plan at random poses with 5 um of noise."""
    rng = np.random.default_rng(0)
    for _ in range(index + 1):
        truth = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-100, 100, 3))
        touches = {k: np.array(v, float) @ truth[:3, :3].T + truth[:3, 3] for k, v in LINE_PLAN.items()}
        touches = {k: v + rng.normal(scale=SIGMA_MM, size=v.shape) for k, v in touches.items()}
    return make("cube").feature_map(), touches, truth


@pytest.mark.parametrize("index", [22, 86])
def test_a_pose_the_search_misses_but_an_explanation_finds_is_the_answer(index):
    """Fitting all touches fails from every start (the top's touches on a line turn its fitted normal 60-90 deg,
    and the starts sweep about it); left out one at a time, the touches lead to a pose that fits them all: that
    pose, not a false `inconsistent`."""
    features, touches, truth = line_plan_trial(index)
    result = register_touches(features, touches, sigma_mm=SIGMA_MM)
    assert result["status"] == "unique" and result["flagged"] == []
    assert distances(features, touches, result["pose"]).max() < 5 * SIGMA_MM
    assert max(pose_errors(np.array(result["pose"]), truth)) < 0.05


def test_every_touch_left_out_is_fitted_afresh_as_its_own_solve_would():
    """The explanations' fits from scratch, every touch left out and all their closed-form starts refined in one
    batch, are what :func:`.solve.solve` gives each touch set alone without its complete search: as many poses,
    the same ones, in the same order; the spoiled touch's among those that fit."""
    rng = np.random.default_rng(4)
    features, touches, truth = cube_touches(rng, {"top": 3, "front": 3, "left": 3})
    bad = spoil(features, touches, truth, "left", 2)
    problem = Problem(build_groups(features, touches), SIGMA_MM)
    touched = list(dict.fromkeys(int(k) for k in problem.row_touch))
    batched = _fits_afresh(problem, touched, None)
    for touch in touched:
        alone = solve(problem.without(touch), None, complete=False, good_only=True)
        assert len(batched[touch]) == len(alone), touch
        for a, b in zip(batched[touch], alone):
            assert np.allclose(a.rotation, b.rotation, atol=1e-9) and np.allclose(a.translation, b.translation,
                                                                                  atol=1e-6)
    assert batched[bad]
    assert pose_errors(batched[bad][0].fixture2meas, truth)[0] < 0.05
