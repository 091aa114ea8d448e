"""`fixturecad plan` against the templates' minimal plans and the best of 20,000 random plans, and its time.

Run by hand: ``python benchmarks/bench_plan.py``. For every template: the D-optimal plan of as many
point-probe touches as the minimal plan makes (the default plan where there is no ``minimal``), the best
(by the same criterion) of 20,000 seeded random plans of that count on the same candidates (the patches
1 mm in, reachable), and that plan; the Cramer-Rao bound of each per um of touch noise (translation um, rotation mdeg). Then the median time of
`fixturecad plan --touches 12`, the whole command.
"""

import json
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
from fixturecad.registration import planning  # noqa: E402
from fixturecad.registration.features import features_from_json  # noqa: E402
from fixturecad.registration.problem import Problem  # noqa: E402
from fixturecad.registration.sampling import load_mesh  # noqa: E402
from fixturecad.registration.synthetic import plan_touches  # noqa: E402
from fixturecad.registration.touches import build_groups  # noqa: E402
from fixturecad.registration.uncertainty import covariance, sigmas  # noqa: E402
from fixturecad.templates import TEMPLATES, make  # noqa: E402

RANDOM_PLANS = 20_000
SIGMA_MM = 0.005


def bound(rows):
    t, r = sigmas(covariance(rows, np.zeros(3), SIGMA_MM))
    return (np.inf, np.inf) if t is None else (t / SIGMA_MM, r / SIGMA_MM)


def main():
    print(describe())
    print("| template | touches | planned: um, mdeg | best of 20,000 random: um, mdeg | minimal: um, mdeg | plan time, 12 touches |")
    print("|---|---|---|---|---|---|")
    rng = np.random.default_rng(2026)
    with tempfile.TemporaryDirectory() as root:
        for name in TEMPLATES:
            folder = build(make(name), Path(root) / name)
            document = json.loads((folder / "features.json").read_text())
            features = features_from_json(document)
            mesh = load_mesh(folder / "fixture.stl")
            ids = [fid for fid, f in features.items() if f.kind in ("plane", "sphere", "cylinder")]
            cands = planning.candidates(features, ids, 1.0, keep=lambda p, n: planning.reachable(mesh.triangles, p, n))
            minimal = document["plans"].get("minimal", document["plans"]["default"])["touch_plan"]
            count = max(6, sum(len(e["points"]) for e in minimal))
            chosen = planning.design(cands, count, "d")
            scale = np.r_[np.full(3, 1.0 / cands.length_mm), np.ones(3)]
            picks = np.array([rng.choice(len(cands.rows), count, replace=False) for _ in range(RANDOM_PLANS)])
            rows = cands.rows[picks] * scale
            values = planning.criterion_values(np.einsum("kni,knj->kij", rows, rows), "d")
            best = picks[int(np.argmax(values))]
            touches, contacts = plan_touches(minimal, np.eye(4))
            _, J = Problem(build_groups(features, touches, 0.0, contacts), SIGMA_MM).evaluate(np.eye(3), np.zeros(3))
            times = []
            for _ in range(5):
                start = time.perf_counter()
                subprocess.run([sys.executable, "-m", "fixturecad", "plan", str(folder), "--touches", "12", "--force"],
                               check=True, capture_output=True)
                times.append(time.perf_counter() - start)
            cells = [f"{a:.3f}, {b:.3f}" for a, b in (bound(cands.rows[chosen]), bound(cands.rows[best]), bound(J))]
            print(f"| {name} | {count} | {' | '.join(cells)} | {statistics.median(times):.2f} s |")


if __name__ == "__main__":
    main()
