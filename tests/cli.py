"""Run the ``fixturecad`` entry point in a subprocess, as a user would."""

import subprocess
import sys


def run(*args, cwd=None, env=None):
    """Run ``fixturecad ARGS``; returns the CompletedProcess (text)."""
    return subprocess.run(
        [sys.executable, "-c", "from fixturecad.cli import main; main()", *map(str, args)],
        capture_output=True, text=True, cwd=cwd, env=env,
    )


def assert_bad_input(result, *words):
    """Exit code 2, one line on stderr that names the problem, nothing on stdout."""
    assert_one_line(result, 2, *words)


def assert_fault(result, *words):
    """Exit code 1 (the machine, not the input: a full disk, a missing library), one line with the reason."""
    assert_one_line(result, 1, *words)


def assert_one_line(result, code, *words):
    assert result.returncode == code, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    for word in words:
        assert word in lines[0]
