"""Touch files and the command line of the generated ``register.py``.

A CSV touch file has the header ``feature,x,y,z``: one touch per line, the
feature id of features.json and the probe point (or ball centre) in mm in the
measurement frame; lines starting with ``#`` and blank lines are skipped, and
a UTF-8 byte order mark (Excel's "CSV UTF-8") is allowed. Three more columns ``ax,ay,az`` may give the direction the
probe moved to make the touch; poses at which it would have touched a surface
from inside are then rejected. A JSON touch file holds contacts of any type
(a point touch may carry ``"approach": [ax, ay, az]``)::

    {"ball_radius_mm": 0.0,
     "touches": [{"feature": "flat_a", "point": [x, y, z]},
                 {"feature": "base", "contact": "PL/F-PL/F",
                  "sensor": {"q": [...], "n": [...], "o": [...], "u": [...]}, "rho": 0.0}]}

Errors are ``ValueError`` with a one-line message. This module imports numpy
only and nothing of fixturecad: it is inlined into the generated standalone
``register.py``.
"""

import argparse
import csv
import io
import json
import os
import sys

import numpy as np

from .defaults import DEFAULT_SIGMA_MM, SENSOR_LEVER_MM

CSV_COLUMNS = ("feature", "x", "y", "z")
APPROACH_COLUMNS = ("ax", "ay", "az")
MIN_ROWS = 6  # constraint rows a rigid pose needs at the very least
# Exit code of a registration by its status; 2 is bad input.
EXIT_CODES = {"unique": 0, "ambiguous": 3, "underdetermined": 4, "inconsistent": 5}


def read_touch_csv(text, feature_ids):
    """Touches and approach directions by feature id, arrays (n, 3), from CSV text, and the
    file line of every touch by feature id (lists)."""
    text = text.removeprefix("\ufeff")  # Excel's "CSV UTF-8" starts with a byte order mark
    # Comment lines (#) and blank lines are skipped; the others keep their line number in the file.
    numbered = [(k, row) for k, row in enumerate(csv.reader(io.StringIO(text)), start=1)
                if row and any(cell.strip() for cell in row) and not row[0].lstrip().startswith("#")]
    if not numbered:
        raise ValueError("the touch file is empty")
    header = tuple(cell.strip().lower() for cell in numbered[0][1])
    if header not in (CSV_COLUMNS, CSV_COLUMNS + APPROACH_COLUMNS):
        raise ValueError(
            f"touch CSV must have the columns {','.join(CSV_COLUMNS)} (and optionally "
            f"{','.join(APPROACH_COLUMNS)}), got {','.join(header)}"
        )
    width = len(header)
    touches, approaches, lines = {}, {}, {}
    for line, row in numbered[1:]:
        if len(row) != width:
            raise ValueError(f"line {line}: expected {width} values ({','.join(header)}), got {len(row)}")
        _check_id(row[0].strip(), feature_ids, f"line {line}")
        try:
            values = [float(cell) for cell in row[1:]]
        except ValueError:
            raise ValueError(f"line {line}: coordinates must be numbers, got {','.join(row[1:])}") from None
        if not np.all(np.isfinite(values)):
            raise ValueError(f"line {line}: coordinates must be finite, got {','.join(row[1:])}")
        touches.setdefault(row[0].strip(), []).append(values[:3])
        approaches.setdefault(row[0].strip(), []).append(values[3:] or [np.nan] * 3)
        lines.setdefault(row[0].strip(), []).append(line)
    if not touches:
        raise ValueError("the touch file has a header but no touches")
    arrays = {key: np.array(value) for key, value in approaches.items()}
    return {key: np.array(value) for key, value in touches.items()}, (arrays if width == 7 else {}), lines


def touch_csv(entries, plan_name):
    """A touch CSV a user fills in: a point-touch plan's nominal points (fixture frame, mm), with how to."""
    lines = [f"# Touch plan {plan_name!r}: the nominal points in the fixture frame, mm. Replace each x,y,z",
             "# by the point the probe measured on that feature (measurement frame), keep the feature ids;",
             "# add or remove rows as you touch. Lines starting with # are skipped.",
             ",".join(CSV_COLUMNS)]
    for entry in entries:
        for x, y, z in np.asarray(entry["points"], float).reshape(-1, 3):
            lines.append(f"{entry['feature']},{x:.4f},{y:.4f},{z:.4f}")
    return "\n".join(lines) + "\n"


def read_touch_json(text, feature_ids):
    """Point touches by feature id, the other contacts, and the ball radius, from JSON text."""
    if not text.strip():
        raise ValueError("the touch file is empty")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"touch JSON is not valid JSON: {error.msg} at line {error.lineno}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("touches"), list):
        raise ValueError('touch JSON must be an object with a "touches" list')
    touches, contacts, approaches = {}, [], {}
    for k, entry in enumerate(doc["touches"]):
        where = f"touch {k}"
        if not isinstance(entry, dict):
            raise ValueError(f"{where}: expected an object")
        _check_id(entry.get("feature"), feature_ids, where)
        if "contact" in entry:
            sensor = entry.get("sensor")
            if not isinstance(sensor, dict):
                raise ValueError(f"{where}: a {entry['contact']} contact needs the sensor geometry")
            for key, value in sensor.items():
                if key != "kind":
                    _check_finite(value, f"{where}: sensor {key}")
            contacts.append(entry)
        else:
            point = _check_finite(entry.get("point"), f"{where}: point")
            if point.shape != (3,):
                raise ValueError(f"{where}: point must be [x, y, z] in mm")
            touches.setdefault(entry["feature"], []).append(point)
            approach = entry.get("approach")
            approach = [np.nan] * 3 if approach is None else _check_finite(approach, f"{where}: approach")
            approaches.setdefault(entry["feature"], []).append(approach)
    if not touches and not contacts:
        raise ValueError("the touch file has no touches")
    radius = float(doc.get("ball_radius_mm", 0.0))
    arrays = {key: np.array(value, dtype=float) for key, value in approaches.items()}
    if all(np.isnan(a).all() for a in arrays.values()):
        arrays = {}
    return {key: np.array(value) for key, value in touches.items()}, contacts, radius, arrays


