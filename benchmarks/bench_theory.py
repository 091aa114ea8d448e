"""Wall time of the theory commands, end to end, as a user runs them.

Run by hand: ``python benchmarks/bench_theory.py``. Targets (issue 2):
``fixturecad catalog --format json`` (rank verification included) under 1 s,
``fixturecad --help`` under 0.5 s.
"""

import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from machine import describe  # noqa: E402

COMMANDS = {
    "fixturecad --help": ["--help"],
    "fixturecad catalog --format json": ["catalog", "--format", "json"],
    "fixturecad analyze PL/F-PL/F P/F-S/M P/F-PL/M L/M-L/M": ["analyze", "PL/F-PL/F", "P/F-S/M", "P/F-PL/M", "L/M-L/M"],
    "fixturecad analyze (cube 3-2-1 with labels)": ["analyze"] + ["P/F-PL/M@a"] * 3 + ["P/F-PL/M@b"] * 2 + ["P/F-PL/M@c"],
}


def wall_time(args, runs=7) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "fixturecad", *args], check=True, capture_output=True)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


if __name__ == "__main__":
    print(describe())
    for label, args in COMMANDS.items():
        print(f"{label}: median {wall_time(args):.3f} s")
