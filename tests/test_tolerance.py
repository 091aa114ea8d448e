"""Manufacturing tolerance, datum frames and calibration (numpy only, no CAD)."""

import numpy as np
import pytest

from fixturecad.registration.calibration import calibrate
from fixturecad.registration.datums import DatumScheme, frame_change, in_datum_frame
from fixturecad.registration.deviations import FixtureTolerance
from fixturecad.registration.patches import patch_points
from fixturecad.registration.pose import fixture2meas_from_rt, pose_errors, random_rotation, vector_from_rotation
from fixturecad.registration.tolerance import coordinates, deviated, modes, moved, random_coordinates
from fixturecad.templates import TEMPLATES

NAMES = sorted(TEMPLATES)


def nominal(name):
    template = TEMPLATES[name]()
    return template, {f.id: f for f in template.features()}


def point_touches_of(template):
    """The point touches of a template's default plan, by feature (its sensors left out)."""
    touches = {}
    for entry in template.touch_plans()["default"].touches:
        if "sensor" not in entry:
            touches.setdefault(entry["feature"], []).extend(np.reshape(entry["points"], (-1, 3)).tolist())
    return touches


@pytest.mark.parametrize("name", NAMES)
def test_mode_coordinates_read_back(name):
    """A feature deviated by known coordinates reads them back (to second order in the deviation)."""
    _, features = nominal(name)
    rng = np.random.default_rng(1)
    for feature in features.values():
        m = modes(feature)
        c = random_coordinates(m, 0.2, rng)
        assert np.allclose(coordinates(m, deviated(m, c)), c, atol=1e-6)


@pytest.mark.parametrize("name", NAMES)
def test_a_part_within_its_modes_stays_in_the_zone(name):
    """Every coordinate within its range keeps every patch point within +-zone/2 of the drawing."""
    _, features = nominal(name)
    rng = np.random.default_rng(2)
    zone = 0.2
    worst = 0.0
    for feature in features.values():
        m = modes(feature)
        points = patch_points(feature)
        for _ in range(50):
            extreme = m.half_range * zone * rng.choice([-1.0, 1.0], size=len(m.names))  # corners of the box
            printed = deviated(m, extreme).closest_point(points)
            worst = max(worst, float(np.abs(feature.signed_distance(printed)).max()))
    assert worst <= zone / 2 * 1.01  # the shares hold to first order in the deviation
    assert worst > 0.3 * zone / 2  # the shares use the zone, not a sliver of it


def test_inclined_plane_cylinder_frame_is_the_papers():
    """Example Two: Z along the axis, origin where it meets the plane, Y = n x Z: the nominal frame itself."""
    template, features = nominal("inclined-plane-cylinder")
    assert np.allclose(template.DATUMS.frame(features), np.eye(4), atol=1e-12)


@pytest.mark.parametrize("name", NAMES)
def test_datum_frame_moves_with_the_part(name):
    """The construction is equivariant: moving the part moves its datum frame alike."""
    template, features = nominal(name)
    rng = np.random.default_rng(3)
    R, t = random_rotation(rng), rng.uniform(-50, 50, 3)
    moved_part = {fid: moved(f, R, t) for fid, f in features.items()}
    g = fixture2meas_from_rt(R, t)
    assert np.allclose(template.DATUMS.frame(moved_part), g @ template.DATUMS.frame(features), atol=1e-9)


@pytest.mark.parametrize("name", NAMES)
def test_seen_from_the_datum_frame(name):
    """The linear gauge projection matches the exact re-expression of a printed part in its datum frame."""
    template, features = nominal(name)
    tolerance = FixtureTolerance(features, template.DATUMS, 0.1)
    rng = np.random.default_rng(4)
    part = tolerance.random_part(rng)
    delta = np.concatenate([coordinates(tolerance.modes[f], part[f]) for f in features])
    seen = in_datum_frame(template.DATUMS, features, part)
    exact = np.concatenate([coordinates(tolerance.modes[f], seen[f]) for f in features])
    assert np.abs(tolerance.projection @ delta - exact).max() < 1e-3 * np.abs(delta).max()
    # The datum features define the frame: seen from it, they lose as many coordinates as the frame has.
    assert np.linalg.matrix_rank(tolerance.covariance, 1e-12 * np.abs(tolerance.covariance).max()) == tolerance.size - 6


