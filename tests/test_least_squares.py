"""Refinement of many starts at once (issue 19): the same rows as one pose at a time, the same minima."""

import numpy as np
import pytest

from fixturecad.registration.least_squares import levenberg_marquardt, levenberg_marquardt_batch
from fixturecad.registration.pose import random_rotation, rotation_from_vector, skew
from fixturecad.registration.problem import Problem
from fixturecad.registration.touches import build_groups
from search_cases import VARIANTS, layout

# Exact and printed parts, point touches and sensors, planes, spheres and cylinders (radius modes among them),
# several features' groups of one contact type computed as one (the cube's planes, the sphere-plate's spheres).
NAMES = ["cube 2-2-2", "inclined-plane-cylinder 2+4, printed", "Example One (paper plan), printed",
         "{R}{C-R-C} design (default plan), printed", "{R}{G3-R} design (default plan)",
         "sphere-plate 4 per ball, printed"]
SIGMA_MM = 0.005


def _problem(name):
    case = next(case for case, noise in VARIANTS if case.name == name)
    lay = layout(case, SIGMA_MM, 1)
    return Problem(build_groups(lay.features, lay.touches, 0.0, lay.contacts), SIGMA_MM,
                   tolerance=lay.tolerance), lay.truth


@pytest.mark.parametrize("name", NAMES)
def test_rows_at_many_poses_are_each_poses_rows(name):
    """evaluate_batch, each pose's problem without a touch or not, against that problem's own evaluate (a
    sensor's rows are whitened in another frame: compared by the cost, the gradient and Gauss-Newton matrix,
    the fixture-frame twist mapped to the spatial one)."""
    rng = np.random.default_rng(2)
    problem, _ = _problem(name)
    touches = sorted(set(problem.row_touch))
    Rs = np.array([random_rotation(rng) for _ in range(6)])
    ts = rng.uniform(-50.0, 50.0, (6, 3))
    without = np.array([-1, -1, *rng.choice(touches, 4)])
    r, J = problem.evaluate_batch(Rs, ts, without)
    for k in range(len(Rs)):
        reduced = problem if without[k] < 0 else problem.without(int(without[k]))
        r0, J0 = reduced.evaluate(Rs[k], ts[k])
        adjoint = np.block([[Rs[k], np.zeros((3, 3))], [skew(ts[k]) @ Rs[k], Rs[k]]])
        J0 = J0 @ adjoint
        assert r[k] @ r[k] == pytest.approx(r0 @ r0, rel=1e-9)
        assert np.allclose(J[k].T @ r[k], J0.T @ r0, rtol=1e-7, atol=1e-7 * np.abs(J0.T @ r0).max())
        assert np.allclose(J[k].T @ J[k], J0.T @ J0, rtol=1e-7, atol=1e-7 * np.abs(J0.T @ J0).max())


@pytest.mark.parametrize("name", NAMES)
def test_many_starts_at_once_reach_the_minima_each_reaches_alone(name):
    """20 starts 2-10 deg and 2-10 mm off the truth, refined together and one at a time: the same cost, to a
    part in 1e6 of the threshold's scale (sigma^2 a row), and the same pose within 0.01 sigma at the touches; the
    cost returned is the pose's."""
    rng = np.random.default_rng(3)
    problem, truth = _problem(name)
    starts = []
    for _ in range(20):
        axis = rng.normal(size=3)
        turn = rotation_from_vector(np.radians(rng.uniform(2, 10)) * axis / np.linalg.norm(axis))
        starts.append((turn @ truth[:3, :3], truth[:3, 3] + rng.uniform(2, 10) * rng.choice([-1, 1], 3) / np.sqrt(3)))
    Rs, ts, costs = levenberg_marquardt_batch(problem, *map(np.array, zip(*starts)))
    points = np.concatenate([g.centre for g in problem.groups])
    for (R0, t0), R, t, cost in zip(starts, Rs, ts, costs):
        R1, t1, r1, _ = levenberg_marquardt(problem, R0, t0)
        r = problem.evaluate(R, t)[0]
        assert cost == pytest.approx(r @ r, rel=1e-7)  # what the residual test is told of the pose
        assert r @ r == pytest.approx(r1 @ r1, abs=1e-6 * SIGMA_MM**2 * len(r))
        if r1 @ r1 <= SIGMA_MM**2 * 10 * len(r):  # (both at the truth's minimum: the same pose)
            moved = np.linalg.norm((points - t) @ R - (points - t1) @ R1, axis=1)
            assert moved.max() < 0.01 * SIGMA_MM
