"""Touch files a user writes, and what `register` prints from them: the JSON schema and its documented
examples, file rows in every message, the pose in each controller's convention, exit codes."""

import json
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
from jsonschema.validators import validator_for

from cli import assert_bad_input, run
from fixturecad.registration.controllers import FORMATS, pose_from_format
from fixturecad.registration.elements import ELEMENTS
from fixturecad.registration.features import features_from_json
from fixturecad.registration.problem import Problem
from fixturecad.registration.touches import build_groups
from fixturecad.registration.touchfile import ENTRY_KEYS, read_touch_json, touch_json
from fixturecad.registration.verdict import inadmissible

ROOT = Path(__file__).resolve().parent.parent
SCHEMA = json.loads(resources.files("fixturecad").joinpath("schema/touches.schema.json").read_text())


def validate(document):
    validator_for(SCHEMA)(SCHEMA).validate(document)


def documented_examples():
    """(fixture, JSON text) of every example of docs/touch-files.md."""
    text = (ROOT / "docs" / "touch-files.md").read_text()
    return re.findall(r"<!-- fixture: ([a-z-]+) -->\n```json\n(.*?)```", text, flags=re.S)


def test_the_schema_is_a_valid_schema_with_the_readers_keys():
    validator_for(SCHEMA).check_schema(SCHEMA)
    assert set(SCHEMA["$defs"]["entry"]["properties"]) == ENTRY_KEYS
    # A sensor has the geometry keys of its element in the one element table.
    sensors = {variant["properties"]["kind"]["const"]: set(variant["required"]) - {"kind"}
               for variant in SCHEMA["$defs"]["sensor"]["oneOf"]}
    assert sensors == {e.kind: set(e.json_keys) for e in ELEMENTS}


def test_every_documented_example_is_valid_and_lies_on_its_features(built):
    examples = documented_examples()
    assert len(examples) == 6
    contacts = set()
    for fixture, text in examples:
        document = json.loads(text)
        validate(document)
        features = features_from_json(json.loads((built(fixture) / "features.json").read_text()))
        touches, sensors, radius, approaches, rows = read_touch_json(text, features)
        problem = Problem(build_groups(features, touches, radius, sensors, approaches))
        residuals, _ = problem.evaluate(np.eye(3), np.zeros(3))
        assert np.abs(residuals * problem.sigma).max() < 2e-6, (fixture, text)
        assert not inadmissible(problem, np.eye(3), np.zeros(3))
        assert len(rows) == sum(len(v) for v in touches.values()) + len(sensors)
        contacts |= {g.ctype.name for g in problem.groups}
    assert {"P/F-PL/M", "P/F-S/M", "S/M-PL/M", "S/M-S/M", "PL/F-PL/F", "L/M-L/M", "PL/M-C/M", "L/M-C/M"} <= contacts


@pytest.mark.parametrize("name", ["cube", "quarter-sphere", "inclined-plane-cylinder"])
def test_the_build_writes_touch_templates_that_register_at_the_nominal_pose(built, name):
    folder = built(name)
    validate(json.loads((folder / "touches.template.json").read_text()))
    for template in ("touches.template.csv", "touches.template.json"):
        out = run("register", folder, folder / template, "--json")
        assert out.returncode == 0, out.stderr
        result = json.loads(out.stdout)
        assert result["status"] == "unique"
        assert np.abs(np.array(result["pose"]) - np.eye(4)).max() < 1e-4


def test_touch_json_reads_back_to_the_same_touches(built):
    features = features_from_json(json.loads((built("quarter-sphere") / "features.json").read_text()))
    text = (built("quarter-sphere") / "touches.template.json").read_text()
    touches, contacts, radius, _, _ = read_touch_json(text, features)
    again = read_touch_json(touch_json(touches, contacts, radius), features)
    assert again[1] == contacts and again[2] == radius
    assert all(np.array_equal(again[0][key], touches[key]) for key in touches)


