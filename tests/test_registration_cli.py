"""`fixturecad register | simulate` on built fixtures; touches sampled on the STL mesh."""

import json

import numpy as np
import pytest

from cli import assert_bad_input, run
from fixturecad.registration.engine import register_touches
from fixturecad.registration.problem import Problem
from fixturecad.registration.touches import build_groups
from fixturecad.registration.uncertainty import cramer_rao_bound, sigmas
from fixturecad.registration.pose import pose_errors

templates = pytest.importorskip("fixturecad.templates")
NAMES = sorted(templates.TEMPLATES)


def _sampler(folder, random_positions=False):
    from fixturecad.registration.sampling import TouchSampler, load_mesh

    document = json.loads((folder / "features.json").read_text())
    return document, TouchSampler(document, load_mesh(folder / "fixture.stl"), "default", random_positions)


@pytest.mark.parametrize("name", NAMES)
def test_touches_on_the_mesh_give_the_pose_within_the_chord_tolerance(name, built):
    folder = built(name)
    document, sampler = _sampler(folder, random_positions=True)
    chord = document["files"]["stl_tolerance_mm"]
    sigma = chord / np.sqrt(3.0)
    rng = np.random.default_rng(21)
    statuses = []
    for _ in range(10):
        touches, contacts, truth = sampler.draw(rng, 0.0)
        result = register_touches(sampler.features, touches, sigma_mm=sigma, contacts=contacts)
        statuses.append(result["status"])
        # Every touch within the chord tolerance of its feature at the recovered pose, unless the random
        # places leave the pose too weak to claim (a 3-2-1 with touches bunched): then the weak motion is named.
        assert result["status"] in ("unique", "underdetermined"), result["status"]
        if result["status"] == "underdetermined":
            assert len(result["free_motions"]) == 1 and result["sigma_translation_mm"] > 0.1
        assert result["rms_residual_mm"] <= chord
        # ... and the pose as close as that tolerance allows (3 sigma of its propagated error).
        problem = Problem(build_groups(sampler.features, touches, 0.0, contacts), sigma)
        bound_t, bound_r = sigmas(cramer_rao_bound(problem, truth, chord))
        dt, dr = pose_errors(np.array(result["pose"]), truth)
        assert dt <= 3.0 * bound_t + 1e-6
        assert np.degrees(dr) <= 3.0 * bound_r + 1e-6
    assert statuses.count("unique") >= 7


def _touch_csv(path, touches):
    lines = ["feature,x,y,z"] + [
        ",".join([k] + [repr(float(x)) for x in p]) for k, v in touches.items() for p in v
    ]
    path.write_text("\n".join(lines) + "\n")


