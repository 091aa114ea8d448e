"""Benchmark: `fixturecad design` over Table V: classes designed, built, registered, and the time per design.

Every one of the 579 classes is laid out (no CAD) as `design --class` does it;
a spread sample is designed and built end to end by the command line, each
folder's register.py registers synthetic touches of its plan made at a random
pose, and the median time of a design is compared with `fixturecad build
quarter-sphere --radius 40`, run between the designs (target: at most 1.5
times). Run from the repository root:

    .venv/bin/python benchmarks/bench_design.py [--sample 12] [--seed 1]
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from machine import describe

TARGET_RATIO = 1.5
CLI = [sys.executable, "-c", "from fixturecad.cli import main; main()"]


def timed(command, cwd):
    start = time.perf_counter()
    result = subprocess.run(command, cwd=cwd, capture_output=True, text=True)
    return time.perf_counter() - start, result


def register(folder: Path, rng) -> tuple[str, bool]:
    """(status, right pose among the solutions) for the default plan's touches made at a random pose."""
    from fixturecad.registration.pose import random_rotation
    from fixturecad.registration.synthetic import plan_touches
    from fixturecad.registration.touchfile import touch_json

    document = json.loads((folder / "features.json").read_text())
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = random_rotation(rng), rng.uniform(-300, 300, 3)
    touches = folder / "synthetic.json"
    touches.write_text(touch_json(*plan_touches(document["plans"]["default"]["touch_plan"], pose)))
    result = subprocess.run([sys.executable, folder / "register.py", touches, "--json"], capture_output=True, text=True)
    answer = json.loads(result.stdout)
    errors = [np.abs(np.array(s["pose"]) - pose).max() for s in answer["solutions"]]
    return answer["status"], bool(errors) and min(errors) < 1e-3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sample", type=int, default=12, help="classes built end to end, spread over Table V")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    from fixturecad.design.combination import for_class
    from fixturecad.design import DEFAULT_BALL_MM, DEFAULT_SIZE_MM, DESIGN_SEED
    from fixturecad.design.layout import best_layout
    from fixturecad.theory.enumeration import enumerate_classes

    found = enumerate_classes().found
    start, designed, failed, margins = time.perf_counter(), 0, [], []
    for number, item in enumerate(found, start=1):
        combination = for_class(item.members)
        layout, _ = best_layout(combination.contacts, combination.labels, DEFAULT_SIZE_MM, DEFAULT_BALL_MM, DESIGN_SEED)
        if layout is None:
            failed.append(item.name)
        else:
            designed += 1
            margins.append(layout.margin)
        print(f"\rlayouts {number}/{len(found)}", end="", file=sys.stderr, flush=True)
    layout_seconds = (time.perf_counter() - start) / len(found)
    print(file=sys.stderr)

    sample = [found[i] for i in np.linspace(0, len(found) - 1, args.sample).round().astype(int)]
    rng = np.random.default_rng(args.seed)
    built, among, statuses, design_times = 0, 0, Counter(), []
    with tempfile.TemporaryDirectory() as work:
        build_times = []
        for number, item in enumerate(sample, start=1):
            # interleaved with the designs, so that both see the same load on a shared machine
            build_times.append(timed(CLI + ["build", "quarter-sphere", "--radius", "40", "--force"], work)[0])
            folder = Path(work) / f"design-{number}"
            seconds, result = timed(CLI + ["design", "--class", item.name, "--out", str(folder)], work)
            if result.returncode == 0:
                built += 1
                design_times.append(seconds)
                status, right = register(folder, rng)
                statuses[status, right] += 1
                among += right
            else:
                print(f"\n{item.name}: {result.stderr.strip()}", file=sys.stderr)
            print(f"\rbuilds {number}/{len(sample)}", end="", file=sys.stderr, flush=True)
        print(file=sys.stderr)
    design_median, build_median = statistics.median(design_times), statistics.median(build_times)
    ratio = design_median / build_median
    print(f"machine: {describe()}")
    print(f"classes of Table V laid out, mobility 0 at the real geometry: {designed}/{len(found)} "
          f"({layout_seconds * 1000:.0f} ms each; smallest margin {min(margins):.2g}, median {np.median(margins):.2g})")
    for name in failed:
        print(f"  not laid out: {name}")
    print(f"sample designed and built (one valid solid, features on its BREP): {built}/{len(sample)}")
    print(f"registered by register.py at a random pose: right pose among the solutions {among}/{built}; "
          + ", ".join(f"{status} ({'right' if right else 'wrong'} pose) {count}"
                      for (status, right), count in sorted(statuses.items())))
    print(f"fixturecad design --class (median of {len(design_times)}) {design_median:.2f} s; "
          f"build quarter-sphere -r 40 (median of {len(build_times)}, interleaved) {build_median:.2f} s")
    print(f"ratio {ratio:.2f} (target <= {TARGET_RATIO:g}): {'PASS' if ratio <= TARGET_RATIO else 'FAIL'}")


if __name__ == "__main__":
    main()
