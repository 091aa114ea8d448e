"""Every command the README and the docs show runs as written, in the order written, each page in a folder of
its own (with the shipped example files) as a user who opens that page would: no page leans on another's
outputs. The pages run side by side on the suite's workers."""

import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from cli import run

ROOT = Path(__file__).resolve().parent.parent
PAGES = ["README.md"] + sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))


def commands(page):
    """The commands of a page: the ``fixturecad`` steps of its ``bash`` blocks (the install line's build)
    and the ``$ `` lines of its console blocks, comments stripped, in the order written."""
    lines, block = [], None
    for line in (ROOT / page).read_text().splitlines():
        if line.startswith("```"):
            block = line.strip()[3:] if block is None else None
        elif block == "console" and line.startswith("$ "):
            lines.append(shlex.split(line[2:], comments=True))
        elif block == "bash":
            steps = [shlex.split(step) for step in line.split("&&")]
            lines += [["fixturecad", *step[1:]] for step in steps if step and step[0].endswith("/fixturecad")]
    return lines


@pytest.mark.parametrize("page", [page for page in PAGES if commands(page)])
def test_the_commands_of_every_page_run_in_order(page, tmp_path):
    shutil.copytree(ROOT / "docs" / "examples", tmp_path / "docs" / "examples")
    outputs = []
    for argv in commands(page):
        if argv[0] == "fixturecad":
            result = run(*argv[1:], cwd=tmp_path)
        else:
            assert argv[0] == "python", argv
            result = subprocess.run([sys.executable, *argv[1:]], cwd=tmp_path, capture_output=True, text=True)
        assert result.returncode == 0, (page, argv, result.stderr)
        outputs.append(result.stdout)
    if page == "README.md":
        assert commands(page)[0][:2] == ["fixturecad", "build"]  # the install line's build comes first
        assert (tmp_path / "out" / "quarter-sphere-r40" / "fixture.step").exists()
    if page == "docs/tolerance.md":
        # As the page says: the example part's left face is out of the recorded zone.
        assert any("left" in out and "OUT of the 0.1 mm zone" in out for out in outputs)
