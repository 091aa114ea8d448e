"""The field edges: every input of issue 10's audit ends in one line on stderr and exit 2 (or the
documented code), nothing written or lost, no Python warning."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

from cli import assert_bad_input, assert_fault, run


@pytest.fixture
def cube(built, tmp_path):
    """A copy of a built cube folder, free to damage."""
    folder = tmp_path / "cube"
    shutil.copytree(built("cube"), folder)
    return folder


def touches_csv(folder, path, rows):
    path.write_text("feature,x,y,z\n" + "".join(f"{row}\n" for row in rows))
    return path


def test_out_must_be_a_new_folder(cube, tmp_path):
    for out in (".", "..", ""):
        assert_bad_input(run("build", "cube", "--out", out, "--force", cwd=cube), "folder")
    assert sorted(p.name for p in cube.parent.iterdir()) == ["cube"]


def test_out_below_a_file_or_in_a_read_only_folder(cube, tmp_path):
    (tmp_path / "file").write_text("mine")
    assert_bad_input(run("build", "cube", "--out", tmp_path / "file" / "x"), "is a file")
    assert_bad_input(run("build", "cube", "--out", tmp_path / "file", "--force"), "not a folder")
    assert (tmp_path / "file").read_text() == "mine"
    locked = tmp_path / "locked"
    locked.mkdir()
    with _read_only(locked):
        assert_bad_input(run("build", "cube", "--out", locked / "x"), "cannot write")
        assert list(locked.iterdir()) == []


@contextmanager
def _read_only(folder):
    """A folder this user cannot write in: mode 555, or immutable (chattr +i) for root."""
    folder.chmod(0o555)
    immutable = os.access(folder, os.W_OK) and shutil.which("chattr") is not None and subprocess.run(
        ["chattr", "+i", str(folder)], capture_output=True).returncode == 0
    try:
        if os.access(folder, os.W_OK) and not immutable:
            pytest.skip("this user writes in read-only folders and cannot make one immutable")
        yield
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
        folder.chmod(0o755)


def test_force_replaces_only_what_fixturecad_wrote(cube, tmp_path):
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("keep me")
    assert_bad_input(run("build", "cube", "--out", theirs, "--force"), "not written by fixturecad")
    assert (theirs / "notes.txt").read_text() == "keep me"
    assert_bad_input(run("build", "cube", "--out", cube), "--force")
    # What fixturecad did not write is kept: a measured-touch file, plans/, simulate's files.
    (cube / "mine.csv").write_text("x")
    (cube / "plans").mkdir()
    (cube / "plans" / "ball.json").write_text("{}")
    assert run("simulate", cube, "--trials", 2).returncode == 0
    (cube / "fixture.stl").write_text("old")
    assert run("build", "cube", "--out", cube, "--force").returncode == 0
    assert (cube / "mine.csv").read_text() == "x" and (cube / "plans" / "ball.json").read_text() == "{}"
    assert (cube / "simulation.json").exists() and (cube / "fixture.stl").read_bytes() != b"old"
    written = json.loads((cube / "fixturecad-files.json").read_text())["files"]
    assert sorted(p.name for p in cube.iterdir() if p.name not in written) == [
        "fixturecad-files.json", "mine.csv", "plans", "simulation.json", "simulation.png"]
    # A file the manifest does not list, with the name of one fixturecad writes, is not replaced.
    written.remove("preview.png")
    (cube / "fixturecad-files.json").write_text(json.dumps({"files": written}))
    assert_bad_input(run("build", "cube", "--out", cube, "--force"), "preview.png", "not a file fixturecad wrote")
    empty = tmp_path / "empty"
    empty.mkdir()
    assert run("build", "cube", "--out", empty).returncode == 0


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_an_interrupted_build_leaves_nothing_and_says_so(tmp_path, signum):
    (tmp_path / ".cube.999999999.tmp").mkdir()  # left by a killed build: its pid does not run
    process = subprocess.Popen([sys.executable, "-c", "from fixturecad.cli import main; main()", "build", "cube",
                                "--out", "cube"], cwd=tmp_path, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not any(p.name.startswith(f".cube.{process.pid}.") for p in tmp_path.iterdir()):
        assert time.monotonic() < deadline and process.poll() is None
        time.sleep(0.01)
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signum
    assert stderr == "fixturecad: interrupted; nothing was written\n"
    assert list(tmp_path.iterdir()) == []  # its own temporary folder and the stale one are gone


def test_an_interrupt_between_making_a_temporary_folder_and_registering_it_waits_and_removes_it(tmp_path):
    """The race an interrupted build once lost under load (its temporary folder left behind): the signal comes
    after the folder is made and before it is registered for removal; held, it waits, and the folder goes."""
    script = ("import os, signal, sys; from contextlib import ExitStack; from pathlib import Path; "
              "from fixturecad import interrupt; interrupt.install(); path = Path(sys.argv[1])\n"
              "with ExitStack() as stack:\n"
              "    with interrupt.held():\n"
              "        path.mkdir(); os.kill(os.getpid(), signal.SIGTERM)\n"
              "        stack.enter_context(interrupt.removing(path))\n"
              "    print('not reached')\n")
    done = subprocess.run([sys.executable, "-c", script, str(tmp_path / "staging")], capture_output=True, text=True,
                          timeout=60)
    assert (done.returncode, done.stdout, done.stderr) == (128 + signal.SIGTERM, "",
                                                           "fixturecad: interrupted; nothing was written\n")
    assert list(tmp_path.iterdir()) == []


def test_an_interrupt_between_the_two_renames_of_a_replaced_folder_waits_for_the_new_one(tmp_path):
    """A folder replaced (--force) is renamed aside, then the new one into place: a signal after the first rename
    waits until the second is done, so the target is never missing (the old one aside would be cleared as stale by
    the next command, the user's own files with it)."""
    script = ("import os, signal, sys; from pathlib import Path; from fixturecad import interrupt, staging\n"
              "interrupt.install(); root = Path(sys.argv[1]); target, new = root / 'cube', root / 'new'\n"
              "target.mkdir(); (target / 'old.txt').write_text('old')\n"
              "new.mkdir(); (new / 'new.txt').write_text('new')\n"
              "rename = os.replace\n"
              "def replace(a, b):\n"
              "    rename(a, b)\n"
              "    os.kill(os.getpid(), signal.SIGTERM)\n"
              "os.replace = replace\n"
              "staging._move_into_place(new, target)\n"
              "print('not reached')\n")
    done = subprocess.run([sys.executable, "-c", script, str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert (done.returncode, done.stdout) == (128 + signal.SIGTERM, "")
    assert (tmp_path / "cube" / "new.txt").read_text() == "new"


@pytest.mark.parametrize("content", ["", "garbage(\n", "x = 1\n"])
def test_a_damaged_register_py(cube, content):
    (cube / "register.py").write_text(content)
    assert_bad_input(run("simulate", cube, "--trials", 2), "register.py", "rebuild")
    assert run("register", cube, cube / "touches.template.csv").returncode == 0  # on the folder's features.json


def test_a_truncated_stl(cube):
    data = (cube / "fixture.stl").read_bytes()
    (cube / "fixture.stl").write_bytes(data[: len(data) // 2])
    assert_bad_input(run("simulate", cube, "--trials", 2), "fixture.stl", "rebuild")
    assert not (cube / "simulation.json").exists()


def test_simulate_seed_must_not_be_negative(cube):
    assert_bad_input(run("simulate", cube, "--seed", -1), "--seed")


@pytest.mark.parametrize("jobs", [-1, "two"])
def test_simulate_jobs_must_be_a_count(cube, jobs):
    assert_bad_input(run("simulate", cube, "--jobs", jobs), "--jobs")
    assert not (cube / "simulation.json").exists()


JSON_CASES = {
    "radius null": ({"ball_radius_mm": None, "touches": [{"feature": "top", "points": [[1, 2, 50]]}]}, "ball_radius_mm"),
    "radius list": ({"ball_radius_mm": [1], "touches": [{"feature": "top", "points": [[1, 2, 50]]}]}, "ball_radius_mm"),
    "radius negative": ({"ball_radius_mm": -1, "touches": [{"feature": "top", "points": [[1, 2, 50]]}]}, "ball_radius_mm"),
    "contact a number": ({"touches": [{"feature": "top", "contact": 5, "points": [[1, 2, 50]]}]}, "contact"),
    "sensor without point": ({"touches": [{"feature": "top", "contact": "PL/F-PL/F",
                                           "sensor": {"kind": "plane", "normal": [0, 0, 1]}}]}, "point, normal"),
    "sensor without normal": ({"touches": [{"feature": "top", "contact": "PL/F-PL/F", "points": [[1, 2, 50]],
                                            "sensor": {"kind": "plane", "point": [1, 2, 50]}}]}, "point, normal"),
    "sensor of zero normal": ({"touches": [{"feature": "top", "contact": "PL/F-PL/F", "points": [[1, 2, 50]],
                                            "sensor": {"kind": "plane", "point": [1, 2, 50], "normal": [0, 0, 0]}}] * 6},
                              "non-zero"),
    "feature a list": ({"touches": [{"feature": ["top"], "points": [[1, 2, 50]]}]}, "unknown feature"),
    "not an object": ([1, 2], "object"),
    "fixed fixture side without its point": ({"touches": [{"feature": "top", "contact": "S/F-PL/F", "points": [[1, 2, 50]],
                                                          "sensor": {"kind": "sphere", "center": [1, 2, 53], "radius": 3}}] * 6},
                                             '"fixture": {"o"'),
    "huge": ({"touches": [{"feature": "top", "points": [[1e302, 2, 50]] * 6}]}, "beyond"),
}


@pytest.mark.parametrize("case", sorted(JSON_CASES))
def test_bad_json_touch_files(cube, tmp_path, case):
    document, words = JSON_CASES[case]
    path = tmp_path / "touches.json"
    path.write_text(json.dumps(document))
    assert_bad_input(run("register", cube, path), words)
    out = subprocess.run([sys.executable, str(cube / "register.py"), str(path)], capture_output=True, text=True)
    assert out.returncode == 2 and len(out.stderr.splitlines()) == 1 and words in out.stderr, out.stderr


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_ball_radius_must_be_a_length(cube, value):
    assert_bad_input(run("register", cube, cube / "touches.template.csv", "--ball-radius", value), "--ball-radius")


def test_huge_coordinates_in_a_csv(cube, tmp_path):
    path = touches_csv(cube, tmp_path / "t.csv", ["top,1e302,0,50"] * 6)
    assert_bad_input(run("register", cube, path), "row 2", "beyond")


def test_six_identical_touches_warn_nothing(cube, tmp_path):
    """Underdetermined (exit 4) with the free motions named, and no Python warning: only the repeated rows."""
    path = touches_csv(cube, tmp_path / "t.csv", ["top,10,10,50"] * 6)
    for prog, command in (("register.py", [sys.executable, "-W", "error", str(cube / "register.py"), str(path)]),
                          ("fixturecad", [sys.executable, "-W", "error", "-c", "from fixturecad.cli import main; main()",
                                          "register", str(cube), str(path)])):
        out = subprocess.run(command, capture_output=True, text=True)
        assert out.returncode == 4, out.stderr
        assert out.stderr == (f"{prog}: warning: row 3 of t.csv repeats row 2 of t.csv (and 4 more): "
                              "a repeated touch checks nothing; touch again elsewhere\n")
        assert "free: planar motion {G_P} in the plane of top" in out.stdout


def test_suggest_bounds_the_counts():
    assert_bad_input(run("suggest", "{S-T2}x1000000000{R}x1000000000"), "more than 64 contacts")


def test_version_and_bare_help():
    from fixturecad import __version__

    out = run("--version")
    assert out.returncode == 0 and out.stdout == f"fixturecad {__version__}\n"
    bare = run()
    assert bare.returncode == 0 and "Usage: fixturecad" in bare.stdout and bare.stderr == ""


def test_build_help_shows_the_default_folder_and_the_parameters():
    out = run("build", "--help")
    text = " ".join(out.stdout.split())
    assert "out/<template>-<parameters>" in text
    assert "quarter-sphere: --radius 40 mm (5..500)" in text
    assert "--lever" in run("register", "--help").stdout and "20.0" in run("register", "--help").stdout


def test_empty_touch_lists_are_no_touches(built):
    """register({"left": []}): a clear error, not a numpy shape; empty lists beside others are skipped."""
    from fixturecad.registration.engine import register_touches
    from fixturecad.registration.features import features_from_json

    features = features_from_json(json.loads((built("cube") / "features.json").read_text()))
    with pytest.raises(ValueError, match="no touches given"):
        register_touches(features, {"left": []})
    touches = {"top": [[10, 10, 50], [40, 10, 50], [25, 40, 50]], "front": [[10, 0, 25], [40, 0, 25]], "left": []}
    result = register_touches(features, touches)
    assert result["status"] == "underdetermined" and result["touches"] == 5
    assert result["free_motions"] == ["translation {T_u} along the normal of left"]


def test_replaced_files_are_ordinary_files(built, tmp_path):
    """simulate's files are written whole (a temporary file moved in) with the umask's mode, not private."""
    import stat

    out = run("simulate", built("cube"), "--trials", 2, "--out", tmp_path / "sim")
    assert out.returncode == 0, out.stderr
    mask = os.umask(0)
    os.umask(mask)
    for name in ("simulation.json", "simulation.png"):
        assert stat.S_IMODE((tmp_path / "sim" / name).stat().st_mode) == 0o666 & ~mask


# Issue 22: the last tracebacks.

FULL_DISK = """import errno, os, pathlib
_write_text = pathlib.Path.write_text
def _full(self, *args, **kwargs):
    if self.name == {name!r}:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self))
    return _write_text(self, *args, **kwargs)
pathlib.Path.write_text = _full
"""


@pytest.mark.parametrize("name", ["features.json", "register.py"])  # written by calibrate, by its side process
def test_calibrate_on_a_full_disk(cube, tmp_path, name):
    """A full disk is the machine's fault: exit 1 with the reason, and no as-built folder."""
    (tmp_path / "site").mkdir()
    (tmp_path / "site" / "sitecustomize.py").write_text(FULL_DISK.format(name=name))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp_path / "site"), os.environ.get("PYTHONPATH")]))}
    out = run("calibrate", cube, cube / "touches.template.csv", "--out", tmp_path / "asbuilt", env=env)
    assert_fault(out, "cannot write", "No space left on device")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cube", "site"]


