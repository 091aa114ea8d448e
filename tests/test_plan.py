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
from fixturecad.registration.reach import reachable
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


def all_candidates(features, margin_mm=1.0):
    """Candidates on every surface feature's patch, no reachability test."""
    return planning.candidates(features, planning.candidate_points(features, surface_ids(features), margin_mm))


def bounds(rows):
    """(translation um, rotation mdeg) per um of noise of rows at the nominal pose, inf when singular."""
    from fixturecad.registration.uncertainty import covariance, sigmas

    if matrix_rank(rows, 50.0) < 6:
        return np.inf, np.inf
    t, r = sigmas(covariance(rows, np.zeros(3), 1.0))
    return t, r


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
        assert reachable(mesh.triangles, p, -a).all()
        points.append(p)
    assert sum(len(p) for p in points) == 8
    cands = all_candidates(features, 2.0)
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


@pytest.mark.parametrize("name, count", [("cube", 12), ("v-block", 14), ("sphere-plate", 12)])
def test_the_design_beats_the_default_plan_and_random_plans(built, folder, name, count):
    """Same count as the default (point-probe) plan, same candidates: no random plan is better in both bounds,
    the best random plan by the determinant is worse in both, and so is the default plan (by the command)."""
    features = features_from_json(json.loads((built(name) / "features.json").read_text()))
    cands = all_candidates(features)
    planned = bounds(cands.rows[planning.design(cands, count, "d")])
    rng = np.random.default_rng(8)
    picks = [rng.choice(len(cands.rows), count, replace=False) for _ in range(500)]
    scale = np.r_[np.full(3, 1.0 / cands.length_mm), np.ones(3)]
    values = [planning.criterion_values((cands.rows[p] * scale).T @ (cands.rows[p] * scale), "d") for p in picks]
    random = np.array([bounds(cands.rows[p]) for p in picks])
    assert not np.any(np.all(random < planned, axis=1))
    assert np.all(random[int(np.argmax(values))] > planned)
    out = run("plan", folder(name), "--touches", count)
    assert out.returncode == 0, out.stderr
    planned, default = [line.split(":")[1] for line in out.stdout.splitlines() if line.startswith(("  planned", "  default"))]
    (pt, pr), (dt, dr) = ([float(x.split()[0]) for x in text.split(",")] for text in (planned, default))
    assert pt <= dt and pr <= dr and (pt < dt or pr < dr)


def test_a_default_plan_better_in_one_bound_is_matched_in_both(built):
    """The guarantee: given the default plan, the design is no worse in either bound, better in one."""
    features = features_from_json(json.loads((built("sphere-plate") / "features.json").read_text()))
    document = json.loads((built("sphere-plate") / "features.json").read_text())
    touches = [(e["feature"], p) for e in document["plans"]["default"]["touch_plan"] for p in e["points"]]
    cands = planning.candidates(features, planning.candidate_points(features, surface_ids(features), 1.0, also=touches))
    reference = planning.indices(cands, touches)
    assert reference is not None
    default = np.array(bounds(cands.rows[reference]))
    planned = np.array(bounds(cands.rows[planning.design(cands, 12, "d", reference=reference)]))
    assert np.all(planned <= default) and np.any(planned < default)


def test_criteria_each_win_on_their_own_measure(built):
    features = features_from_json(json.loads((built("quarter-sphere") / "features.json").read_text()))
    cands = all_candidates(features)
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


def _built_cube(built):
    """The built cube's features and its stored reachable candidates (features.json's touch_candidates)."""
    document = json.loads((built("cube") / "features.json").read_text())
    return features_from_json(document), planning.stored_candidates(document)


def test_the_next_touch_adds_more_information_than_200_random_candidates(built):
    from fixturecad.registration.engine import register_touches

    features, candidates = _built_cube(built)
    touches = {k: np.array(v, float) for k, v in CUBE_321.items()}
    result = register_touches(features, touches, plan_next=True, candidates=candidates)
    nxt = result["next_touch"]

    def logdet(extra_feature, point):
        more = {k: v.copy() for k, v in touches.items()}
        more[extra_feature] = np.vstack([more[extra_feature], point])
        cov = np.array(register_touches(features, more, initial_pose=np.eye(4))["covariance"])
        return -np.linalg.slogdet(cov)[1]

    best = logdet(nxt["feature"], nxt["point_meas_mm"])
    rng = np.random.default_rng(200)
    for _ in range(200):
        fid = str(rng.choice(list(candidates)))
        assert best >= logdet(fid, candidates[fid][rng.integers(len(candidates[fid]))]) - 1e-9


