"""How well touches check each other (issue 12): rows beyond six, unchecked touches, the smallest error
found, against leave-one-out ranks and the residual of a registration with that error."""

import numpy as np
import pytest

from fixturecad.build import features_document
from fixturecad.registration.engine import register_touches
from fixturecad.registration.features import features_from_json
from fixturecad.registration.least_squares import levenberg_marquardt
from fixturecad.registration.mobility import matrix_rank
from fixturecad.registration.problem import Problem
from fixturecad.registration.defaults import DEFAULT_SIGMA_MM
from fixturecad.registration.pose import fixture2meas_from_rt, pose_errors, random_rotation
from fixturecad.registration.redundancy import DETECTION_FACTOR
from fixturecad.registration.synthetic import perturb_touches, plan_touches
from fixturecad.registration.touches import build_groups
from fixturecad.templates import TEMPLATES, make

SIGMA_MM = 0.005


def cube(points):
    features = features_from_json(features_document(make("cube")))
    touches = {}
    for feature, point in points:
        touches.setdefault(feature, []).append(point)
    return features, {k: np.array(v, float) for k, v in touches.items()}


# 3-2-1 on the 50 mm cube, then two more on the top and one more on the front.
PLAN = [("top", (10, 10, 50)), ("top", (40, 10, 50)), ("top", (25, 40, 50)), ("front", (10, 0, 25)),
        ("front", (40, 0, 25)), ("left", (0, 25, 25))]
MORE = [("top", (40, 40, 50)), ("top", (10, 40, 50)), ("front", (25, 0, 40))]


def test_a_321_plan_checks_nothing():
    features, touches = cube(PLAN)
    result = register_touches(features, touches, sigma_mm=SIGMA_MM)
    assert result["status"] == "unique"
    check = result["redundancy"]
    assert check["rows_beyond_six"] == 0 and check["unchecked"] == list(range(6))


def test_unchecked_touches_are_those_the_others_cannot_replace():
    """Leave-one-out rank, independently: a touch is checked iff the others alone fix the pose."""
    features, touches = cube(PLAN + MORE)
    result = register_touches(features, touches, sigma_mm=SIGMA_MM)
    check = result["redundancy"]
    assert check["rows_beyond_six"] == 3
    problem = Problem(build_groups(features, touches), SIGMA_MM)
    expected = [k for k in range(len(PLAN + MORE))
                if matrix_rank(problem.without(k).evaluate(np.eye(3), np.zeros(3))[1], 50.0) < 6]
    # Touches are numbered by feature (top 0-4, front 5-7, left 8): only the left face's one is unchecked.
    assert check["unchecked"] == expected == [8]


def test_the_detectable_error_gives_the_residual_it_promises():
    """An error of detectable_mm in a checked touch leaves a residual sum of squares of (4.13 sigma)^2."""
    features, touches = cube(PLAN + MORE)
    check = register_touches(features, touches, sigma_mm=SIGMA_MM)["redundancy"]
    order = [(feature, i) for feature, points in touches.items() for i in range(len(points))]
    for k, size in enumerate(check["detectable_mm"]):
        if size is None:
            continue
        feature, index = order[k]
        moved = {f: v.copy() for f, v in touches.items()}
        moved[feature][index] += size * features[feature].normal
        # The least-squares pose (the one the residual test judges), from the truth.
        _, _, residuals, _ = levenberg_marquardt(Problem(build_groups(features, moved), SIGMA_MM), np.eye(3),
                                                 np.zeros(3))
        cost = float(residuals @ residuals)
        assert abs(cost - (DETECTION_FACTOR * SIGMA_MM) ** 2) < 1e-3 * (DETECTION_FACTOR * SIGMA_MM) ** 2, k


TEMPLATE_NAMES = sorted(TEMPLATES)


def _leverage_redundancy(J, touches):
    """Each touch's redundancy number 1 - max leverage of its rows, from the Jacobian's column space."""
    basis = np.linalg.svd(J, full_matrices=False)[0][:, :6]
    leverage = np.sum(basis**2, axis=1)
    return {int(k): 1.0 - leverage[touches == k].max() for k in np.unique(touches)}


@pytest.mark.parametrize("name", TEMPLATE_NAMES)
def test_every_default_plan_checks_every_touch_also_with_any_one_left_out(name):
    """Issue 12: a single faulty touch is found (every touch checked) and named (with any other touch left out,
    it is still checked: no two touches whose errors look alike), at well under 0.5 mm, at the default noise."""
    template = make(name)
    touches, contacts = plan_touches(template.touch_plans()["default"].touches, np.eye(4))
    problem = Problem(build_groups(template.feature_map(), touches, 0.0, contacts), DEFAULT_SIGMA_MM)
    worst = 0.0
    for left_out in [None] + list(range(problem.row_touch.max() + 1)):
        reduced = problem if left_out is None else problem.without(left_out)
        J = reduced.evaluate(np.eye(3), np.zeros(3))[1]
        assert matrix_rank(J, 50.0) == 6
        r = min(_leverage_redundancy(J, reduced.row_touch).values())
        worst = max(worst, DETECTION_FACTOR * DEFAULT_SIGMA_MM / np.sqrt(max(r, 1e-12)))
    assert worst < 0.1, worst


@pytest.mark.parametrize("name", TEMPLATE_NAMES)
def test_one_touch_off_in_a_default_plan_is_named(name):
    """A seeded layout of each template's default plan at a random pose, 5 um of noise, one touch 0.5 mm off its
    feature: `inconsistent`, that touch the one culprit, its refit the pose (benchmarks/bench_redundancy.py
    sweeps random layouts, directions and wrong labels)."""
    template = make(name)
    features = template.feature_map()
    rng = np.random.default_rng(12)
    truth = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-100.0, 100.0, 3))
    touches, contacts = perturb_touches(*plan_touches(template.touch_plans()["default"].touches, truth), rng,
                                        DEFAULT_SIGMA_MM)
    order = [(fid, k) for fid, points in touches.items() for k in range(len(points))]
    bad = int(rng.integers(len(order)))
    fid, k = order[bad]
    local = (touches[fid][k] - truth[:3, 3]) @ truth[:3, :3]
    touches[fid][k] = truth[:3, :3] @ (local + 0.5 * features[fid].normal_at(local[None])[0]) + truth[:3, 3]
    result = register_touches(features, touches, sigma_mm=DEFAULT_SIGMA_MM, contacts=contacts)
    assert result["status"] == "inconsistent" and result["culprit"] == bad, (result["status"], result["flagged"])
    assert max(pose_errors(np.array(result["pose"]), truth)) < 0.05
