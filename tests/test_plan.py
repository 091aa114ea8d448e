"""`fixturecad plan` (issue 8, part 1): touches on the real patches, reachable, locating, and better on the
criterion than the default plan and than seeded random plans of the same count on the same candidates."""

import json
import shutil

import numpy as np
import pytest

from cli import assert_bad_input, run
from fixturecad.registration import planning
from fixturecad.registration.features import features_from_json
from fixturecad.registration.mobility import matrix_rank
from fixturecad.registration.sampling import load_mesh


@pytest.fixture
def folder(built, tmp_path):
    def copy(name):
        target = tmp_path / name
        shutil.copytree(built(name), target)
        return target
    return copy


def surface_ids(features):
    return [fid for fid, f in features.items() if f.kind in ("plane", "sphere", "cylinder")]


@pytest.mark.parametrize("name", ["cube", "quarter-sphere", "sphere-plate"])
def test_planned_touches_lie_on_their_patches_are_reachable_and_locate(folder, name):
    out_dir = folder(name)
    result = run("plan", out_dir, "--touches", 8, "--margin", 2, "--preview")
    assert result.returncode == 0, result.stderr
    plan = json.loads((out_dir / "plans" / "designed.json").read_text())
    features = features_from_json(json.loads((out_dir / "features.json").read_text()))
    points = []
    mesh = load_mesh(out_dir / "fixture.stl")
    for entry in plan["touch_plan"]:
        feature = features[entry["feature"]]
        p, a = np.array(entry["points"]), np.array(entry["approaches"])
        assert np.abs(feature.signed_distance(p)).max() < 1e-9
        assert np.all(feature.extent.margin(p, feature._parameter(p)) >= 2.0 - 1e-9)
        assert np.allclose(a, -feature.normal_at(p))
        # Independently of the planner: no triangle of the STL lies on the way out along the normal.
        assert planning.reachable(mesh.triangles, p, -a).all()
        points.append(p)
    assert sum(len(p) for p in points) == 8
    cands = planning.candidates(features, surface_ids(features), 2.0)
    touches = {}
    for entry in plan["touch_plan"]:
        touches.setdefault(entry["feature"], []).extend(entry["points"])
    from fixturecad.registration.problem import Problem
    from fixturecad.registration.touches import build_groups

    _, J = Problem(build_groups(features, {k: np.array(v) for k, v in touches.items()})).evaluate(np.eye(3), np.zeros(3))
    assert matrix_rank(J, cands.length_mm) == 6
    assert (out_dir / "plans" / "designed.png").stat().st_size > 10000
    assert "robust to the loss of any one touch" in result.stdout
    # The touch file written with it registers the nominal pose.
    reg = run("register", out_dir, out_dir / "plans" / "designed.csv", "--json")
    assert reg.returncode == 0, reg.stderr
    assert np.abs(np.array(json.loads(reg.stdout)["pose"]) - np.eye(4)).max() < 1e-3
    sim = run("simulate", out_dir, "--trials", 5, "--touch-plan", "designed")
    assert sim.returncode == 0 and "(designed)" in sim.stdout and "unique 5" in sim.stdout, sim.stdout + sim.stderr


@pytest.mark.parametrize("name, count", [("cube", 12), ("v-block", 12)])
def test_the_design_beats_the_default_plan_and_random_plans(built, folder, name, count):
    """Same count as the default (point-probe) plan, same candidates: the criterion and both bounds."""
    features = features_from_json(json.loads((built(name) / "features.json").read_text()))
    cands = planning.candidates(features, surface_ids(features), 1.0)
    chosen = planning.design(cands, count, "d")
    scale = np.r_[np.full(3, 1.0 / cands.length_mm), np.ones(3)]

    def value(rows):
        return planning.criterion_values((rows * scale).T @ (rows * scale), "d")

    rng = np.random.default_rng(8)
    random = [value(cands.rows[rng.choice(len(cands.rows), count, replace=False)]) for _ in range(500)]
    assert value(cands.rows[chosen]) >= max(random)
    out = run("plan", folder(name), "--touches", count)
    assert out.returncode == 0, out.stderr
    planned, default = [line.split(":")[1] for line in out.stdout.splitlines() if line.startswith(("  planned", "  default"))]
    (pt, pr), (dt, dr) = ([float(x.split()[0]) for x in text.split(",")] for text in (planned, default))
    assert pt < dt and pr < dr


def test_criteria_each_win_on_their_own_measure(built):
    features = features_from_json(json.loads((built("quarter-sphere") / "features.json").read_text()))
    cands = planning.candidates(features, surface_ids(features), 1.0)
    scale = np.r_[np.full(3, 1.0 / cands.length_mm), np.ones(3)]
    plans = {c: planning.design(cands, 9, c) for c in planning.CRITERIA}
    for criterion, chosen in plans.items():
        mine = cands.rows[chosen] * scale
        for other in plans.values():
            rows = cands.rows[other] * scale
            assert planning.criterion_values(mine.T @ mine, criterion) >= \
                planning.criterion_values(rows.T @ rows, criterion) - 1e-9


