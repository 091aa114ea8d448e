"""The generated standalone register.py: numpy and scipy only, same pose as the library."""

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fixturecad.registration.engine import register_touches
from fixturecad.registration.synthetic import perturb_touches, plan_touches
from fixturecad.registration.touchfile import touch_json
from fixturecad.registration.generate import register_source, write_register_script
from fixturecad.registration.pose import fixture2meas_from_rt, pose_errors, random_rotation

templates = pytest.importorskip("fixturecad.templates")
build = pytest.importorskip("fixturecad.build")
NAMES = sorted(templates.TEMPLATES)


def features_document(name):
    """features.json content of a template at its defaults (no CAD)."""
    return build.features_document(templates.make(name))


def generated_case(tmp_path, name, seed, entries=None):
    """register.py of a template in tmp_path, a random true pose and its exact touches."""
    document = features_document(name)
    write_register_script(document, tmp_path / "register.py")
    rng = np.random.default_rng(seed)
    truth = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-80, 80, 3))
    touches, contacts = plan_touches(entries or document["plans"]["default"]["touch_plan"], truth)
    return document, truth, touches, contacts


@pytest.fixture(scope="module")
def bare_site(tmp_path_factory):
    """A directory holding numpy and scipy only: the import path of a robot cell's PC."""
    import numpy
    import scipy

    site = tmp_path_factory.mktemp("site")
    for module in (numpy, scipy):
        root = Path(module.__file__).parent
        (site / root.name).symlink_to(root)
        libs = root.parent / f"{root.name}.libs"
        if libs.exists():
            (site / libs.name).symlink_to(libs)
    return site


def run_bare(site, cwd, *args):
    """Python without site-packages, with only ``site`` on its path."""
    env = {"PATH": os.environ.get("PATH", "/usr/bin"), "PYTHONPATH": str(site)}
    return subprocess.run([sys.executable, "-S", *map(str, args)], cwd=cwd, capture_output=True, text=True, env=env)


def write_csv(path, touches):
    lines = ["feature,x,y,z"]
    for feature, points in touches.items():
        lines += [",".join([feature] + [repr(float(x)) for x in p]) for p in points]
    path.write_text("\n".join(lines) + "\n")


def test_the_bare_interpreter_has_no_fixturecad_nor_cadquery(bare_site, tmp_path):
    code = "import numpy, scipy\nfor name in ('fixturecad', 'cadquery', 'trimesh'):\n" \
           "    try:\n        __import__(name)\n        print('found', name)\n    except ImportError:\n        pass\n"
    out = run_bare(bare_site, tmp_path, "-c", code)
    assert out.returncode == 0, out.stderr
    assert out.stdout == ""


