"""`fixturecad plan` against the default plans and 20,000 random plans, and its time.

Run by hand: ``python benchmarks/bench_plan.py``. For every template: the plan designed on the determinant
(criterion d) with as many point-probe touches as the default plan makes (at least six), as the command makes
it (the default plan given when it is a point-probe plan of that count); 20,000 seeded random plans of that
count on the same candidates (the patches 1 mm in, reachable, the default plan's touches among them): the
best by the determinant, and how many of those that locate have both bounds smaller than the designed plan's;
the default plan. The Cramer-Rao bound of each per um of touch noise (translation um, rotation mdeg). Then
the median of five runs of the whole command `fixturecad plan --touches 12`, with a point probe and with a
ball tip of radius 2 mm: wall time and CPU time.
"""

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from machine import describe  # noqa: E402

from fixturecad.build import build  # noqa: E402
from fixturecad.plan_commands import default_touches  # noqa: E402
from fixturecad.registration import planning  # noqa: E402
from fixturecad.registration.features import features_from_json  # noqa: E402
from fixturecad.registration.mobility import matrix_ranks  # noqa: E402
from fixturecad.registration.problem import Problem  # noqa: E402
from fixturecad.registration.reach import reachable  # noqa: E402
from fixturecad.registration.sampling import read_triangles  # noqa: E402
from fixturecad.registration.synthetic import plan_touches  # noqa: E402
from fixturecad.registration.touches import build_groups  # noqa: E402
from fixturecad.registration.uncertainty import covariance, sigmas  # noqa: E402
from fixturecad.templates import TEMPLATES, make  # noqa: E402

RANDOM_PLANS = 20_000
SIGMA_MM = 0.005
RUNS = 5


def bound(rows):
    t, r = sigmas(covariance(rows, np.zeros(3), SIGMA_MM))
    return (np.inf, np.inf) if t is None else (t / SIGMA_MM, r / SIGMA_MM)


def command_time(folder, *options):
    """Median wall and CPU (user + system) seconds of the command: on a shared machine the CPU time is what
    the command itself costs."""
    times = []
    for _ in range(RUNS):
        before, start = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
        subprocess.run([sys.executable, "-m", "fixturecad", "plan", str(folder), "--touches", "12", "--force",
                        *options], check=True, capture_output=True)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        times.append((time.perf_counter() - start, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime))
    wall, cpu = (statistics.median(t) for t in zip(*times))
    return f"{wall:.2f} s ({cpu:.2f} s CPU)"


def main():
    print(f"{describe()}, load average {os.getloadavg()[0]:.1f} at the start")
    print("| template | touches | planned | best of 20,000 random (by det) | random plans better in both "
          "| default | plan, 12 touches: point; ball 2 mm |")
    print("|---|---|---|---|---|---|---|")
    rng = np.random.default_rng(2026)
    with tempfile.TemporaryDirectory() as root:
        for name in TEMPLATES:
            folder = build(make(name), Path(root) / name)
            document = json.loads((folder / "features.json").read_text())
            features = features_from_json(document)
            triangles = read_triangles(folder / "fixture.stl")
            ids = [fid for fid, f in features.items() if f.kind in planning.SURFACES]
            default = document["plans"]["default"]["touch_plan"]
            count = max(6, sum(len(e["points"]) for e in default))
            reference = default_touches(document, ids, count)
            points = planning.candidate_points(features, ids, planning.DEFAULT_MARGIN_MM, also=reference,
                                               keep=lambda p, n: reachable(triangles, p, n))
            cands = planning.candidates(features, points)
            chosen = planning.design(cands, count, "d", None, reference and planning.indices(cands, reference))
            planned = bound(cands.rows[chosen])
            scale = np.r_[np.full(3, 1.0 / cands.length_mm), np.ones(3)]
            picks = np.array([rng.choice(len(cands.rows), count, replace=False) for _ in range(RANDOM_PLANS)])
            rows = cands.rows[picks] * scale
            values = planning.criterion_values(np.einsum("kni,knj->kij", rows, rows), "d")
            best = picks[int(np.argmax(values))]
            located = picks[matrix_ranks(rows) == 6]
            better = sum(all(b < p for b, p in zip(bound(cands.rows[k]), planned)) for k in located)
            touches, contacts = plan_touches(default, np.eye(4))
            _, J = Problem(build_groups(features, touches, 0.0, contacts), SIGMA_MM).evaluate(np.eye(3), np.zeros(3))
            cells = [f"{a:.3f}, {b:.3f}" for a, b in (planned, bound(cands.rows[best]))]
            cells += [f"{better} of {len(located)}", "{:.3f}, {:.3f}".format(*bound(J))]
            times = f"{command_time(folder)}; {command_time(folder, '--sensor', 'ball:2')}"
            print(f"| {name} | {count} | {' | '.join(cells)} | {times} |", flush=True)


if __name__ == "__main__":
    main()