def test_bad_input_writes_nothing(folder):
    out_dir = folder("cube")
    assert_bad_input(run("plan", out_dir, "--touches", 5), "--touches")
    assert_bad_input(run("plan", out_dir, "--touches", 8, "--features", "top,nope"), "unknown feature 'nope'")
    assert_bad_input(run("plan", out_dir, "--touches", 8, "--margin", 500), "lower --margin")
    assert_bad_input(run("plan", out_dir, "--touches", 8, "--features", "top"), "cannot locate")
    assert_bad_input(run("plan", out_dir, "--touches", 8, "--name", "../x"), "--name")
    assert not (out_dir / "plans").exists()
    assert run("plan", out_dir, "--touches", 8).returncode == 0
    assert_bad_input(run("plan", out_dir, "--touches", 8), "--force")


def _cube():
    from fixturecad.build import features_document
    from fixturecad.templates import make

    return features_from_json(features_document(make("cube")))


CUBE_321 = {"top": [[10, 10, 50], [40, 10, 50], [25, 40, 50]], "front": [[10, 0, 25], [40, 0, 25]],
            "left": [[0, 25, 25]]}


def test_the_next_touch_adds_more_information_than_200_random_candidates():
    from fixturecad.registration.engine import register_touches
    from fixturecad.registration.patches import patch_points

    features = _cube()
    touches = {k: np.array(v, float) for k, v in CUBE_321.items()}
    result = register_touches(features, touches, plan_next=True)
    nxt = result["next_touch"]

    def logdet(extra_feature, point):
        more = {k: v.copy() for k, v in touches.items()}
        more[extra_feature] = np.vstack([more[extra_feature], point])
        cov = np.array(register_touches(features, more, initial_pose=np.eye(4))["covariance"])
        return -np.linalg.slogdet(cov)[1]

    best = logdet(nxt["feature"], nxt["point_meas_mm"])
    rng = np.random.default_rng(200)
    for _ in range(200):
        fid = str(rng.choice(list(features)))
        points = patch_points(features[fid])
        assert best >= logdet(fid, points[rng.integers(len(points))]) - 1e-9


def test_the_next_touch_removes_a_free_motion_and_the_target_counts_touches():
    from fixturecad.registration.engine import register_touches

    features = _cube()
    touches = {"top": np.array(CUBE_321["top"], float), "front": np.array([[10, 0, 25], [40, 0, 25], [25, 0, 40]], float)}
    result = register_touches(features, touches, plan_next=True)
    assert result["status"] == "underdetermined"
    assert result["next_touch"]["feature"] == "left"  # only the left face holds the part along x
    # Where it says on the part (the truth is the identity; along x the pose found is arbitrary).
    touches["left"] = np.array([result["next_touch"]["point_fixture_mm"]])
    assert register_touches(features, touches)["status"] == "unique"
    done = register_touches(features, touches, target_sigma=(1.0, None))["target"]
    assert done["met"] and done["more_touches"] == 0
    wanted = register_touches(features, touches, target_sigma=(0.005, None))
    more = wanted["target"]["more_touches"]
    assert not wanted["target"]["met"] and more > 0
    # Making the predicted touches does meet it (noise-free touches: the prediction is the covariance).
    from fixturecad.registration.planning import next_touches
    from fixturecad.registration.problem import Problem
    from fixturecad.registration.solve import solve
    from fixturecad.registration.touches import build_groups

    solution = solve(Problem(build_groups(features, touches)))[0]
    planned, _ = next_touches(features, solution, more)
    for _, fid, point, _ in planned:
        touches[fid] = np.vstack([touches.get(fid, np.zeros((0, 3))), point])
    assert register_touches(features, touches)["sigma_translation_mm"] <= 0.005


def test_a_point_of_interest_is_located_better_by_its_own_plan():
    """The position error of a tool point 100 mm off the cube, from the plans' covariances."""
    from fixturecad.registration.pose import skew
    from fixturecad.registration.uncertainty import covariance

    features = _cube()
    cands = planning.candidates(features, surface_ids(features), 1.0)
    point = np.array([120.0, 90.0, 60.0])

    def variance(chosen):
        # covariance() is over (rotation, fixture origin): the point moves by omega x (x - 0) + origin shift.
        cov = covariance(cands.rows[chosen], np.zeros(3), 0.005)
        J = np.hstack([-skew(point), np.eye(3)])
        return np.trace(J @ cov @ J.T)

    own = variance(planning.design(cands, 8, "point", point))
    for criterion in planning.CRITERIA:
        assert own <= variance(planning.design(cands, 8, criterion)) + 1e-15


def test_seven_or_more_touches_survive_the_loss_of_any_one(built):
    """On the inclined plane and cylinder the D-optimal plan puts only three touches on the plane; the
    plan then trades some determinant for every touch checked by the others."""
    features = features_from_json(json.loads((built("inclined-plane-cylinder") / "features.json").read_text()))
    cands = planning.candidates(features, surface_ids(features), 1.0)
    for count in (7, 9):
        chosen = planning.design(cands, count, "d")
        assert planning.robust(cands.rows[chosen], cands.length_mm)
        assert all(matrix_rank(np.delete(cands.rows[chosen], k, axis=0), cands.length_mm) == 6 for k in range(count))