@pytest.mark.parametrize("name", FORMATS)
def test_register_prints_the_pose_in_each_controllers_convention(built, tmp_path, name):
    """The printed numbers (from --json's controller entry) give back the registered 4x4."""
    folder = built("cube")
    pose = np.eye(4)
    pose[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    pose[:3, 3] = [812.5, -143.25, 96.0]
    touches = _moved(folder / "touches.template.csv", pose)
    path = tmp_path / "touches.csv"
    path.write_text(touches)
    out = run("register", folder, path, "--json", "--format", name)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    controller = result["controller"]
    assert controller["format"] == name and len(controller["sigmas"]) == len(controller["values"])
    assert np.abs(pose_from_format(name, controller["values"]) - np.array(result["pose"])).max() < 1e-9
    assert np.abs(np.array(result["pose"]) - pose).max() < 1e-6
    text = run("register", folder, path, "--format", name)
    assert text.returncode == 0
    if name == "json":  # only JSON on stdout: the pose's object, the status and report lines in it
        assert json.loads(controller["text"]).items() <= json.loads(text.stdout).items()
    else:
        assert controller["text"] in text.stdout


def test_the_generated_routine_takes_format_too(built):
    import subprocess
    import sys

    folder = built("cube")
    out = subprocess.run([sys.executable, str(folder / "register.py"), str(folder / "touches.template.csv"),
                          "--format", "kuka"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "; KUKA FRAME (BASE_DATA)" in out.stdout and "{X 0.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C 0.0}" in out.stdout
    bad = subprocess.run([sys.executable, str(folder / "register.py"), str(folder / "touches.template.csv"),
                          "--format", "staubli"], capture_output=True, text=True)
    assert bad.returncode == 2 and "invalid choice" in bad.stderr


def test_a_flagged_touch_is_named_by_its_row(built, tmp_path):
    """Redundant cube touches, one 0.5 mm off on row 9 (after three comment lines and the header)."""
    folder = built("cube")
    lines = (folder / "touches.template.csv").read_text().splitlines()
    extra = ["top,30.0,30.0,50.0", "front,30.0,0.0,30.0", "left,0.0,40.0,10.0", "top,15.0,35.0,50.0"]
    lines += extra
    off = lines.index("front,40.0000,0.0000,25.0000")
    lines[off] = "front,40.0000,0.5000,25.0000"
    path = tmp_path / "touches.csv"
    path.write_text("\n".join(lines) + "\n")
    out = run("register", folder, path)
    assert out.returncode == 5, out.stdout + out.stderr
    assert f"flagged: row {off + 1} of touches.csv on front (0.5000 mm off)" in out.stdout, out.stdout
    result = json.loads(run("register", folder, path, "--json").stdout)
    assert result["flagged"][0]["row"] == f"row {off + 1} of touches.csv"
    assert len(result["touch_rows"]) == result["touches"]


def _moved(path, pose):
    """A touch CSV's points moved by a pose (4x4): the touches of the fixture placed there."""
    rows = []
    for line in path.read_text().splitlines():
        cells = line.split(",")
        if line.startswith("#") or cells[0] == "feature":
            rows.append(line)
            continue
        x = pose[:3, :3] @ np.array(cells[1:], float) + pose[:3, 3]
        rows.append(",".join([cells[0], *(f"{v:.9f}" for v in x)]))
    return "\n".join(rows) + "\n"


def test_a_bad_json_touch_is_named_by_its_entry(built, tmp_path):
    folder = built("quarter-sphere")
    path = tmp_path / "touches.json"
    path.write_text(json.dumps({"touches": [{"feature": "flat_a", "points": [[0, 1, 0]]},
                                            {"feature": "sphere", "point": [0, 1, 0]}]}))
    assert_bad_input(run("register", folder, path), "touch 2", '"points"')


def test_a_gross_outlier_is_reported_with_its_real_distance(built, tmp_path):
    """A touch 1 m off: named with its distance, and the good touches are not called inadmissible."""
    folder = built("cube")
    lines = (folder / "touches.template.csv").read_text().splitlines()
    lines += ["top,30.0,30.0,50.0", "front,30.0,0.0,30.0", "left,0.0,40.0,10.0"]
    off = lines.index("front,10.0000,0.0000,25.0000")
    lines[off] = "front,10.0000,1000.0000,25.0000"
    path = tmp_path / "touches.csv"
    path.write_text("\n".join(lines) + "\n")
    result = json.loads(run("register", folder, path, "--json").stdout)
    assert result["status"] == "inconsistent"
    assert [flag["row"] for flag in result["flagged"]] == [f"row {off + 1} of touches.csv"]
    assert abs(result["flagged"][0]["residual_mm"] - 1000.0) < 0.01
    assert result["inadmissible"] == []
    assert np.abs(np.array(result["pose"]) - np.eye(4)).max() < 1e-6


# Issue 22: the shipped CSV templates are plans whose touches check each other.

def _template_touches(name):
    from fixturecad.build import touch_template
    from fixturecad.registration.deviations import FixtureTolerance
    from fixturecad.registration.touchfile import read_touch_csv
    from fixturecad.templates import make

    template = make(name)
    features = {f.id: f for f in template.features()}
    touches, _, _ = read_touch_csv(touch_template(template), list(features))
    return features, touches, FixtureTolerance(features, template.DATUMS, 0.1)


@pytest.mark.parametrize("name", ["cube", "inclined-plane-cylinder", "quarter-sphere", "sphere-plate", "v-block"])
def test_every_template_csv_checks_each_touch(name):
    from fixturecad.registration.engine import register_touches

    features, touches, tolerance = _template_touches(name)
    result = register_touches(features, touches, tolerance=tolerance)
    assert result["status"] == "unique" and result["redundancy"]["rows_beyond_six"] > 0
    assert result["redundancy"]["unchecked"] == []


def test_the_quarter_sphere_csv_finds_a_touch_half_a_millimetre_off():
    """Each touch in turn moved 0.5 mm off its surface: inconsistent, that touch among at most two flagged
    (the 7-touch point-probe plan it replaces said "7 touches could each explain it")."""
    from fixturecad.registration.engine import register_touches

    features, touches, tolerance = _template_touches("quarter-sphere")
    order = [(fid, k) for fid in touches for k in range(len(touches[fid]))]
    assert len(order) == 10
    for index, (fid, k) in enumerate(order):
        moved = {key: value.copy() for key, value in touches.items()}
        moved[fid][k] += 0.5 * features[fid].normal_at(moved[fid][k])[0]
        result = register_touches(features, moved, tolerance=tolerance)
        flagged = {flag["touch"] for flag in result["flagged"]}
        assert result["status"] == "inconsistent" and index in flagged and len(flagged) <= 2, (fid, k, flagged)


def test_repeated_rows_are_warned_of(built, tmp_path):
    folder = built("cube")
    lines = (folder / "touches.template.csv").read_text().splitlines()
    first = next(k for k, line in enumerate(lines) if line.startswith("top,"))
    path = tmp_path / "t.csv"
    path.write_text("\n".join(lines + [lines[first], lines[first]]) + "\n")
    out = run("register", folder, path)
    assert out.returncode == 0
    assert out.stderr == (f"fixturecad: warning: row {len(lines) + 1} of t.csv repeats row {first + 1} of t.csv "
                          "(and 1 more): a repeated touch checks nothing; touch again elsewhere\n")
    assert run("register", folder, folder / "touches.template.csv").stderr == ""
