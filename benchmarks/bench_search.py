"""Issues 12 and 18's long sweep: register_touches on many seeded random layouts per case, judged against the
brute-force enumeration of admissible poses (tests/brute_force.py, tests/search_cases.py).

Run by hand: ``python benchmarks/bench_search.py [--layouts 200] [--case SUBSTRING] [--first 0]``. Per case and noise
level, one row: layouts; the engine's answers by status; its failures (a wrong ``unique``, ``unique``
with another admissible pose, ``unique`` with none, ``ambiguous`` missing an admissible pose, a false
``inconsistent``, a separating touch off the part or not separating); the median, 95th percentile and largest
time of one register_touches call without and with a nominal pose (5 deg, 5 mm off), and of the brute force (run
only where the engine claims a pose: not on `underdetermined` or a stopped search).
Times are the CPU time of the process (``time.process_time``, one thread: run with OMP_NUM_THREADS=1),
which other load on a shared machine does not inflate; one run each.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
from machine import describe  # noqa: E402
from search_cases import VARIANTS, judge_all, variant_id  # noqa: E402

FAILURES = [
    # A stopped search on a continuum too weak to claim says underdetermined (exit 4); any other exits 6.
    ("search stopped, underdetermined", lambda o: o.search != "complete" and o.status == "underdetermined"),
    ("search stopped, exit 6", lambda o: o.search != "complete" and o.status != "underdetermined"),
    ("wrong unique", lambda o: o.wrong_unique),
    ("unique, missed one", lambda o: o.unique_missed),
    ("unique, none admissible", lambda o: o.unique_none),
    ("ambiguous, missing one", lambda o: o.ambiguous_missing),
    ("false inconsistent", lambda o: o.false_inconsistent),
    ("separating touch off the part", lambda o: o.separating == "off the part"),
    ("separating touch does not separate", lambda o: o.separating in ("does not separate", "missing")),
]
STATUSES = ("unique", "ambiguous", "inconsistent", "underdetermined")
TIMES = ("engine", "engine, nominal pose", "brute force")


def row(name, outcomes):
    counts = [sum(o.status == s for o in outcomes) for s in STATUSES]
    failures = [sum(bool(test(o)) for o in outcomes) for _, test in FAILURES]
    times = []
    for key in TIMES:
        # The brute force runs only where the engine claims a pose.
        ms = [1000.0 * o.seconds[key] for o in outcomes if key in o.seconds]
        times.append(f"{np.median(ms):.1f} / {np.percentile(ms, 95):.0f} / {max(ms):.0f}" if ms else "-")
    return [name, str(len(outcomes))] + [str(c) for c in counts] + [str(f) for f in failures] + times


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--layouts", type=int, default=200, help="random layouts per case and noise level")
    parser.add_argument("--case", default="", help="only the cases whose name contains this")
    parser.add_argument("--first", type=int, default=0,
                        help="the first layout's index: another draws fresh seeds (the README's rows: 0 and 1000)")
    args = parser.parse_args()
    print(f"machine: {describe()}")
    header = (["case", "layouts"] + list(STATUSES) + [name for name, _ in FAILURES]
              + [f"{key} ms (median / 95th / max)" for key in TIMES])
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for case, noise_mm in VARIANTS:
        name = variant_id(case, noise_mm)
        if args.case in name:
            outcomes = judge_all(case, noise_mm, args.layouts, timed=True, first=args.first)
            print("| " + " | ".join(row(name, outcomes)) + " |", flush=True)


if __name__ == "__main__":
    main()