def test_register_command_wraps_the_generated_routine(built, tmp_path):
    folder = built("cube")
    _, sampler = _sampler(folder)
    touches, _, truth = sampler.draw(np.random.default_rng(2), 0.0)
    _touch_csv(tmp_path / "touches.csv", touches)
    out = run("register", folder, tmp_path / "touches.csv", "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["status"] == "unique"
    assert max(pose_errors(np.array(result["pose"]), truth)) < 1e-3
    text = run("register", folder, tmp_path / "touches.csv")
    assert text.returncode == 0 and "status: unique" in text.stdout


def test_format_json_prints_only_json(built, tmp_path):
    """--format json: stdout parses, the status and the report's lines inside, for the CLI and register.py."""
    import subprocess
    import sys

    folder = built("cube")
    underdetermined = tmp_path / "same.csv"
    underdetermined.write_text("feature,x,y,z\n" + "top,10,10,50\n" * 6)
    for touches, status, code in ((folder / "touches.template.csv", "unique", 0), (underdetermined, "underdetermined", 4)):
        for out in (run("register", folder, touches, "--format", "json"),
                    subprocess.run([sys.executable, str(folder / "register.py"), str(touches), "--format", "json"],
                                   capture_output=True, text=True)):
            assert out.returncode == code, out.stderr
            document = json.loads(out.stdout)
            assert document["status"] == status and f"status: {status}" in document["report"]
            assert "quaternion_wxyz" in document and "sigma" in document


@pytest.mark.parametrize(
    "content,words",
    [
        ("feature,x,y,z\nnope,1,2,3\n", "unknown feature 'nope'"),
        ("feature,x,y,z\ntop,1,2,nan\n", "finite"),
        ("x,y,z\n1,2,3\n", "columns"),
        ("", "empty"),
        ("feature,x,y,z\ntop,1,2,3\n", "too few touches"),
    ],
)
def test_register_command_refuses_bad_touch_files(built, tmp_path, content, words):
    folder = built("cube")
    (tmp_path / "touches.csv").write_text(content)
    assert_bad_input(run("register", folder, tmp_path / "touches.csv"), words)


def test_register_command_needs_a_built_folder(tmp_path):
    (tmp_path / "touches.csv").write_text("feature,x,y,z\n")
    assert_bad_input(run("register", tmp_path, tmp_path / "touches.csv"), "no features.json", "fixturecad build")
    assert_bad_input(run("simulate", tmp_path / "missing"), "does not exist")


def test_simulate_reports_errors_against_the_bound_and_writes_a_plot(built):
    folder = built("v-block")
    out = run("simulate", folder, "--trials", 40, "--noise", 0.005, "--seed", 1)
    assert out.returncode == 0, out.stderr
    for words in ("median", "95th percentile", "Cramer-Rao", "success: 100.0 %"):
        assert words in out.stdout
    assert (folder / "simulation.png").stat().st_size > 1000
    summary = json.loads((folder / "simulation.json").read_text())
    assert summary["trials"] == 40 and summary["success_rate"] == 1.0
    assert 0.7 < summary["ratio_translation_to_crb"] < 1.5
    before = (folder / "simulation.json").read_bytes()
    assert_bad_input(run("simulate", folder, "--trials", 10), "pass --force")
    assert (folder / "simulation.json").read_bytes() == before
    random_plan = run("simulate", folder, "--trials", 10, "--plan", "random", "--nominal", "--force")
    assert random_plan.returncode == 0, random_plan.stderr
    assert json.loads((folder / "simulation.json").read_text())["plan"] == "random"


def test_simulate_gives_the_same_trials_in_one_process_or_several(built, tmp_path):
    """Each trial draws from its own generator of the seed: two worker processes give what one process gives
    (the summary whole but its time), and another seed something else."""
    folder = built("cube")
    summaries = []
    for jobs, seed in ((1, 5), (2, 5), (2, 6)):
        out = run("simulate", folder, "--trials", 8, "--seed", seed, "--jobs", jobs, "--out", tmp_path / f"{jobs}-{seed}")
        assert out.returncode == 0, out.stderr
        summary = json.loads((tmp_path / f"{jobs}-{seed}" / "simulation.json").read_text())
        summaries.append({key: value for key, value in summary.items() if key != "median_time_ms"})
    assert summaries[0] == summaries[1] and summaries[2] != summaries[0]


def test_simulate_writes_where_out_says(built, tmp_path):
    folder = built("cube")
    out = run("simulate", folder, "--trials", 3, "--out", tmp_path / "sim")
    assert out.returncode == 0, out.stderr
    assert sorted(p.name for p in (tmp_path / "sim").iterdir()) == ["simulation.json", "simulation.png"]
    assert f"plot: {tmp_path / 'sim' / 'simulation.png'}" in out.stdout
    # Again, after a killed run (its pid does not run) left its temporary folder there: it is cleared.
    (tmp_path / "sim" / ".sim.999999999.tmp").mkdir()
    assert run("simulate", folder, "--trials", 3, "--out", tmp_path / "sim", "--force").returncode == 0
    assert sorted(p.name for p in (tmp_path / "sim").iterdir()) == ["simulation.json", "simulation.png"]


def test_simulate_refuses_bad_options(built):
    folder = built("cube")
    assert_bad_input(run("simulate", folder, "--trials", 0), "--trials")
    assert_bad_input(run("simulate", folder, "--noise", -1), "--noise")
    assert_bad_input(run("simulate", folder, "--lever", 0), "--lever")
    assert_bad_input(run("simulate", folder, "--touch-plan", "nope"), "unknown touch plan 'nope'")


def test_simulate_s_ratio_to_the_bound_takes_the_unique_trials_alone():
    """An ambiguous trial's pose (another that fits as well, far off) and an underdetermined one's unbounded bound
    stay out of the ratio: RMS error and RMS bound over the same unique trials."""
    from fixturecad.registration_commands import format_summary, summarise

    def record(status, error_mm, bound_mm):
        return {"status": status, "translation_error_mm": error_mm, "rotation_error_deg": error_mm,
                "crb_translation_mm": bound_mm, "crb_rotation_deg": bound_mm, "time_s": 0.01}

    records = [record("unique", 0.003, 0.004), record("unique", 0.005, 0.004), record("ambiguous", 80.0, 0.004),
               record("underdetermined", 0.1, float("inf"))]
    s = summarise(records, 0.005)
    assert s["unique_trials"] == 2
    assert s["ratio_translation_to_crb"] == pytest.approx(np.sqrt((0.003**2 + 0.005**2) / 2) / 0.004)
    s.update(trials=4, noise_mm=0.005, plan="default", touch_plan="default", fixture_tolerance_mm=None)
    assert "over the 2 unique trials" in format_summary(s)
    # The bound's RMS line: the underdetermined trial's unbounded bound left out, not averaged to infinity.
    assert s["crb_translation_mm"] == pytest.approx(0.004)
    s = summarise(records[2:], 0.005)
    assert s["ratio_translation_to_crb"] is None
    s.update(trials=2, noise_mm=0.005, plan="default", touch_plan="default", fixture_tolerance_mm=None)
    assert "no unique trial" in format_summary(s)