def test_unknown_and_incomplete_datum_schemes():
    _, features = nominal("cube")
    with pytest.raises(ValueError, match="unknown datum construction"):
        DatumScheme("circles", ("top",))
    with pytest.raises(ValueError, match="not a feature"):
        FixtureTolerance(features, DatumScheme("planes", ("top", "front", "back")), 0.1)
    parallel = dict(features, back=moved(features["front"], np.diag([1.0, -1.0, -1.0]), np.zeros(3)))
    with pytest.raises(ValueError, match="do not fix the frame"):
        FixtureTolerance(parallel, DatumScheme("planes", ("top", "front", "back")), 0.1)


def measured(features, part, fixture2meas, rng, count, noise_mm):
    """Points measured on a printed part: spread over each patch, in the measurement frame."""
    out = {}
    for fid, feature in features.items():
        points = patch_points(feature)
        printed = part[fid].closest_point(points[rng.choice(len(points), count)])
        out[fid] = printed @ fixture2meas[:3, :3].T + fixture2meas[:3, 3] + rng.normal(scale=noise_mm, size=printed.shape)
    return out


@pytest.mark.parametrize("name", NAMES)
def test_calibration_recovers_the_printed_part(name):
    """Known deviations (three times the recorded tolerance) come back within their stated uncertainty."""
    template, features = nominal(name)
    tolerance = FixtureTolerance(features, template.DATUMS, 0.1)
    rng = np.random.default_rng(5)
    part = tolerance.random_part(rng, zone_mm=0.3)
    truth = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-200, 200, 3))
    result = calibrate(features, template.DATUMS, measured(features, part, truth, rng, 200, 0.002), 0.002, 0.1)
    seen = in_datum_frame(template.DATUMS, features, part)
    scores = []
    for fid in features:
        true = coordinates(tolerance.modes[fid], seen[fid])
        sd = np.sqrt(np.diag(result.covariances[fid]))
        free = sd > 1e-9
        scores.extend(((result.deviations[fid] - true)[free] / sd[free]).tolist())
    assert np.abs(scores).max() < 4.5 and 0.4 < np.sqrt(np.mean(np.square(scores))) < 1.6
    dt, dr = pose_errors(result.fixture2meas, truth @ frame_change(template.DATUMS, features, part))
    assert dt < 0.005 and dr < 1e-4


LINE_ON_LEFT = np.column_stack([np.zeros(50), np.linspace(5.0, 45.0, 50), np.full(50, 25.0)])
REFUSALS = {
    # Points on one line of a plane leave its tilt across that line undetermined.
    "a mode left open": (lambda points, rng: points.update(left=LINE_ON_LEFT), "left leave its tilt_.*undetermined"),
    "another fixture's points": (lambda points, rng: points.update(
        top=points["top"] + rng.normal(scale=3.0, size=points["top"].shape)), "not from this fixture"),
    "a feature not measured": (lambda points, rng: points.pop("front"), "no points on feature front"),
}


@pytest.mark.parametrize("case", sorted(REFUSALS))
def test_calibration_refuses_with_the_reason(case):
    template, features = nominal("cube")
    rng = np.random.default_rng(6)
    points = measured(features, features, np.eye(4), rng, 50, 0.001)
    spoil, reason = REFUSALS[case]
    spoil(points, rng)
    with pytest.raises(ValueError, match=reason):
        calibrate(features, template.DATUMS, points, 0.001, 0.1)


def _covariance_check(name, zone_mm, trials, seed):
    """Registration of touches on random printed parts: coverage of the 95 % ellipsoid, sigma vs RMS, statuses."""
    from fixturecad.registration.engine import register_touches

    template, features = nominal(name)
    tolerance = FixtureTolerance(features, template.DATUMS, zone_mm)
    plans = template.touch_plans()
    entries = [e for e in plans.get("point-probe", plans["default"]).touches if "sensor" not in e]
    rng = np.random.default_rng(seed)
    inside, errors, sigmas, inconsistent = 0, [], [], 0
    for _ in range(trials):
        part = tolerance.random_part(rng)
        cad2meas = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-100, 100, 3))
        truth = cad2meas @ frame_change(template.DATUMS, features, part)
        touches = {}
        for entry in entries:
            printed = part[entry["feature"]].closest_point(np.asarray(entry["points"], float).reshape(-1, 3))
            meas = printed @ cad2meas[:3, :3].T + cad2meas[:3, 3] + rng.normal(scale=0.005, size=printed.shape)
            touches.setdefault(entry["feature"], []).extend(meas)
        result = register_touches(features, touches, initial_pose=truth, sigma_mm=0.005, tolerance=tolerance)
        inconsistent += result["status"] == "inconsistent"
        if result["pose"] is None:  # inconsistent, not explained by one touch: counted outside the ellipsoid
            continue
        pose = np.array(result["pose"])
        error = np.concatenate([vector_from_rotation(pose[:3, :3] @ truth[:3, :3].T), pose[:3, 3] - truth[:3, 3]])
        inside += error @ np.linalg.solve(np.array(result["covariance"]), error) <= 12.592  # chi2(6), 95 %
        errors.append(np.linalg.norm(error[3:]))
        sigmas.append(result["sigma_translation_mm"])
    return inside / trials, float(np.mean(sigmas) / np.sqrt(np.mean(np.square(errors)))), inconsistent / trials


