"""The certified search over rotations (registration/search.py): its bound holds, and no pose that passes
is dropped."""

import numpy as np
import pytest

from fixturecad.registration.patches import patch_points
from fixturecad.registration.pose import random_rotation, rotation_angle, rotation_from_vector
from fixturecad.registration.problem import Problem
from fixturecad.registration.search import LEAF_RAD, RotationSearch, leaf_starts
from fixturecad.registration.touches import build_groups

from test_registration_engine import _plan

CASES = [("cube", {"top": 2, "front": 2, "left": 2}), ("v-block", None), ("inclined-plane-cylinder", None),
         ("sphere-plate", None)]


def _layout(name, counts, rng):
    """Touches drawn on the template's patches (every touched feature of the default plan, or ``counts``),
    at a random pose: (features, touches in the measurement frame, true R, t)."""
    features, plan = _plan(name, "default")
    if counts is None:
        counts = {}
        for entry in plan:
            counts[entry["feature"]] = counts.get(entry["feature"], 0) + len(entry["points"])
    R, t = random_rotation(rng), rng.uniform(-80, 80, 3)
    touches = {}
    for fid, count in counts.items():
        points = patch_points(features[fid])
        touches[fid] = points[rng.choice(len(points), count, replace=False)] @ R.T + t
    return features, touches, R, t


@pytest.mark.parametrize("name,counts", CASES)
def test_the_search_distances_are_the_rows(name, counts):
    """One geometry: the search's distances are the lengths of the contact model's rows, touch by touch."""
    rng = np.random.default_rng(3)
    features, touches, R, t = _layout(name, counts, rng)
    problem = Problem(build_groups(features, touches))
    search = RotationSearch(problem, 1.0)
    Rs = np.array([random_rotation(rng) for _ in range(4)])
    ts = rng.uniform(-50, 50, (4, 3))
    rows = problem.evaluate_batch(Rs, ts)[0]
    a = np.einsum("kji,nj->kni", Rs, search.points - search.centroid)
    d, _ = search.distances(a, np.einsum("kji,kj->ki", Rs, search.centroid - ts))
    per_touch = np.stack([np.bincount(problem.row_touch, weights=r**2) for r in rows])
    assert np.allclose(d**2, per_touch, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name,counts", CASES)
def test_the_bound_holds_within_a_cell(name, counts):
    """At a cell's centre and the same image y, the cost is at most (sqrt(cost) + delta sqrt(lambda))^2 for
    any rotation of the cell: the inequality the pruning rests on, on random cells and rotations."""
    rng = np.random.default_rng(5)
    features, touches, R, t = _layout(name, counts, rng)
    search = RotationSearch(Problem(build_groups(features, touches)), 1.0)
    for _ in range(200):
        delta = rng.uniform(0.01, 0.7)
        v0 = rng.normal(size=3)
        step = rng.normal(size=3)
        v = v0 + rng.uniform(0, 1) * delta * step / np.linalg.norm(step)
        R0, R1 = rotation_from_vector(v0), rotation_from_vector(v)
        assert rotation_angle(R1 @ R0.T) <= delta + 1e-12  # the geodesic radius of a rotation-vector ball
        y = rng.uniform(-30, 30, 3)
        costs = []
        for Rk in (R0, R1):
            a = (search.points - search.centroid) @ Rk
            costs.append(np.sum(search.distances(a[None], y[None])[0] ** 2))
        assert costs[0] <= (np.sqrt(costs[1]) + delta * search.swing_mm) ** 2 + 1e-9


@pytest.mark.parametrize("name,counts", CASES)
def test_the_true_pose_keeps_its_leaf(name, counts):
    """Noise-free touches at a random pose and layout: a leaf is left within one leaf radius of the truth
    (the search never drops the cell that holds a pose that passes), and its refinement starts there."""
    for seed in range(3):
        rng = np.random.default_rng(seed)
        features, touches, R, t = _layout(name, counts, rng)
        problem = Problem(build_groups(features, touches))
        search = RotationSearch(problem, problem.sigma**2 * 30.0)
        leaves = search.leaves()
        assert leaves is not None
        angles = [rotation_angle(Rk @ R.T) for Rk in leaves[0]]
        assert min(angles) <= LEAF_RAD
        starts = leaf_starts(problem, problem.sigma**2 * 30.0)
        assert any(rotation_angle(Rk @ R.T) < 1e-3 and np.linalg.norm(tk - t) < 0.01 for Rk, tk in starts)