def test_simulate_into_a_read_only_folder(cube, tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    with _read_only(locked):
        assert_bad_input(run("simulate", cube, "--trials", 2, "--out", locked), "cannot write in")
        assert list(locked.iterdir()) == []


def test_a_csv_field_over_the_csv_limit(cube, tmp_path):
    path = touches_csv(cube, tmp_path / "t.csv", ["top,1" + "0" * 140_000 + ",0,50"])
    assert_bad_input(run("register", cube, path), "row 2", "field limit")
    assert_bad_input(run("calibrate", cube, path, "--out", tmp_path / "asbuilt"), "row 2", "field limit")
    assert not (tmp_path / "asbuilt").exists()


def test_deeply_nested_json(cube, tmp_path):
    path = tmp_path / "touches.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    assert_bad_input(run("register", cube, path), "nested too deeply")
    (cube / "features.json").write_text(path.read_text())
    assert_bad_input(run("simulate", cube, "--trials", 2), "features.json")


def test_touch_plan_names_a_plan_not_a_path(cube):
    (cube / "plans").mkdir()
    assert_bad_input(run("simulate", cube, "--trials", 2, "--touch-plan", "../features"), "unknown touch plan")
    (cube / "plans" / "mine.json").write_text('{"note": "not a plan"}')
    assert_bad_input(run("simulate", cube, "--trials", 2, "--touch-plan", "mine"), "mine.json", "not a touch plan")
    assert not (cube / "simulation.json").exists()


def test_design_seed_must_not_be_negative(tmp_path):
    assert_bad_input(run("design", "--class", "{S-T2}x3 {S-S}x3", "--seed", -1, "--out", tmp_path / "d"), "--seed")
    assert list(tmp_path.iterdir()) == []


def test_register_py_without_numpy(cube):
    """Python without its site packages has no numpy: register.py says so in one line, exit 1."""
    out = subprocess.run([sys.executable, "-I", "-S", str(cube / "register.py"), str(cube / "touches.template.csv")],
                         capture_output=True, text=True)
    assert_fault(out, "numpy is not installed", "pip install numpy scipy")


PLANE = {"feature": "top", "contact": "PL/F-PL/F", "sensor": {"kind": "plane", "point": [1, 2, 50], "normal": [0, 0, 1]}}
# Touch files the shipped touches.schema.json rejects, made from a build's valid touches.template.json.
SCHEMA_CASES = {
    "rho a string": (lambda doc: doc["touches"][0].update(rho="x"), "rho"),
    "rho a list": (lambda doc: doc["touches"][0].update(rho=[1]), "rho"),
    "rho a boolean": (lambda doc: doc["touches"][0].update(rho=True), "rho"),
    "coordinate a string": (lambda doc: doc["touches"][0]["points"][0].__setitem__(0, "1"), "points"),
    "coordinate a boolean": (lambda doc: doc["touches"][0]["points"][0].__setitem__(0, True), "points"),
    "point of two numbers": (lambda doc: doc["touches"][0]["points"].__setitem__(0, [1, 2]), "points"),
    "no points": (lambda doc: doc["touches"][0].update(points=[]), "points"),
    "unknown top-level key": (lambda doc: doc.update(units="mm"), "units"),
    "fixture with another key": (lambda doc: doc["touches"][0].update(fixture={"u": [0, 0, 1]}), "fixture"),
    "fixture point of two": (lambda doc: doc["touches"][0].update(fixture={"o": [0, 0]}), "fixture"),
    "sensor with approaches": (lambda doc: doc["touches"].append({**PLANE, "approaches": [[0, 0, -1]]}), "approaches"),
    "sensor point of two": (lambda doc: doc["touches"].append({**PLANE, "sensor": {**PLANE["sensor"], "point": [1, 2]}}),
                            "sensor point"),
    "sensor radius negative": (lambda doc: doc["touches"].append(
        {"feature": "top", "contact": "S/M-PL/M", "sensor": {"kind": "sphere", "center": [1, 2, 53], "radius": -3}}),
        "sensor radius"),
}


@pytest.mark.parametrize("case", sorted(SCHEMA_CASES))
def test_touch_files_are_checked_against_the_shipped_schema(cube, tmp_path, case):
    """Whatever touches.schema.json rejects, register and register.py refuse in one line."""
    from importlib import resources

    from jsonschema import Draft202012Validator

    schema = json.loads(resources.files("fixturecad").joinpath("schema/touches.schema.json").read_text())
    document = json.loads((cube / "touches.template.json").read_text())
    assert Draft202012Validator(schema).is_valid(document)
    change, words = SCHEMA_CASES[case]
    change(document)
    assert not Draft202012Validator(schema).is_valid(document)
    path = tmp_path / "touches.json"
    path.write_text(json.dumps(document))
    assert_bad_input(run("register", cube, path), words)
    out = subprocess.run([sys.executable, str(cube / "register.py"), str(path)], capture_output=True, text=True)
    assert out.returncode == 2 and len(out.stderr.splitlines()) == 1 and words in out.stderr, out.stderr


def test_an_approach_of_zero_is_refused(cube, tmp_path):
    rows = [line + ",0,0,-1" for line in (cube / "touches.template.csv").read_text().splitlines()
            if line and not line.startswith(("#", "feature"))]
    rows[3] = rows[3].removesuffix(",0,0,-1") + ",0,0,0"
    path = tmp_path / "t.csv"
    path.write_text("feature,x,y,z,ax,ay,az\n" + "\n".join(rows) + "\n")
    assert_bad_input(run("register", cube, path), "row 5", "approach", "zero")
    document = json.loads((cube / "touches.template.json").read_text())
    document["touches"][0]["approaches"] = [[0, 0, -1]] * 3 + [[0, 0, 0]]
    path = tmp_path / "t.json"
    path.write_text(json.dumps(document))
    assert_bad_input(run("register", cube, path), "touch 1", "[0, 0, 0]")


def test_suggest_and_design_agree_on_what_a_class_is(tmp_path):
    """A class outside Table V that no template realises: the same one line, exit 2, from both."""
    suggest = run("suggest", "{S-T2}x5")
    design = run("design", "--class", "{S-T2}x5", "--out", tmp_path / "d")
    for out in (suggest, design):
        assert_bad_input(out, "{S-T2}x5 is not a class of Table V")
    assert suggest.stderr == design.stderr
    assert list(tmp_path.iterdir()) == []


def _until_it_catches_sigterm(process):
    """Wait until the process handles SIGTERM (Python does not by default): its first instruction has run."""
    status = Path(f"/proc/{process.pid}/status")
    if not status.exists():
        pytest.skip("no /proc to see a process's signal handlers")
    deadline = time.monotonic() + 60
    while not int(next(line for line in status.read_text().splitlines() if line.startswith("SigCgt:")).split()[1],
                  16) >> (signal.SIGTERM - 1) & 1:
        assert time.monotonic() < deadline and process.poll() is None
        time.sleep(0.001)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("delay", [0.0, 1.0])  # in the imports (trimesh's swallowed Ctrl-C), or in the trials
def test_an_interrupted_simulate_says_so_and_writes_nothing(cube, tmp_path, signum, delay):
    out = tmp_path / "results" / "simulated"  # made only with its files: an interrupted run leaves no empty folder
    process = subprocess.Popen([sys.executable, "-c", "from fixturecad.cli import main; main()", "simulate", str(cube),
                                "--trials", "1000", "--out", str(out)], stderr=subprocess.PIPE, text=True)
    _until_it_catches_sigterm(process)
    time.sleep(delay)
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signum
    # Before it: at most the announcement of a long run, made before the first trial.
    *before, last = stderr.splitlines()
    assert last == "fixturecad: interrupted; nothing was written"
    assert all(line.startswith("simulate: about ") for line in before) and len(before) <= 1
    assert not [p.name for p in cube.iterdir() if "simulation" in p.name]
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_simulate_in_worker_processes_says_so_once_and_leaves_none_running(cube, tmp_path, signum):
    """Stopped while its two workers run trials, the signal sent to them all as a terminal's Ctrl-C is: one line
    (the workers' go nowhere), nothing written, and the workers gone within a trial (each fails to send its
    trial to a parent that has gone)."""
    out = tmp_path / "simulated"
    process = subprocess.Popen([sys.executable, "-c", "from fixturecad.cli import main; main()", "simulate", str(cube),
                                "--trials", "1000", "--jobs", "2", "--out", str(out)], stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    children = Path(f"/proc/{process.pid}/task/{process.pid}/children")
    if not children.exists():
        pytest.skip("no /proc to see a process's children")
    deadline = time.monotonic() + 60
    while len(workers := children.read_text().split()) < 2:
        assert time.monotonic() < deadline and process.poll() is None
        time.sleep(0.01)
    time.sleep(0.5)  # (in their trials)
    os.killpg(process.pid, signum)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signum
    assert stderr.splitlines()[-1] == "fixturecad: interrupted; nothing was written"
    assert stderr.count("interrupted") == 1 and "Traceback" not in stderr
    assert not out.exists() and not [p.name for p in cube.iterdir() if "simulation" in p.name]
    deadline = time.monotonic() + 30
    while any(Path(f"/proc/{pid}").exists() and "(Z)" not in _state(pid) for pid in workers):
        assert time.monotonic() < deadline, "a worker outlived its parent"
        time.sleep(0.05)


def _state(pid):
    """A process's state letter in parentheses, as /proc/PID/status says it ('' once it is gone)."""
    try:
        line = next(line for line in Path(f"/proc/{pid}/status").read_text().splitlines() if line.startswith("State:"))
    except (FileNotFoundError, ProcessLookupError):
        return ""
    return line.split(None, 2)[2] if len(line.split()) > 2 else ""


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_register_py_says_so(cube, signum):
    process = subprocess.Popen([sys.executable, str(cube / "register.py"), str(cube / "touches.template.csv")],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _until_it_catches_sigterm(process)
    process.send_signal(signum)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 128 + signum and stdout == "" and stderr == "register.py: interrupted\n"


# Issue 22: lengths in another unit, ball centres taken for points, simulate's bounds.

def template_rows(folder, name="touches.template.csv"):
    """The (feature, point) rows of a build's touch template (fixture frame, mm)."""
    lines = (folder / name).read_text().splitlines()
    return [(cells[0], [float(x) for x in cells[1:]]) for cells in (line.split(",") for line in lines)
            if len(cells) == 4 and not cells[0].startswith("#") and cells[0] != "feature"]


@pytest.mark.parametrize("unit, per_mm, word", [("m", 1e-3, "metres"), ("in", 1 / 25.4, "inches"),
                                                ("um", 1e3, "micrometres")])
def test_touches_in_another_unit_are_refused_naming_it(cube, tmp_path, unit, per_mm, word):
    path = touches_csv(cube, tmp_path / "t.csv", [f"{f},{x * per_mm!r},{y * per_mm!r},{z * per_mm!r}"
                                                   for f, (x, y, z) in template_rows(cube)])
    for out in (run("register", cube, path),
                subprocess.run([sys.executable, str(cube / "register.py"), str(path)], capture_output=True, text=True)):
        assert_bad_input(out, word, "mm")
    # --units mm says they are mm: registered as they are, not refused (inches even fit the cube's three
    # planes through one corner, "unique" with a pose 48 mm off: what the spread check is for).
    trusted = run("register", cube, path, "--units", "mm")
    assert trusted.returncode != 2 and trusted.stderr == ""
    if unit == "um":
        return
    # Converted, the template's points are the fixture's own: the pose is the identity.
    for out in (run("register", cube, path, "--units", unit, "--format", "json"),
                subprocess.run([sys.executable, str(cube / "register.py"), str(path), "--units", unit, "--format", "json"],
                               capture_output=True, text=True)):
        assert out.returncode == 0, out.stderr
        document = json.loads(out.stdout)
        assert document["status"] == "unique"
        assert max(abs(v) for row in document["fixture2meas"] for v in row[:3]) == pytest.approx(1.0)
        assert max(abs(v) for v in document["translation_mm"]) < 1e-6


def test_cmm_points_in_metres_are_refused_and_converted(cube, tmp_path):
    import numpy as np

    example = Path(__file__).resolve().parent.parent / "docs" / "examples" / "cube-cmm.csv"
    rows = template_rows(example.parent, example.name)
    path = touches_csv(cube, tmp_path / "cmm-m.csv", [f"{f},{x / 1000!r},{y / 1000!r},{z / 1000!r}" for f, (x, y, z) in rows])
    assert_bad_input(run("calibrate", cube, path, "--out", tmp_path / "m"), "measured points", "metres", "--units m")
    assert not (tmp_path / "m").exists()
    for out, source, units in ((tmp_path / "m", path, "m"), (tmp_path / "mm", example, "mm")):
        assert run("calibrate", cube, source, "--out", out, "--units", units).returncode == 0
    features = [json.loads((tmp_path / name / "features.json").read_text())["features"] for name in ("m", "mm")]
    for converted, given in zip(*features):
        for key in ("point", "normal"):
            np.testing.assert_allclose(converted[key], given[key], atol=1e-9)


def test_ball_centres_registered_as_points_are_named(built, tmp_path):
    """A 2 mm ball tip's centres, without --ball-radius: every touch lies 2 mm outside its surface."""
    import numpy as np

    from fixturecad.registration.features import features_from_json

    folder = built("quarter-sphere")
    features = features_from_json(json.loads((folder / "features.json").read_text()))
    shift = np.array([5.0, -3.0, 2.0])
    rows = [f"{f},{','.join(map(str, (np.array(p) + 2.0 * features[f].normal_at(np.array(p))[0] + shift).tolist()))}"
            for f, p in template_rows(folder)]
    path = touches_csv(folder, tmp_path / "ball.csv", rows)
    assert_bad_input(run("register", folder, path), "2 mm outside", "--ball-radius 2")
    out = run("register", folder, path, "--ball-radius", 2, "--format", "json")
    assert out.returncode == 0 and json.loads(out.stdout)["status"] == "unique"
    assert np.allclose(json.loads(out.stdout)["translation_mm"], shift, atol=1e-6)


@pytest.mark.parametrize("option, value, words", [("--noise", 10, ("in mm", "--noise 0.01")),
                                                  ("--trials", 1_000_000, ("--trials", "100,000"))])
def test_simulate_bounds_its_noise_and_trials(cube, option, value, words):
    assert_bad_input(run("simulate", cube, option, value), *words)
    assert not (cube / "simulation.json").exists()


def test_calibrate_never_writes_over_its_input_nor_a_drawing_over_an_as_built(cube, tmp_path):
    example = Path(__file__).resolve().parent.parent / "docs" / "examples" / "cube-cmm.csv"
    before = {p.name: p.read_bytes() for p in cube.iterdir()}
    for out in (cube, tmp_path):
        assert_bad_input(run("calibrate", cube, example, "--out", out, "--force"), "the folder this command reads")
    assert {p.name: p.read_bytes() for p in cube.iterdir()} == before
    assert run("calibrate", cube, example, "--out", tmp_path / "asbuilt").returncode == 0
    assert_bad_input(run("build", "cube", "--out", tmp_path / "asbuilt", "--force"), "an as-built folder", "a drawing")
    assert "calibration" in json.loads((tmp_path / "asbuilt" / "features.json").read_text())
    drawing = shutil.copytree(cube, tmp_path / "drawing")
    assert_bad_input(run("calibrate", cube, example, "--out", drawing, "--force"), "is a drawing", "an as-built")
    assert "calibration" not in json.loads((drawing / "features.json").read_text())


# Issue 22: reading is streamed and bounded.

@pytest.mark.parametrize("command", ["register", "calibrate"])
def test_a_bad_row_is_reported_before_the_rest_is_read(cube, tmp_path, command):
    """The touch file is a pipe whose writer sends two rows and then waits: a reader that wanted the whole
    file first would wait with it."""
    import threading

    pipe = tmp_path / "touches.csv"
    os.mkfifo(pipe)
    done = threading.Event()

    def writer():
        with open(pipe, "w") as handle:
            handle.write("feature,x,y,z\nnosuch,1,2,3\n")
            handle.flush()
            done.wait(60)

    thread = threading.Thread(target=writer)
    thread.start()
    try:
        out = subprocess.run([sys.executable, "-c", "from fixturecad.cli import main; main()", command, str(cube),
                              str(pipe)], capture_output=True, text=True, timeout=50)
    finally:
        done.set()
        thread.join()
    assert_bad_input(out, "row 2", "unknown feature 'nosuch'")


def test_a_touch_file_past_the_limit_is_refused(cube, tmp_path):
    from fixturecad.registration.touchfile import MAX_TOUCH_ROWS

    path = touches_csv(cube, tmp_path / "t.csv", ["top,10,10,50"] * (MAX_TOUCH_ROWS + 1))
    assert_bad_input(run("register", cube, path), f"row {MAX_TOUCH_ROWS + 2}", f"more than {MAX_TOUCH_ROWS:,} touches")


def test_a_long_simulation_says_how_long_before_it_goes_on(cube, tmp_path):
    process = subprocess.Popen([sys.executable, "-c", "from fixturecad.cli import main; main()", "simulate", str(cube),
                                "--trials", "100000", "--out", str(tmp_path / "sim")], stderr=subprocess.PIPE, text=True)
    try:
        line = process.stderr.readline()
    finally:
        process.send_signal(signal.SIGINT)
        process.communicate(timeout=60)
    assert line.startswith("simulate: about ") and "min for 100000 trials" in line
    assert not list((tmp_path / "sim").glob("*"))


@pytest.mark.parametrize("command, option, value, words", [
    ("register", "--sigma", 5, ("--sigma is in mm", "--sigma 0.005")),
    ("register", "--ball-radius", 1500, ("--ball-radius is in mm", "give 1.5")),
    ("calibrate", "--sigma", 2, ("--sigma is in mm", "--sigma 0.002"))])
def test_lengths_in_micrometres_given_as_mm_are_refused(cube, tmp_path, command, option, value, words):
    out = tmp_path / "asbuilt"
    extra = ["--out", out] if command == "calibrate" else []
    assert_bad_input(run(command, cube, cube / "touches.template.csv", option, value, *extra), *words)
    assert not out.exists()