def test_the_next_touch_removes_a_free_motion_and_the_target_counts_touches(built):
    from fixturecad.registration.engine import register_touches

    features, candidates = _built_cube(built)
    touches = {"top": np.array(CUBE_321["top"], float), "front": np.array([[10, 0, 25], [40, 0, 25], [25, 0, 40]], float)}
    result = register_touches(features, touches, plan_next=True, candidates=candidates)
    assert result["status"] == "underdetermined"
    assert result["next_touch"]["feature"] == "left"  # only the left face holds the part along x
    # Where it says on the part (the truth is the identity; along x the pose found is arbitrary).
    touches["left"] = np.array([result["next_touch"]["point_fixture_mm"]])
    assert register_touches(features, touches)["status"] == "unique"
    done = register_touches(features, touches, target_sigma=(1.0, None), candidates=candidates)["target"]
    assert done["met"] and done["more_touches"] == 0
    wanted = register_touches(features, touches, target_sigma=(0.005, None), candidates=candidates)
    more = wanted["target"]["more_touches"]
    assert not wanted["target"]["met"] and more > 0
    # Making the predicted touches does meet it (noise-free touches: the prediction is the covariance).
    from fixturecad.registration.planning import next_touches
    from fixturecad.registration.problem import Problem
    from fixturecad.registration.solve import solve
    from fixturecad.registration.touches import build_groups

    solution = solve(Problem(build_groups(features, touches)))[0]
    planned, _ = next_touches(features, solution, candidates, more)
    for _, fid, point, _ in planned:
        touches[fid] = np.vstack([touches.get(fid, np.zeros((0, 3))), point])
    assert register_touches(features, touches)["sigma_translation_mm"] <= 0.005


def test_a_point_of_interest_is_located_better_by_its_own_plan():
    """The position error of a tool point 100 mm off the cube, from the plans' covariances."""
    from fixturecad.registration.pose import skew
    from fixturecad.registration.uncertainty import covariance

    features = _cube()
    cands = all_candidates(features)
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
    cands = all_candidates(features)
    for count in (7, 9):
        chosen = planning.design(cands, count, "d")
        assert planning.robust(cands.rows[chosen], cands.length_mm)
        assert all(matrix_rank(np.delete(cands.rows[chosen], k, axis=0), cands.length_mm) == 6 for k in range(count))


