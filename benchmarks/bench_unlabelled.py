"""Unlabelled touches: what the search says, how long it takes and how close it comes, per template.

Run by hand: ``OMP_NUM_THREADS=1 python benchmarks/bench_unlabelled.py [--layouts N] [--touches 12]``. For every
template, N layouts: the touches drawn at random on the default plan's point-touch features' patches
(evenly over the features), a random true pose, 5 um noise, the labels dropped; ``register_touches`` with
``unlabelled=`` and no nominal pose, and the same touches labelled. Per template: the statuses and how the
search ended; the wrong answers (``unique`` more than 10 sigma from the truth, the labelled registration's
sigma; ``inconsistent`` or a lost truth although the search said complete, where the touches labelled fit a
pose); the error over the labelled
bound; the CPU time (``time.process_time``). The truth is the independent answer; no brute force runs.
"""

import argparse
import collections
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from machine import describe  # noqa: E402

NOISE_MM = 0.005
WRONG_SIGMAS = 10.0


def layouts(name, count, touches, rng):
    """The template's features and ``count`` layouts: (truth 4x4, labelled touches by feature)."""
    from fixturecad.build import features_document
    from fixturecad.registration.features import features_from_json
    from fixturecad.registration.patches import patch_points
    from fixturecad.registration.pose import fixture2meas_from_rt, random_rotation
    from fixturecad.templates import make

    document = features_document(make(name))
    features = features_from_json(document)
    planned = [e["feature"] for e in document["plans"]["default"]["touch_plan"] if "sensor" not in e]
    ids = [f for f in dict.fromkeys(planned) if features[f].kind in ("plane", "sphere", "cylinder")]
    out = []
    for _ in range(count):
        R, t = random_rotation(rng), rng.uniform(-80.0, 80.0, 3)
        shares = np.diff(np.linspace(0, touches, len(ids) + 1).round().astype(int))
        drawn = {}
        for fid, n in zip(ids, shares):
            points = patch_points(features[fid])
            drawn[fid] = points[rng.choice(len(points), n, replace=False)] @ R.T + t + rng.normal(0, NOISE_MM, (n, 3))
        out.append((fixture2meas_from_rt(R, t), drawn))
    return features, out


def run(count, touches, seed):
    from fixturecad.registration.engine import register_touches
    from fixturecad.registration.pose import pose_errors
    from fixturecad.templates import TEMPLATES

    rng = np.random.default_rng(seed)
    print(f"machine: {describe()}; {count} layouts a template, {touches} touches, {NOISE_MM * 1000:g} um noise")
    print("template | statuses (search) | wrong | error / labelled bound, median | ms median, 95th percentile, max")
    for name in sorted(TEMPLATES):
        features, cases = layouts(name, count, touches, rng)
        statuses, wrong, ratios, times = collections.Counter(), 0, [], []
        for truth, drawn in cases:
            labelled = register_touches(features, drawn, sigma_mm=NOISE_MM)
            points = np.concatenate(list(drawn.values()))
            start = time.process_time()
            result = register_touches(features, {}, unlabelled=points, sigma_mm=NOISE_MM)
            times.append(1000.0 * (time.process_time() - start))
            statuses[f"{result['status']} ({result['search']})"] += 1
            sigma = labelled["sigma_translation_mm"] or 0.0
            found = [pose_errors(np.array(s["pose"]), truth)[0] for s in result["solutions"]]
            if result["status"] == "unique" and result["pose"] is not None:
                error = pose_errors(np.array(result["pose"]), truth)[0]
                wrong += error > WRONG_SIGMAS * sigma + 1e-3
                ratios.append(error / max(sigma, 1e-12))
            elif result["search"] == "complete" and not any(e <= WRONG_SIGMAS * sigma + 1e-3 for e in found):
                # Complete, yet the truth is not among the poses: wrong unless the same touches labelled fit no
                # pose either (the noise fails the test at the truth now and then).
                wrong += labelled["status"] != "inconsistent"
        print(f"{name} | {dict(statuses)} | {wrong} | "
              f"{statistics.median(ratios) if ratios else float('nan'):.2f} | "
              f"{statistics.median(times):.0f}, {np.percentile(times, 95):.0f}, {max(times):.0f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--layouts", type=int, default=20, help="layouts a template")
    parser.add_argument("--touches", type=int, default=12, help="unlabelled touches a layout")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    run(args.layouts, args.touches, args.seed)


if __name__ == "__main__":
    main()