def _check_id(feature_id, feature_ids, where):
    if feature_id not in feature_ids:
        raise ValueError(f"{where}: unknown feature {feature_id!r}; features are {', '.join(feature_ids)}")


def _check_finite(value, where):
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{where} must be numbers, got {value!r}") from None
    if array.size == 0 or not np.all(np.isfinite(array)):
        raise ValueError(f"{where} must be finite numbers, got {value!r}")
    return array


def read_touch_file(path, feature_ids):
    """(touches, contacts, ball radius, approaches) from a .csv or .json touch file."""
    try:
        with open(path, encoding="utf-8") as handle:
            text = handle.read()
    except OSError as error:
        raise ValueError(f"cannot read touch file {path}: {error.strerror}") from None
    if str(path).lower().endswith(".json"):
        return read_touch_json(text, feature_ids)
    touches, approaches, _ = read_touch_csv(text, feature_ids)
    return touches, [], 0.0, approaches


def check_enough(features, touches, contacts, ball_radius_mm):
    """Refuse a touch set with fewer constraint rows than a pose needs."""
    from .problem import Problem
    from .touches import build_groups

    rows = Problem(build_groups(features, touches, ball_radius_mm, contacts)).size
    if rows < MIN_ROWS:
        count = sum(len(v) for v in touches.values()) + len(contacts)
        raise ValueError(f"too few touches: {count} touches give {rows} constraints, a pose needs at least {MIN_ROWS}")


def format_result(result):
    """A short human-readable report of a registration result."""
    lines = [f"status: {result['status']}", f"rms residual: {result['rms_residual_mm']:.6f} mm"]
    if result["sigma_translation_mm"] is not None:
        lines.append(
            f"sigma: {result['sigma_translation_mm']:.6f} mm, {result['sigma_rotation_deg']:.6f} deg"
        )
    lines.append("fixture2meas:")
    lines.extend("  " + " ".join(f"{x:12.6f}" for x in row) for row in result["pose"])
    if len(result["solutions"]) > 1:
        lines.append(f"{len(result['solutions'])} solutions pass the residual test")
    for motion in result["free_motions"]:
        lines.append(f"free: {motion}")
    for flag in result.get("fixture_flagged", []):
        lines.append(f"fixture: {flag['feature']} departs {flag['departure_mm']:.3f} mm from the drawing "
                     f"({flag['mode']} {flag['deviation']:.4g}), beyond its tolerance")
    for flag in result["flagged"]:
        lines.append(f"flagged: touch {flag['touch']} on {flag['feature']} ({flag['residual_mm']:.4f} mm off)")
    if result["separating_touch"]:
        s = result["separating_touch"]
        lines.append(f"separating touch: {s['feature']} at {s['point_meas_mm']} (separates by {s['separation_mm']:.3f} mm)")
    return "\n".join(lines)


def main(features, register, argv=None, prog="register.py", default_sigma_mm=DEFAULT_SIGMA_MM,
         default_lever_mm=SENSOR_LEVER_MM):
    """Command line: ``register.py touches.csv [--json]``; bad input is one line, exit 2.

    The exit code tells the status: 0 unique, 3 ambiguous, 4 underdetermined,
    5 inconsistent (:data:`EXIT_CODES`).
    """
    parser = argparse.ArgumentParser(prog=prog, description="Pose of the fixture from touches.")
    parser.add_argument("touches", help="touch file: CSV feature,x,y,z (mm) or JSON")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--sigma", type=float, default=default_sigma_mm,
                        help="sensor placement noise, mm (each axis)")
    parser.add_argument("--lever", type=float, default=default_lever_mm,
                        help="sensor size, mm: plane and line sensors tilt by sigma/lever rad")
    parser.add_argument("--ball-radius", type=float, default=None, help="ball tip radius, mm")
    parser.add_argument("--fixture-tolerance", type=float, default=None,
                        help="profile tolerance zone width of the printed features, mm (default: as recorded; 0: exact)")
    args = parser.parse_args(argv)
    try:
        if not np.isfinite(args.sigma) or args.sigma <= 0:
            raise ValueError(f"--sigma must be a positive number of mm, got {args.sigma}")
        if not np.isfinite(args.lever) or args.lever <= 0:
            raise ValueError(f"--lever must be a positive number of mm, got {args.lever}")
        if args.fixture_tolerance is not None and not (0 <= args.fixture_tolerance < np.inf):
            raise ValueError(f"--fixture-tolerance must be a non-negative number of mm, got {args.fixture_tolerance}")
        touches, contacts, radius, approaches = read_touch_file(args.touches, list(features))
        if args.ball_radius is not None:
            radius = args.ball_radius
        check_enough(features, touches, contacts, radius)
        result = register(touches, sigma_mm=args.sigma, ball_radius_mm=radius, contacts=contacts,
                          approaches=approaches, lever_mm=args.lever, fixture_tolerance_mm=args.fixture_tolerance)
    except ValueError as error:
        print(f"{prog}: error: {str(error).splitlines()[0]}", file=sys.stderr)
        return 2
    try:
        print(json.dumps(result, indent=2) if args.json else format_result(result), flush=True)
    except BrokenPipeError:
        # The reader stopped (``| head``): say nothing more, and let Python's exit not complain either.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return EXIT_CODES[result["status"]]