@pytest.mark.parametrize("name", ["inclined-plane-cylinder", "sphere-plate"])
def test_reported_covariance_is_honest_on_a_printed_part(name):
    """Issue 7: the true datum-frame pose lies in the 95 % ellipsoid in >= 90 % of trials, the reported
    sigma is within [0.5, 2] x the RMS error, and at most 2 % are called inconsistent."""
    coverage, ratio, inconsistent = _covariance_check(name, 0.1, 150, 9)
    assert coverage >= 0.9 and 0.5 <= ratio <= 2.0 and inconsistent <= 0.02


@pytest.mark.parametrize("name, fid, mode, amount", [
    ("quarter-sphere", "sphere", "radius_mm", 1.0),
    ("inclined-plane-cylinder", "cylinder", "radius_mm", 0.5),
    ("sphere-plate", "ball_2", "radius_mm", 0.5),
])
def test_a_feature_beyond_its_tolerance_is_named(name, fid, mode, amount):
    """A printed feature far outside the zone makes the touches inconsistent, and the smallest
    deviation that explains them is that feature's, with its size."""
    from fixturecad.registration.engine import register_touches

    template, features = nominal(name)
    tolerance = FixtureTolerance(features, template.DATUMS, 0.1)
    m = tolerance.modes[fid]
    part = dict(features, **{fid: deviated(m, amount * (np.array(m.names) == mode))})
    plans = template.touch_plans()
    entries = [e for e in plans.get("point-probe", plans["default"]).touches if "sensor" not in e]
    rng = np.random.default_rng(0)
    truth = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-100, 100, 3))
    touches = {}
    for entry in entries:
        printed = part[entry["feature"]].closest_point(np.asarray(entry["points"], float).reshape(-1, 3))
        touches.setdefault(entry["feature"], []).extend(
            printed @ truth[:3, :3].T + truth[:3, 3] + rng.normal(scale=0.005, size=printed.shape))
    result = register_touches(features, touches, sigma_mm=0.005, tolerance=tolerance)
    assert result["status"] == "inconsistent"
    first = result["fixture_flagged"][0]
    assert (first["feature"], first["mode"]) == (fid, mode)
    assert first["departure_mm"] == pytest.approx(amount, rel=0.05)


@pytest.mark.parametrize("name", NAMES)
def test_rows_whitened_for_the_print_as_the_dense_covariance_says(name):
    """The low-rank whitening W (W^T W = C^-1, C = I + J_d S J_d^T / sigma^2) against C solved densely."""
    from fixturecad.registration.deviations import deviation_rows, whitening
    from fixturecad.registration.problem import Problem
    from fixturecad.registration.touches import build_groups

    template, features = nominal(name)
    tolerance = FixtureTolerance(features, template.DATUMS, 0.1)
    touches = point_touches_of(template)
    problem = Problem(build_groups(features, touches), 0.005, tolerance=tolerance)
    r, J = problem.sensor_rows(np.eye(3), np.zeros(3))
    Jd = deviation_rows(problem, tolerance, np.eye(3), np.zeros(3), J)
    C = np.eye(len(r)) + Jd @ tolerance.covariance @ Jd.T / problem.sigma**2
    whiten = whitening(tolerance, Jd, problem.sigma)
    W = whiten(np.eye(len(r)))
    assert np.allclose(W, W.T) and np.allclose(W.T @ W, np.linalg.inv(C), atol=1e-9)
    assert np.allclose(whiten(r), W @ r) and np.allclose(whiten(J), W @ J)


