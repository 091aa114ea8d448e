"""One faulty touch in every template's default plan: is it found and named, is a wrong pose ever `unique`?

Run by hand: ``python benchmarks/bench_redundancy.py [--trials 200] [--plan default]``. For every
template, seeded trials: a random true pose, a random layout (every point touch of the plan moved along its
feature by up to ``JITTER_FRACTION`` of the fixture's size, kept on its patch), 5 um of sensor noise, then
one point touch spoiled: moved ``OFF_MM`` along a random direction, or taken on a random point of another
feature's patch but given its own label. Registered without a nominal pose, each trial is counted as

* named: `inconsistent` with the spoiled touch as the one culprit;
* harmless: `unique` with the pose right (no plan point moved more than ``WRONG_MM``): the fault did not
  matter, e.g. a move along the surface;
* other: any other answer that is not a wrong `unique` (several culprits, no pose, `ambiguous`);
* wrong unique: `unique` with a plan point moved more than ``WRONG_MM``.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from machine import describe  # noqa: E402

from fixturecad.registration.engine import register_touches  # noqa: E402
from fixturecad.registration.patches import patch_points  # noqa: E402
from fixturecad.registration.pose import fixture2meas_from_rt, random_rotation  # noqa: E402
from fixturecad.registration.synthetic import perturb_touches, plan_touches  # noqa: E402
from fixturecad.templates import TEMPLATES, make  # noqa: E402

SIGMA_MM = 0.005
OFF_MM = 0.5
WRONG_MM = 0.05  # ten times the noise: a pose moving a plan point further is wrong
JITTER_FRACTION = 0.1  # a touch moves along its feature by up to this share of the patch's size
SURFACES = ("plane", "sphere", "cylinder")  # what a point probe touches
OUTCOMES = ("named", "harmless", "other", "wrong unique")


def jittered(features, entries, rng):
    """The plan's entries with every point touch moved at random along its feature, kept on its patch."""
    out = []
    for entry in entries:
        if "sensor" in entry:
            out.append(entry)
            continue
        feature = features[entry["feature"]]
        reach = JITTER_FRACTION * np.ptp(patch_points(feature), axis=0).max()
        points = []
        for point in np.asarray(entry["points"], float):
            moved = feature.closest_point((point + rng.uniform(-reach, reach, 3))[None])[0]
            points.append(moved if feature.contains(moved[None], 0.0)[0] else point)
        out.append({**entry, "points": np.array(points).tolist()})
    return out


def trial(features, entries, rng, fault):
    """One registration with one spoiled point touch; its outcome (one of ``OUTCOMES``)."""
    truth = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-100.0, 100.0, 3))
    layout = jittered(features, entries, rng)
    touches, contacts = perturb_touches(*plan_touches(layout, truth), rng, SIGMA_MM)
    # The engine numbers point touches feature by feature in the dict's order, contacts after them.
    order = [(fid, k) for fid, points in touches.items() for k in range(len(points))]
    spoiled = int(rng.integers(len(order)))
    fid, k = order[spoiled]
    if fault == "off":
        direction = rng.normal(size=3)
        touches[fid][k] += OFF_MM * direction / np.linalg.norm(direction)
    else:
        other = features[rng.choice([f for f, g in features.items() if f != fid and g.kind in SURFACES])]
        samples = patch_points(other)
        touches[fid][k] = truth[:3, :3] @ samples[rng.integers(len(samples))] + truth[:3, 3]
    result = register_touches(features, touches, sigma_mm=SIGMA_MM, contacts=contacts)
    if result["status"] == "inconsistent" and result["culprit"] == spoiled:
        return "named"
    if result["status"] != "unique":
        return "other"
    points = np.concatenate([np.asarray(e["points"], float) for e in layout])
    moved = points @ (np.array(result["pose"])[:3, :3] - truth[:3, :3]).T + np.array(result["pose"])[:3, 3] - truth[:3, 3]
    return "harmless" if np.linalg.norm(moved, axis=1).max() <= WRONG_MM else "wrong unique"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=200, help="trials per template and kind of fault")
    parser.add_argument("--plan", default="default", help="the touch plan of every template")
    parser.add_argument("--template", action="append", choices=list(TEMPLATES), help="only these templates")
    args = parser.parse_args()
    print(describe())
    print(f"| template | touches | fault | {' | '.join(OUTCOMES)} | named or harmless |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.template or TEMPLATES:
        template = make(name)
        features, entries = template.feature_map(), template.touch_plans()[args.plan].touches
        count = sum(len(e["points"]) for e in entries)
        for fault in ("off", "label"):
            rng = np.random.default_rng(12)
            counts = dict.fromkeys(OUTCOMES, 0)
            for _ in range(args.trials):
                counts[trial(features, entries, rng, fault)] += 1
            share = (counts["named"] + counts["harmless"]) / args.trials
            kind = f"{OFF_MM} mm off" if fault == "off" else "wrong label"
            print(f"| {name} | {count} | {kind} | {' | '.join(str(counts[o]) for o in OUTCOMES)} | {100 * share:.1f} % |",
                  flush=True)


if __name__ == "__main__":
    main()