@pytest.mark.parametrize("name", ["v-block", "sphere-plate"])
def test_ball_tip_plans_touch_their_patches_from_outside_and_register(folder, name):
    """A ball of radius 2 mm: centres 2 mm off their features, on the patch 3 mm in (the default margin), the
    swept ball clear of the mesh; the plan's touches made at a random pose register with --ball-radius."""
    import trimesh
    from scipy.spatial import cKDTree

    from fixturecad.registration.pose import fixture2meas_from_rt, pose_errors, random_rotation

    out_dir, radius = folder(name), 2.0
    result = run("plan", out_dir, "--touches", 9, "--sensor", f"ball:{radius:g}", "--preview")
    assert result.returncode == 0, result.stderr
    plan = json.loads((out_dir / "plans" / "designed.json").read_text())
    assert plan["ball_radius_mm"] == radius and "robust to the loss" in result.stdout
    features = features_from_json(json.loads((out_dir / "features.json").read_text()))
    mesh = load_mesh(out_dir / "fixture.stl")
    # Independently of the planner: points spread densely over the mesh keep off every ball's path.
    surface, _ = trimesh.sample.sample_surface(mesh, 200_000, seed=3)
    spacing = np.sqrt(mesh.area / len(surface))
    tree = cKDTree(surface)
    for entry in plan["touch_plan"]:
        assert entry["contact"] == f"S/M-{features[entry['feature']].element}/M"
        feature, centres, approach = features[entry["feature"]], np.array(entry["points"]), np.array(entry["approaches"])
        assert np.allclose(feature.signed_distance(centres), radius)
        touched = centres + radius * approach
        assert np.abs(feature.signed_distance(touched)).max() < 1e-9
        assert np.all(feature.extent.margin(touched, feature._parameter(touched)) >= radius + 1.0 - 1e-9)
        for c, a in zip(centres, approach):
            path = c - np.linspace(0.0, 200.0, 801)[:, None] * a
            assert tree.query(path)[0].min() > radius - 2 * spacing
    rng = np.random.default_rng(9)
    truth = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-80, 80, 3))
    lines = ["feature,x,y,z"] + [f"{e['feature']},{','.join(repr(float(x)) for x in truth[:3, :3] @ p + truth[:3, 3])}"
                                 for e in plan["touch_plan"] for p in e["points"]]
    (out_dir / "measured.csv").write_text("\n".join(lines) + "\n")
    reg = run("register", out_dir, out_dir / "measured.csv", "--ball-radius", radius, "--json")
    assert reg.returncode == 0, reg.stderr
    assert max(pose_errors(np.array(json.loads(reg.stdout)["pose"]), truth)) < 1e-6
    sim = run("simulate", out_dir, "--trials", 5, "--touch-plan", "designed", "--fixture-tolerance", 0, "--force")
    assert sim.returncode == 0 and "unique 5" in sim.stdout, sim.stdout + sim.stderr


def test_bad_sensors_write_nothing(folder):
    out_dir = folder("cube")
    for bad in ("ball:-1", "ball:abc", "ball:0", "ball:", "ball:nan", "tip:2"):
        assert_bad_input(run("plan", out_dir, "--touches", 8, "--sensor", bad), "--sensor")
    assert_bad_input(run("plan", out_dir, "--touches", 8, "--sensor", "ball:40"), "lower --margin")
    assert not (out_dir / "plans").exists()


def test_register_py_plans_the_next_touch_as_the_library_does_among_reachable_touches(built, tmp_path):
    """register.py has no mesh: it chooses among the reachable touches the build stored, as the library."""
    from fixturecad.registration.engine import register_touches

    out_dir = built("inclined-plane-cylinder")
    document = json.loads((out_dir / "features.json").read_text())
    features, candidates = features_from_json(document), planning.stored_candidates(document)
    touches = {}
    for entry in document["plans"]["default"]["touch_plan"]:
        touches.setdefault(entry["feature"], []).extend(entry["points"])
    (tmp_path / "t.csv").write_text("feature,x,y,z\n" + "".join(
        f"{fid},{x!r},{y!r},{z!r}\n" for fid, points in touches.items() for x, y, z in points))
    # An exact part, as the library's call below: the print's tolerance weighs the touches otherwise.
    out = run("register", out_dir, tmp_path / "t.csv", "--json", "--fixture-tolerance", "0")
    assert out.returncode == 0, out.stderr
    mine = json.loads(out.stdout)["next_touch"]
    library = register_touches(features, {k: np.array(v) for k, v in touches.items()}, plan_next=True,
                               candidates=candidates)["next_touch"]
    assert (mine["feature"], mine["point_fixture_mm"]) == (library["feature"], library["point_fixture_mm"])
    assert np.allclose(mine["approach_meas"], library["approach_meas"], atol=1e-9)
    point, approach = np.array(mine["point_fixture_mm"]), np.array(mine["approach_meas"])
    mesh = load_mesh(out_dir / "fixture.stl")
    pose = np.array(json.loads(out.stdout)["pose"])
    assert reachable(mesh.triangles, point[None], -(approach @ pose[:3, :3])[None]).all()
    # The same touches: the stored candidates are the planner's reachable ones, found on the mesh.
    ids = [fid for fid in features if fid in candidates]
    found = planning.candidate_points(features, ids, document["touch_candidates"]["margin_mm"],
                                      keep=lambda p, n: reachable(mesh.triangles, p, n))
    assert all(np.array_equal(found[fid], candidates[fid]) for fid in ids)