@pytest.mark.parametrize("name", NAMES)
def test_the_radius_derivative_is_the_central_difference(name):
    """Rows take their change with a feature's radius as -1 for point touches on a sphere or cylinder and 0 on a
    feature with none (:func:`.problem.radius_change`): the same, to 1e-9, as the central difference of the rows
    with the radius grown and shrunk, which sensors on a sphere or cylinder take; at five poses of each template's
    default plan, its sensors too, and of its point touches alone."""
    from fixturecad.registration.problem import Problem, _radius_difference
    from fixturecad.registration.synthetic import plan_touches
    from fixturecad.registration.touches import build_groups

    template, features = nominal(name)
    rng = np.random.default_rng(5)
    for _ in range(5):
        R, t = random_rotation(rng), rng.uniform(-50, 50, 3)
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = R, t
        touches, contacts = plan_touches(template.touch_plans()["default"].touches, pose)
        for groups in (build_groups(features, point_touches_of(template)), build_groups(features, touches,
                                                                                          contacts=contacts)):
            problem = Problem(groups, 0.005)  # (a fresh one: it keeps a derivative per pose)
            central = _radius_difference(lambda grow: problem.sensor_rows(R, t, grow)[0])
            assert np.allclose(problem.radius_derivative(R, t), central, atol=1e-9)


@pytest.mark.parametrize("design", ["{G3}{R-R-C}{S-T2}", "{R}{C-R-C}", "{R}{G3-R}"])
def test_sensors_on_a_sphere_or_cylinder_take_the_central_difference(design):
    """Designs whose plans put line and point-line sensors on cylinders (tests/search_cases.py): their rows'
    change with the radius is the central difference (whitened, not -1), at five poses about the truth of one
    layout each (:meth:`.Problem.radius_derivative`); and on the printed part the batch
    (:meth:`.Problem.evaluate_batch`, which takes the same derivatives group by group) gives each pose's cost as
    one pose at a time does (a ball's three rows come in either frame)."""
    from search_cases import VARIANTS, layout

    from fixturecad.registration.pose import rotation_from_vector
    from fixturecad.registration.problem import Problem, _radius_difference, radius_change
    from fixturecad.registration.touches import build_groups

    lay = layout(*next((case, noise) for case, noise in VARIANTS
                       if case.name == f"{design} design (default plan)" and noise == 0.0), 1000)
    groups = build_groups(lay.features, lay.touches, contacts=lay.contacts)
    assert any(radius_change(g) is None for g in Problem(groups, 0.005).batches)
    rng = np.random.default_rng(6)
    R = rotation_from_vector(rng.normal(0, 0.01, (5, 3))) @ lay.truth[:3, :3]
    t = lay.truth[:3, 3] + rng.uniform(-1, 1, (5, 3))
    printed = Problem(groups, 0.005, tolerance=lay.tolerance)
    batched = printed.evaluate_batch(R, t)[0]
    for k in range(5):
        problem = Problem(groups, 0.005)  # (a fresh one: it keeps a derivative per pose)
        central = _radius_difference(lambda grow: problem.sensor_rows(R[k], t[k], grow)[0])
        assert np.allclose(problem.radius_derivative(R[k], t[k]), central, atol=1e-9)
        one = Problem(groups, 0.005, tolerance=lay.tolerance).evaluate(R[k], t[k])[0]
        assert np.isclose(batched[k] @ batched[k], one @ one, rtol=1e-9)


def test_ten_thousand_touches_on_a_printed_part_take_memory_linear_in_rows():
    """Evaluating 10,000 rows on a printed part allocates a few MB, not the 800 MB of a dense covariance."""
    import tracemalloc

    from fixturecad.registration.problem import Problem
    from fixturecad.registration.touches import build_groups

    template, features = nominal("cube")
    rng = np.random.default_rng(2)
    touches = {"top": np.column_stack([rng.uniform(5, 45, (3334, 2)), np.full(3334, 50.0)]),
               "front": np.column_stack([rng.uniform(5, 45, 3333), np.zeros(3333), rng.uniform(5, 45, 3333)]),
               "left": np.column_stack([np.zeros(3333), rng.uniform(5, 45, (3333, 2))])}
    problem = Problem(build_groups(features, touches), 0.005, tolerance=FixtureTolerance(features, template.DATUMS, 0.1))
    tracemalloc.start()
    try:
        r, J = problem.evaluate(np.eye(3), np.zeros(3))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert r.shape == (10_000,) and np.abs(r).max() < 1e-9
    assert peak < 50e6, peak
