"""How well touches check each other (issue 12): rows beyond six, unchecked touches, the smallest error
found, against leave-one-out ranks and the residual of a registration with that error."""

import numpy as np

from fixturecad.build import features_document
from fixturecad.registration.engine import register_touches
from fixturecad.registration.features import features_from_json
from fixturecad.registration.least_squares import levenberg_marquardt
from fixturecad.registration.mobility import matrix_rank
from fixturecad.registration.problem import Problem
from fixturecad.registration.redundancy import DETECTION_FACTOR
from fixturecad.registration.touches import build_groups
from fixturecad.templates import make

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
