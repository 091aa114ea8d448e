"""Run the ``fixturecad`` entry point in a subprocess, as a user would."""

import subprocess
import sys


def run(*args, cwd=None):
    """Run ``fixturecad ARGS``; returns the CompletedProcess (text)."""
    return subprocess.run(
        [sys.executable, "-c", "from fixturecad.cli import main; main()", *map(str, args)],
        capture_output=True, text=True, cwd=cwd,
    )


def assert_bad_input(result, *words):
    """Exit code 2, one line on stderr that names the problem, nothing on stdout."""
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0]
