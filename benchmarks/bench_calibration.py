"""Time of ``fixturecad calibrate`` on 1,000 measured points (issue 7 target: under 1 s).

Run by hand: ``python benchmarks/bench_calibration.py``. For every template:
the fit alone (features from the template, no CAD), and, for the cube, the
whole command on a built folder (imports, fit, register.py, calibration.png).
The points lie on a part printed within a 0.2 mm zone, 2 um noise, seeded.
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

from fixturecad.registration.calibration import calibrate  # noqa: E402
from fixturecad.registration.deviations import FixtureTolerance  # noqa: E402
from fixturecad.registration.patches import patch_points  # noqa: E402
from fixturecad.registration.pose import fixture2meas_from_rt, random_rotation  # noqa: E402
from fixturecad.templates import TEMPLATES  # noqa: E402

POINTS = 1000


def measured(features, scheme, rng):
    part = FixtureTolerance(features, scheme, 0.2).random_part(rng)
    pose = fixture2meas_from_rt(random_rotation(rng), rng.uniform(-300, 300, 3))
    out = {}
    for fid, feature in features.items():
        points = patch_points(feature)
        points = part[fid].closest_point(points[rng.choice(len(points), POINTS // len(features))])
        out[fid] = points @ pose[:3, :3].T + pose[:3, 3] + rng.normal(scale=0.002, size=points.shape)
    return out


def fit_time(name, runs=5):
    template = TEMPLATES[name]()
    features = {f.id: f for f in template.features()}
    points = measured(features, template.DATUMS, np.random.default_rng(1))
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        calibrate(features, template.DATUMS, points, 0.002, 0.1)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def command_time(runs=3):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "cube"
        subprocess.run([sys.executable, "-m", "fixturecad", "build", "cube", "--out", str(folder)], check=True,
                       capture_output=True)
        template = TEMPLATES["cube"]()
        features = {f.id: f for f in template.features()}
        points = measured(features, template.DATUMS, np.random.default_rng(2))
        lines = ["feature,x,y,z"] + [f"{fid},{x},{y},{z}" for fid, p in points.items() for x, y, z in p]
        (Path(tmp) / "cmm.csv").write_text("\n".join(lines) + "\n")
        times = []
        for _ in range(runs):
            start = time.perf_counter()
            subprocess.run([sys.executable, "-m", "fixturecad", "calibrate", str(folder), str(Path(tmp) / "cmm.csv"),
                            "--sigma", "0.002", "--force"], check=True, capture_output=True)
            times.append(time.perf_counter() - start)
        json.loads((Path(tmp) / "cube-asbuilt" / "features.json").read_text())
    return statistics.median(times)


if __name__ == "__main__":
    print(describe())
    for name in TEMPLATES:
        print(f"fit of {POINTS} points, {name}: median {fit_time(name) * 1e3:.0f} ms")
    print(f"fixturecad calibrate (cube, {POINTS} points, whole command): median {command_time():.2f} s")