@pytest.mark.parametrize("name", NAMES)
def test_generated_routine_gives_the_library_pose(name, bare_site, tmp_path):
    document = features_document(name)
    path = write_register_script(document, tmp_path / "register.py")
    ast.parse(path.read_text())
    features = {f["id"]: f for f in document["features"]}
    entries = [e for e in document["plans"]["default"]["touch_plan"] if "sensor" not in e] or document["plans"]["default"]["touch_plan"]
    point_plans = [p["touch_plan"] for p in document["plans"].values() if all("sensor" not in e for e in p["touch_plan"])]
    entries = point_plans[0] if point_plans else entries
    rng = np.random.default_rng(12)
    truth = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-80, 80, 3))
    touches, _ = plan_touches(entries, truth)
    touches = {k: v + rng.normal(scale=0.003, size=v.shape) for k, v in touches.items()}
    write_csv(tmp_path / "touches.csv", touches)
    out = run_bare(bare_site, tmp_path, "register.py", "touches.csv", "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    from fixturecad.registration.features import feature_from_json

    from fixturecad.registration.deviations import tolerance_from_document

    built = {k: feature_from_json(v) for k, v in features.items()}
    library = register_touches(built, touches, tolerance=tolerance_from_document(built, document))
    assert result["status"] == library["status"] == "unique"
    assert np.abs(np.array(result["pose"]) - np.array(library["pose"])).max() < 1e-9
    assert max(pose_errors(np.array(result["pose"]), truth)) < 0.05
    for key in ("rms_residual_mm", "solutions", "covariance", "sigma_translation_mm", "sigma_rotation_deg"):
        assert key in result
    assert np.array(result["covariance"]).shape == (6, 6)


def test_generated_api_and_nominal_pose(bare_site, tmp_path):
    _, truth, touches, _ = generated_case(tmp_path, "cube", 3)
    (tmp_path / "case.json").write_text(json.dumps({
        "touches": {k: v.tolist() for k, v in touches.items()}, "truth": truth.tolist()}))
    code = (
        "import json, numpy as np\n"
        "from register import register\n"
        "case = json.load(open('case.json'))\n"
        "touches = {k: np.array(v) for k, v in case['touches'].items()}\n"
        "a = register(touches)\n"
        "b = register(touches, initial_pose=np.array(case['truth']))\n"
        "print(json.dumps([a['pose'], b['pose'], a['status']]))\n"
    )
    out = run_bare(bare_site, tmp_path, "-c", code)
    assert out.returncode == 0, out.stderr
    a, b, status = json.loads(out.stdout)
    assert status == "unique"
    assert np.abs(np.array(a) - truth).max() < 1e-9
    assert np.abs(np.array(b) - truth).max() < 1e-9


def test_generated_routine_reads_plane_and_line_sensors_from_json(bare_site, tmp_path):
    _, truth, touches, contacts = generated_case(tmp_path, "quarter-sphere", 5)
    (tmp_path / "touches.json").write_text(touch_json(touches, contacts))
    out = run_bare(bare_site, tmp_path, "register.py", "touches.json", "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert result["status"] == "unique"
    assert max(pose_errors(np.array(result["pose"]), truth)) < 1e-6


def test_generated_routine_takes_the_sensor_noise_model(bare_site, tmp_path):
    """--sigma and --lever of register.py give the library's pose and covariance."""
    document, truth, touches, contacts = generated_case(tmp_path, "quarter-sphere", 6)
    touches, contacts = perturb_touches(touches, contacts, np.random.default_rng(6), 0.002, 10.0)
    (tmp_path / "touches.json").write_text(touch_json(touches, contacts))
    out = run_bare(bare_site, tmp_path, "register.py", "touches.json", "--json", "--sigma", 0.002, "--lever", 10,
                   "--fixture-tolerance", 0)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    from fixturecad.registration.features import feature_from_json

    features = {f["id"]: feature_from_json(f) for f in document["features"]}
    library = register_touches(features, touches, sigma_mm=0.002, contacts=contacts, lever_mm=10.0)
    assert result["status"] == library["status"] == "unique"
    assert np.abs(np.array(result["pose"]) - np.array(library["pose"])).max() < 1e-9
    assert np.allclose(result["covariance"], library["covariance"], rtol=1e-6, atol=1e-18)
    bad = run_bare(bare_site, tmp_path, "register.py", "touches.json", "--lever", 0)
    assert bad.returncode == 2 and "--lever must be a positive number" in bad.stderr


BAD_FILES = {
    "unknown feature": ("feature,x,y,z\nnope,1,2,3\n", "unknown feature 'nope'"),
    "NaN": ("feature,x,y,z\ntop,nan,2,3\n", "finite"),
    "wrong columns": ("name,x,y\ntop,1,2\n", "columns feature,x,y,z"),
    "empty file": ("", "empty"),
    "too few touches": ("feature,x,y,z\ntop,1,2,3\ntop,4,5,6\n", "too few touches"),
    "text": ("feature,x,y,z\ntop,a,b,c\n", "numbers"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_touch_files_are_one_line_and_exit_2(case, bare_site, tmp_path):
    write_register_script(features_document("cube"), tmp_path / "register.py")
    text, words = BAD_FILES[case]
    (tmp_path / "touches.csv").write_text(text)
    out = run_bare(bare_site, tmp_path, "register.py", "touches.csv")
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], out.stderr
    assert out.stdout == ""


def test_the_template_fails_on_a_missing_key(tmp_path, monkeypatch):
    from string import Template

    from fixturecad.registration import generate

    text = (Path(generate.__file__).parent / generate.TEMPLATE_NAME).read_text()
    with pytest.raises(KeyError):
        Template(text).substitute({})
    source = register_source(features_document("cube"))
    assert "import fixturecad" not in source and "from fixturecad" not in source
    ast.parse(source)
    with pytest.raises(ValueError, match="features"):
        register_source({"template": "cube"})


def test_touch_csv_may_carry_the_probe_approach(tmp_path):
    from fixturecad.registration.touchfile import read_touch_csv

    text = "feature,x,y,z,ax,ay,az\ntop,1,2,3,0,0,-1\ntop,4,5,6,0,0,-1\n"
    touches, approaches, _ = read_touch_csv(text, ["top"])
    assert touches["top"].shape == (2, 3)
    assert approaches["top"].tolist() == [[0, 0, -1], [0, 0, -1]]
    touches, approaches, _ = read_touch_csv("feature,x,y,z\ntop,1,2,3\n", ["top"])
    assert approaches == {}
    with pytest.raises(ValueError, match="expected 7 values"):
        read_touch_csv("feature,x,y,z,ax,ay,az\ntop,1,2,3\n", ["top"])


def test_exit_code_tells_the_status(bare_site, tmp_path):
    """0 unique, 4 underdetermined, 5 inconsistent from register.py and `fixturecad register`."""
    from cli import run

    write_register_script(features_document("cube"), tmp_path / "register.py")
    (tmp_path / "features.json").write_text(json.dumps(features_document("cube")))  # what `register` reads
    good = {"top": [[10, 10, 50], [40, 10, 50], [25, 40, 50]], "front": [[10, 0, 10], [40, 0, 10]],
            "left": [[0, 25, 25], [0, 10, 40]]}
    flat = {"top": [[5, 5, 50], [45, 5, 50], [25, 45, 50], [10, 30, 50], [40, 40, 50], [20, 20, 50]]}
    off = {**good, "left": [[0, 25, 25], [2.0, 10, 40]]}
    for name, case, code in (("good", good, 0), ("flat", flat, 4), ("off", off, 5)):
        write_csv(tmp_path / f"{name}.csv", {k: np.array(v, float) for k, v in case.items()})
        assert run_bare(bare_site, tmp_path, "register.py", f"{name}.csv").returncode == code, name
    assert run("register", tmp_path, tmp_path / "off.csv").returncode == 5


def test_ambiguous_exits_3(tmp_path):
    from fixturecad.registration.touchfile import EXIT_CODES, main

    (tmp_path / "t.csv").write_text("feature,x,y,z\n" + "top,1,2,3\n" * 6)
    result = {"status": "ambiguous", "rms_residual_mm": 0.0, "sigma_translation_mm": None, "pose": np.eye(4).tolist(),
              "solutions": [], "free_motions": [], "flagged": [], "culprit": None, "separating_touch": None,
              "covariance": None, "inadmissible": [], "search": "complete"}
    from fixturecad.registration.features import features_from_json

    features = features_from_json(features_document("cube"))
    assert main(features, lambda *a, **k: result, [str(tmp_path / "t.csv")], default_sigma_mm=0.005) == 3
    assert EXIT_CODES == {"unique": 0, "ambiguous": 3, "underdetermined": 4, "inconsistent": 5}


def test_register_py_embeds_every_module_its_modules_import():
    """The one list of embedded modules is closed under the modules' own relative imports."""
    from fixturecad.registration.generate import EMBEDDED_MODULES

    root = Path(__file__).resolve().parent.parent / "registration"
    for name in EMBEDDED_MODULES:
        for node in ast.walk(ast.parse((root / f"{name}.py").read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                assert node.module in EMBEDDED_MODULES, (name, node.module)
            if isinstance(node, ast.Import) or (isinstance(node, ast.ImportFrom) and node.level == 0):
                top = (node.module if isinstance(node, ast.ImportFrom) else node.names[0].name).split(".")[0]
                assert top in ("numpy", "scipy", "copy", "math", "dataclasses", "functools", "itertools", "argparse", "csv", "io",
                               "json", "os", "reprlib", "sys", "warnings"), (name, top)
