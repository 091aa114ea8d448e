"""Benchmark: `fixturecad build quarter-sphere --radius 40` end to end against `python -c "import cadquery"`.

Both run as fresh processes, several times each, interleaved; the medians are
compared. The issue asks for a ratio below 2. Run from the repository root:

    .venv/bin/python benchmarks/bench_build.py [--runs 7]
"""

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

TARGET_RATIO = 2.0


def wall_time(command, cwd) -> float:
    start = time.perf_counter()
    subprocess.run(command, cwd=cwd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    build = [sys.executable, "-c", "from fixturecad.cli import main; main()",
             "build", "quarter-sphere", "--radius", "40", "--force"]
    imports = [sys.executable, "-c", "import cadquery"]
    with tempfile.TemporaryDirectory() as work:
        wall_time(imports, work)  # warm the file cache once
        wall_time(build, work)
        build_times, import_times = [], []
        for _ in range(args.runs):
            import_times.append(wall_time(imports, work))
            build_times.append(wall_time(build, work))
    build_median, import_median = statistics.median(build_times), statistics.median(import_times)
    ratio = build_median / import_median
    print(f"machine: {os.cpu_count()} cpus, {cpu_model()}, Python {platform.python_version()}")
    print(f"import cadquery                         median {import_median:.3f} s  ({args.runs} runs)")
    print(f"fixturecad build quarter-sphere -r 40   median {build_median:.3f} s  ({args.runs} runs)")
    print(f"ratio {ratio:.2f} (target < {TARGET_RATIO:g}): {'PASS' if ratio < TARGET_RATIO else 'FAIL'}")


if __name__ == "__main__":
    main()
