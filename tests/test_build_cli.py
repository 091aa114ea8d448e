"""``fixturecad build | templates | suggest``: files, round trips, bad input, --force, speed-relevant imports."""

import json
import subprocess
import sys

import numpy as np
import pytest

from cli import assert_bad_input, run
from solid_files import assert_the_files_hold
from fixturecad.build import build, features_document
from fixturecad.features_json import load_schema, validate
from fixturecad.cli import main
from fixturecad.registration.features import feature_from_json
from fixturecad.templates import TEMPLATES, make

jsonschema = pytest.importorskip("jsonschema")
trimesh = pytest.importorskip("trimesh")


def cli(*args):
    """Run ``fixturecad ARGS`` in this process: (exit code, stdout, stderr) via capsys by the caller."""
    try:
        main([str(a) for a in args])
    except SystemExit as exit_:
        return exit_.code
    return 0


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """Each template built once at its default parameters through the library entry point."""
    root = tmp_path_factory.mktemp("built")
    return {name: build(make(name), root / name) for name in TEMPLATES}


@pytest.mark.parametrize("name", list(TEMPLATES))
def test_build_writes_the_four_files(built, name):
    folder = built[name]
    for file in ("fixture.step", "fixture.stl", "features.json", "preview.png"):
        assert (folder / file).stat().st_size > 0, file
    assert (folder / "preview.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(folder.parent.glob(".*tmp")), "staging folders left behind"
    assert not list(folder.glob(".*")), "scratch files left in the folder"
    try:
        import fixturecad.registration.generate  # noqa: F401
    except ModuleNotFoundError:
        return
    assert "def " in (folder / "register.py").read_text()


@pytest.mark.parametrize("name", list(TEMPLATES))
def test_features_json_is_valid_and_round_trips(built, name):
    document = json.loads((built[name] / "features.json").read_text())
    validate(document)
    assert document["schema"] == "fixturecad.features/2" and document["units"] == "mm"
    fixture = make(name)
    assert document["contact_class"] == fixture.contact_class
    for entry, feature in zip(document["features"], fixture.features()):
        assert feature_from_json(entry).to_json() == feature.to_json()
    assert "touch_plan" not in document  # the default plan is stored once, in plans


def test_schema_refuses_unknown_fields_and_bad_kinds():
    document = features_document(make("cube"))
    validate(document)
    for broken in (
        {**document, "colour": "red"},
        {**document, "features": [{**document["features"][0], "kind": "torus"}]},
        {**document, "features": [{**document["features"][0], "extra": 1}]},
        {**document, "plans": {"default": {**document["plans"]["default"], "touch_plan": [
            {**document["plans"]["default"]["touch_plan"][0], "contact": "X/F-PL/M"}]}}},
    ):
        with pytest.raises(jsonschema.ValidationError):
            validate(broken)
    assert load_schema()["additionalProperties"] is False


def test_the_shipped_schema_is_a_valid_draft_2020_12_schema():
    schema = load_schema()
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    jsonschema.Draft202012Validator.check_schema(schema)


@pytest.mark.parametrize("name", list(TEMPLATES))
def test_step_stl_and_3mf_read_back_as_the_solid(built, name):
    text = (built[name] / "fixture.step").read_text(errors="replace")
    assert "FILE_SCHEMA(('AUTOMOTIVE_DESIGN" in text  # AP214
    assert ".MILLI." in text
    assert_the_files_hold(built[name], make(name).volume())


@pytest.mark.parametrize("name", list(TEMPLATES))
def test_stl_is_watertight_consistent_and_close_to_the_volume(built, name):
    mesh = trimesh.load(built[name] / "fixture.stl")
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.is_volume
    assert np.all(mesh.area_faces > 0)
    assert mesh.volume == pytest.approx(make(name).volume(), rel=2e-3)


@pytest.mark.parametrize("tolerance", [0.01, 0.001])
def test_stl_chord_tolerance_is_absolute_and_honoured(tolerance):
    from fixturecad.cad.mesh import mesh_from_shape
    from fixturecad.cad.solid import fixture_solid

    radius = 10.0
    vertices, faces = mesh_from_shape(fixture_solid(make("quarter-sphere", radius=radius)), tolerance)
    tris = vertices[faces]
    on_sphere = np.all(np.abs(np.linalg.norm(tris, axis=2) - radius) < 1e-9, axis=1)
    flat = np.all(np.abs(tris[:, :, 1]) < 1e-9, axis=1) | np.all(np.abs(tris[:, :, 2]) < 1e-9, axis=1)
    sag = radius - np.linalg.norm(tris[on_sphere & ~flat].mean(axis=1), axis=1)
    assert 0 < sag.max() <= tolerance


def test_cli_build_default_folder_prints_it_and_refuses_to_overwrite(tmp_path):
    result = run("build", "quarter-sphere", "--radius", "40", "--stl-tolerance", "0.05", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "out/quarter-sphere-r40"
    folder = tmp_path / "out" / "quarter-sphere-r40"
    assert (folder / "features.json").exists()
    marker = folder / "marker"
    marker.write_text("old")
    again = run("build", "quarter-sphere", "--radius", "40", cwd=tmp_path)
    assert_bad_input(again, "exists", "--force")
    assert marker.exists()
    forced = run("build", "quarter-sphere", "--radius", "40", "--force", "--stl-tolerance", "0.05", cwd=tmp_path)
    assert forced.returncode == 0, forced.stderr
    assert marker.read_text() == "old" and (folder / "fixture.step").exists()  # not fixturecad's: kept
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["quarter-sphere-r40"]


@pytest.mark.parametrize(
    "args, words",
    [
        (["build", "pyramid"], ["unknown template", "quarter-sphere"]),
        (["build", "quarter-sphere", "--radius", "nan"], ["--radius"]),
        (["build", "quarter-sphere", "--radius", "inf"], ["--radius"]),
        (["build", "quarter-sphere", "--radius", "-40"], ["--radius"]),
        (["build", "quarter-sphere", "--radius"], ["--radius", "value"]),
        (["build", "quarter-sphere", "--size", "4"], ["--size", "--radius"]),
        (["build", "cube", "--size", "0"], ["--size"]),
        (["build", "inclined-plane-cylinder", "--angle", "90"], ["--angle"]),
        (["build", "inclined-plane-cylinder", "--angle", "0.5"], ["--angle"]),
        (["build", "cube", "--stl-tolerance", "0"], ["--stl-tolerance"]),
        (["build", "cube", "--stl-tolerance", "nan"], ["--stl-tolerance"]),
        (["suggest", "{G3}{nonsense"], ["class"]),
        (["suggest", "{Q}"], ["unknown class"]),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, args, words):
    result = run(*args, cwd=tmp_path)
    assert_bad_input(result, *words)
    assert list(tmp_path.iterdir()) == []


def test_cli_out_option_and_base(tmp_path, capsys):
    target = tmp_path / "deep" / "fixture"
    assert cli("build", "cube", "--size", "20", "--base", "--out", target) == 0
    assert capsys.readouterr().out.strip() == str(target)
    document = json.loads((target / "features.json").read_text())
    assert document["parameters"] == {"size": 20.0, "base": True}
    assert_the_files_hold(target, make("cube", base=True, size=20).volume())


def test_templates_lists_parameters_ranges_and_classes(capsys):
    assert cli("templates") == 0
    out = capsys.readouterr().out
    for name in TEMPLATES:
        assert name in out
    assert "{G3}{S-S}{S-T2}{C-R-C}" in out and "--radius" in out and "5..500" in out
    assert cli("templates", "--format", "json") == 0
    document = json.loads(capsys.readouterr().out)
    assert {entry["template"] for entry in document} == set(TEMPLATES)


@pytest.mark.parametrize(
    "text, template",
    [
        ("{G3}{S-S}{S-T2}{C-R-C}", "quarter-sphere"),
        ("{S-C}{S-C}{S-C}{S-T2}{S-T2}{S-T2}", "inclined-plane-cylinder"),
        ("{S-C}x3 {S-T2}x3", "inclined-plane-cylinder"),
        ("{S-T2}x6", "cube"),
    ],
)
def test_suggest_goes_from_class_to_a_buildable_design(capsys, text, template):
    assert cli("suggest", text) == 0
    out = capsys.readouterr().out
    assert f"fixturecad build {template}" in out


def test_help_lists_the_fixture_commands():
    result = run("--help")
    assert result.returncode == 0
    for command in ("build", "templates", "suggest"):
        assert command in result.stdout


@pytest.mark.parametrize("args", [["--help"], ["templates"], ["suggest", "{G3}{S-S}{S-T2}{C-R-C}"]])
def test_the_commands_that_do_not_build_import_neither_cadquery_nor_matplotlib(args):
    code = ("import sys\nfrom fixturecad.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m in ('cadquery', 'OCP', 'matplotlib') if m in sys.modules]\n"
            "assert not heavy, heavy")
    subprocess.run([sys.executable, "-c", code, *args], check=True, stdout=subprocess.DEVNULL)


def test_a_failed_build_leaves_nothing_behind(tmp_path, monkeypatch):
    import fixturecad.cad.export
    import fixturecad.cad.mesh

    def broken(*args, **kwargs):
        raise fixturecad.cad.mesh.MeshError("simulated failure")

    monkeypatch.setattr(fixturecad.cad.export, "write_stl", broken)
    with pytest.raises(fixturecad.cad.mesh.MeshError):
        build(make("cube", size=10), tmp_path / "cube")
    assert list(tmp_path.iterdir()) == []


def test_a_failed_forced_build_keeps_the_old_folder(tmp_path, monkeypatch):
    import fixturecad.cad.export
    import fixturecad.cad.mesh

    target = build(make("cube", size=10), tmp_path / "cube")
    before = (target / "features.json").read_text()

    def broken(*args, **kwargs):
        raise fixturecad.cad.mesh.MeshError("simulated failure")

    monkeypatch.setattr(fixturecad.cad.export, "write_stl", broken)
    with pytest.raises(fixturecad.cad.mesh.MeshError):
        build(make("cube", size=12), target, force=True)
    assert (target / "features.json").read_text() == before
    assert [p.name for p in tmp_path.iterdir()] == ["cube"]


def test_template_options_parse_both_spellings_and_refuse_repeats():
    from fixturecad.errors import InputError
    from fixturecad.fixture_commands import parse_template_options

    assert parse_template_options("inclined-plane-cylinder", ["--radius=20", "--angle", "30"]) == {
        "radius": "20", "angle": "30"}
    assert parse_template_options("cube", ["--size", "-3"]) == {"size": "-3"}  # refused later, by range
    for args, word in ((["--size", "1", "--size", "2"], "twice"), (["50"], "unexpected"), (["--size"], "value")):
        with pytest.raises(InputError, match=word):
            parse_template_options("cube", args)


def test_an_older_features_json_is_refused_in_one_line(tmp_path):
    """A folder built by an older fixturecad is named as such, not read wrongly."""
    from cli import assert_bad_input, run

    folder = build(make("cube", size=10), tmp_path / "cube")
    document = json.loads((folder / "features.json").read_text())
    (folder / "features.json").write_text(json.dumps({**document, "schema": "fixturecad.features/1"}))
    assert_bad_input(run("simulate", folder, "--trials", 1), "fixturecad.features/1", "rebuild")
    assert_bad_input(run("register", folder, folder / "touches.template.csv"), "fixturecad.features/1", "rebuild")


def test_register_reads_the_folders_features_json(tmp_path):
    """The cube's top moved up 1 mm in features.json: register's pose moves the part down 1 mm; register.py,
    run alone, keeps the copy it was built with."""
    import subprocess
    import sys

    from cli import run

    folder = build(make("cube", size=10), tmp_path / "cube")
    document = json.loads((folder / "features.json").read_text())
    top = next(f for f in document["features"] if f["id"] == "top")
    top["point"][2] += 1.0
    (folder / "features.json").write_text(json.dumps(document))
    touches = folder / "touches.template.csv"
    moved = json.loads(run("register", folder, touches, "--format", "json").stdout)
    alone = json.loads(subprocess.run([sys.executable, str(folder / "register.py"), str(touches), "--format", "json"],
                                      capture_output=True, text=True).stdout)
    assert moved["translation_mm"] == pytest.approx([0.0, 0.0, -1.0], abs=1e-6)
    assert alone["translation_mm"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)


def test_only_the_cad_room_and_template_bodies_import_the_kernel():
    """cadquery and OCP are imported in fixturecad/cad/ and inside the templates' body() only."""
    import ast
    import inspect
    from pathlib import Path

    root = Path(__file__).resolve().parent.parent
    importers = set()
    for path in sorted(root.glob("fixturecad/**/*.py")) + sorted(root.glob("registration/**/*.py")) + \
            sorted(root.glob("templates/**/*.py")):
        tree = ast.parse(path.read_text())
        in_body = {id(node) for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and f.name == "body"
                   for node in ast.walk(f)}
        for node in ast.walk(tree):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            if any(n.split(".")[0] in ("cadquery", "OCP") for n in names):
                importers.add(f"{path.relative_to(root)}{':body' if id(node) in in_body else ''}")
    room = {f"fixturecad/cad/{name}.py" for name in ("brep", "export", "mesh", "solid")}
    bodies = {f"{Path(inspect.getsourcefile(cls)).relative_to(root)}:body" for cls in TEMPLATES.values()}
    assert importers == room | bodies
