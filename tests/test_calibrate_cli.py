"""The printed part from the command line: `build --fixture-tolerance`, `simulate` on a printed part,
`calibrate` to an as-built folder, and registration on it."""

import json

import numpy as np
import pytest

from cli import assert_bad_input, run
from fixturecad.registration.datums import frame_change
from fixturecad.registration.deviations import tolerance_from_document
from fixturecad.registration.features import features_from_json
from fixturecad.registration.patches import patch_points
from fixturecad.registration.pose import fixture2meas_from_rt, random_rotation


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    folder = tmp_path_factory.mktemp("printed") / "cube"
    result = run("build", "cube", "--out", folder, "--fixture-tolerance", 0.1)
    assert result.returncode == 0, result.stderr
    return folder


def measurement_file(folder, path, zone_mm, count, seed, noise_mm=0.002):
    """Points measured on a part printed within ``zone_mm``, in a random frame: (its deviations, truth)."""
    document = json.loads((folder / "features.json").read_text())
    features = features_from_json(document)
    tolerance = tolerance_from_document(features, document, zone_mm)
    rng = np.random.default_rng(seed)
    deviations = tolerance.random_deviations(rng)
    part = tolerance.part(deviations)
    cad2meas = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-300, 300, 3))
    lines = ["feature,x,y,z"]
    for fid, feature in features.items():
        points = patch_points(feature)
        points = part[fid].closest_point(points[rng.choice(len(points), count)])
        meas = points @ cad2meas[:3, :3].T + cad2meas[:3, 3] + rng.normal(scale=noise_mm, size=points.shape)
        lines += [f"{fid},{x:.6f},{y:.6f},{z:.6f}" for x, y, z in meas]
    path.write_text("\n".join(lines) + "\n")
    return tolerance, deviations, cad2meas @ frame_change(tolerance.scheme, features, part)


def test_build_records_tolerance_and_datums(cube):
    document = json.loads((cube / "features.json").read_text())
    assert document["tolerance"]["zone_mm"] == 0.1
    assert [d["feature"] for d in document["datums"]["features"]] == ["top", "front", "left"]
    assert [d["role"] for d in document["datums"]["features"]] == ["primary", "secondary", "tertiary"]


def test_bad_fixture_tolerance(tmp_path, cube):
    assert_bad_input(run("build", "cube", "--out", tmp_path / "x", "--fixture-tolerance", -1), "--fixture-tolerance")
    assert not (tmp_path / "x").exists()
    assert_bad_input(run("simulate", cube, "--fixture-tolerance", "nan"), "--fixture-tolerance")


def test_simulate_splits_the_error_on_a_printed_part(cube, tmp_path):
    out = run("simulate", cube, "--trials", 30, "--seed", 3, "--touch-plan", "default")
    assert out.returncode == 0, out.stderr
    summary = json.loads((cube / "simulation.json").read_text())
    assert summary["fixture_tolerance_mm"] == 0.1
    # The parts contribute to the error, and the parts' share is what the printed run adds to the noise.
    assert summary["fixture_only_rms_translation_error_mm"] > 0.5 * summary["noise_only_rms_translation_error_mm"]
    total = np.hypot(summary["noise_only_rms_translation_error_mm"], summary["fixture_only_rms_translation_error_mm"])
    assert summary["rms_translation_error_mm"] == pytest.approx(total, rel=0.35)
    assert "RMS error from the printed part" in out.stdout


def test_calibrate_then_register_on_the_printed_part(cube, tmp_path):
    """Issue 7: after calibration the printed part registers within 1.5 x the touch-noise bound."""
    measurements = tmp_path / "cmm.csv"
    tolerance, deviations, _ = measurement_file(cube, measurements, 0.3, 300, seed=4)
    asbuilt = tmp_path / "cube-asbuilt"
    out = run("calibrate", cube, measurements, "--out", asbuilt, "--sigma", 0.002)
    assert out.returncode == 0, out.stderr
    assert {"features.json", "register.py", "calibration.png", "fixture.stl"} <= {p.name for p in asbuilt.iterdir()}
    document = json.loads((asbuilt / "features.json").read_text())
    assert document["calibration"]["source"] == str(measurements)
    assert sum(e["points"] for e in document["calibration"]["features"].values()) == 900
    # The printed part (0.3 mm zone) is named where it leaves the recorded 0.1 mm zone.
    verdicts = document["calibration"]["features"]
    assert all(fid in out.stdout for fid in verdicts)
    assert ("OUT" in out.stdout) == any(not entry["within_tolerance"] for entry in verdicts.values())
    assert any(not entry["within_tolerance"] for entry in verdicts.values())
    # Simulated registration on the as-built folder: the part's own error is gone.
    sim = run("simulate", asbuilt, "--trials", 40, "--seed", 5, "--touch-plan", "default")
    assert sim.returncode == 0, sim.stderr
    summary = json.loads((asbuilt / "simulation.json").read_text())
    assert summary["calibrated"]
    assert summary["rms_translation_error_mm"] <= 1.5 * summary["noise_crb_translation_mm"]
    assert summary["rms_rotation_error_deg"] <= 1.5 * summary["noise_crb_rotation_deg"]
    # Nothing is replaced without --force; an as-built folder is not calibrated again.
    assert_bad_input(run("calibrate", cube, measurements, "--out", asbuilt), "already exists")
    assert_bad_input(run("calibrate", asbuilt, measurements), "already an as-built folder")


BAD_MEASUREMENTS = {
    "unknown feature": ("feature,x,y,z\nnope,1,2,3\n", "unknown feature 'nope'"),
    "NaN": ("feature,x,y,z\ntop,nan,2,3\n", "finite"),
    "a feature not measured": ("feature,x,y,z\ntop,1,2,3\ntop,4,5,6\ntop,7,8,9\n", "no points on feature"),
}


@pytest.mark.parametrize("case", sorted(BAD_MEASUREMENTS))
def test_calibrate_bad_input_writes_nothing(cube, tmp_path, case):
    text, words = BAD_MEASUREMENTS[case]
    (tmp_path / "m.csv").write_text(text)
    assert_bad_input(run("calibrate", cube, tmp_path / "m.csv", "--out", tmp_path / "out"), words)
    assert not (tmp_path / "out").exists()


def test_calibrate_refuses_another_fixtures_points(cube, tmp_path):
    other = tmp_path / "ball"
    assert run("build", "sphere-plate", "--out", other).returncode == 0
    measurement_file(other, tmp_path / "ball.csv", 0.1, 50, seed=6)
    text = (tmp_path / "ball.csv").read_text().replace("ball_1", "top").replace("ball_2", "front").replace("ball_3", "left")
    (tmp_path / "m.csv").write_text(text)
    assert_bad_input(run("calibrate", cube, tmp_path / "m.csv", "--out", tmp_path / "out"), "not from this fixture")
    assert not (tmp_path / "out").exists()
