"""Every command the README and the docs show runs as written on a fresh build, in order, each file in a
folder of its own (with the shipped example files)."""

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
    """The ``$ `` lines of a page's console blocks, comments stripped."""
    lines, inside = [], False
    for line in (ROOT / page).read_text().splitlines():
        if line.startswith("```"):
            inside = line.strip() == "```console"
        elif inside and line.startswith("$ "):
            lines.append(shlex.split(line[2:], comments=True))
    return lines


@pytest.mark.parametrize("page", [p for p in PAGES if commands(p)])
def test_the_commands_of_a_page_run(page, tmp_path):
    shutil.copytree(ROOT / "docs" / "examples", tmp_path / "docs" / "examples")
    outputs = []
    for argv in commands(page):
        if argv[0] == "fixturecad":
            result = run(*argv[1:], cwd=tmp_path)
        else:
            assert argv[0] == "python", argv
            result = subprocess.run([sys.executable, *argv[1:]], cwd=tmp_path, capture_output=True, text=True)
        assert result.returncode == 0, (argv, result.stderr)
        outputs.append(result.stdout)
    if page == "docs/tolerance.md":
        # As the page says: the example part's left face is out of the recorded zone.
        assert any("left" in out and "OUT of the 0.1 mm zone" in out for out in outputs)
    if page in ("README.md", "docs/fixtures.md"):
        assert (tmp_path / "out" / "quarter-sphere-r40" / "fixture.step").exists()
