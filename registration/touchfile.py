"""Touch files and the command line of the generated ``register.py``.

A CSV touch file has the header ``feature,x,y,z``: one touch per row, the
feature id of features.json and the probe point (or ball centre) in mm in the
measurement frame; rows starting with ``#`` and blank rows are skipped, and a
UTF-8 byte order mark (Excel's "CSV UTF-8") is allowed. Three more columns
``ax,ay,az`` may give the direction the probe moved to make the touch; poses
at which it would have touched a surface from inside are then rejected. A
JSON touch file holds contacts of any type, in entries with the keys of the
touch plans (schema ``fixturecad/schema/touches.schema.json``, examples in
``docs/touch-files.md``)::

    {"ball_radius_mm": 0.0,
     "touches": [{"feature": "flat_a", "points": [[x, y, z], ...]},
                 {"feature": "base", "contact": "PL/F-PL/F", "points": [[x, y, z]],
                  "sensor": {"kind": "plane", "point": [...], "normal": [...]}}]}

Errors are ``ValueError`` with a one-line message. This module imports numpy
only and nothing of fixturecad: it is inlined into the generated standalone
``register.py``.
"""

import argparse
import csv
import io
import json
import os
import reprlib
import sys
import warnings

import numpy as np

from .defaults import DEFAULT_SIGMA_MM, MAX_COORDINATE_MM, SENSOR_LEVER_MM
from .contacts import ContactType
from .elements import KINDS, element
from .touches import EXTRA_SENSOR_KEYS
from .units import UNITS_MM, ball_radius_estimate, check_ball_radius, check_noise, check_spread, from_units, reach_mm

CSV_COLUMNS = ("feature", "x", "y", "z")
APPROACH_COLUMNS = ("ax", "ay", "az")
MIN_ROWS = 6  # constraint rows a rigid pose needs at the very least
# The most touches a file may hold: the search's memory grows with the touches times its cells (1,998 touches
# on the cube: 392 MB), far beyond any touch plan. A JSON file (read whole) may be at most
# MAX_JSON_BYTES.
MAX_TOUCH_ROWS = 2_000
MAX_JSON_BYTES = 10 * 10**6
# Exit code of a registration by its status; 2 is bad input, 6 a search that did not complete (:func:`exit_code`).
EXIT_CODES = {"unique": 0, "ambiguous": 3, "underdetermined": 4, "inconsistent": 5}
INCOMPLETE_EXIT = 6


def exit_code(result):
    """The status's exit code, or ``INCOMPLETE_EXIT`` when the search stopped before it was complete: its
    ``unique``, ``ambiguous`` or ``inconsistent`` is then the best found, not proven (``underdetermined``
    claims no pose, and keeps its code)."""
    if result["search"] == "incomplete" and result["status"] != "underdetermined":
        return INCOMPLETE_EXIT
    return EXIT_CODES[result["status"]]


def read_touch_csv(source, feature_ids):
    """Touches and approach directions by feature id, arrays (n, 3), and the file row (line number) of
    every touch by feature id (lists), from CSV text or an open text file; an empty feature is an
    unlabelled touch, under the id None.

    A file is read row by row: a refusal comes at the row it concerns, before the rest is read, and
    memory grows with the rows kept. At most ``MAX_TOUCH_ROWS`` touches.
    """
    reader = csv.reader(io.StringIO(source.removeprefix("\ufeff")) if isinstance(source, str) else source)
    header, count = None, 0
    touches, approaches, lines = {}, {}, {}
    try:
        for number, row in enumerate(reader, start=1):
            # Comment lines (#) and blank lines are skipped; the others keep their line number in the file.
            if not row or not any(cell.strip() for cell in row) or row[0].lstrip().startswith("#"):
                continue
            if header is None:
                header = _csv_header(row)
                continue
            values = _csv_row(row, header, feature_ids, number)
            key = row[0].strip() or None  # an empty feature: an unlabelled touch
            touches.setdefault(key, []).append(values[:3])
            approaches.setdefault(key, []).append(values[3:] or [np.nan] * 3)
            lines.setdefault(key, []).append(number)
            count += 1
            if count > MAX_TOUCH_ROWS:
                raise ValueError(f"row {number}: more than {MAX_TOUCH_ROWS:,} touches; a touch file holds at most that many")
    except csv.Error as error:  # a field over csv's limit, a NUL
        raise ValueError(f"row {reader.line_num}: {error}") from None
    if header is None:
        raise ValueError("the touch file is empty")
    if not touches:
        raise ValueError("the touch file has a header but no touches")
    arrays = {key: np.array(value) for key, value in approaches.items()}
    return {key: np.array(value) for key, value in touches.items()}, (arrays if len(header) == 7 else {}), lines


def _csv_header(row):
    header = tuple(cell.strip().lower() for cell in row)
    if header not in (CSV_COLUMNS, CSV_COLUMNS + APPROACH_COLUMNS):
        raise ValueError(
            f"touch CSV must have the columns {','.join(CSV_COLUMNS)} (and optionally "
            f"{','.join(APPROACH_COLUMNS)}), got {','.join(header)}"
        )
    return header


def _csv_row(row, header, feature_ids, line):
    """A touch row's numbers: x, y, z and, with the approach columns, ax, ay, az (not all zero)."""
    if len(row) != len(header):
        raise ValueError(f"row {line}: expected {len(header)} values ({','.join(header)}), got {len(row)}")
    if row[0].strip():
        _check_id(row[0].strip(), feature_ids, f"row {line}")
    try:
        values = [float(cell) for cell in row[1:]]
    except ValueError:
        raise ValueError(f"row {line}: coordinates must be numbers, got {','.join(row[1:])}") from None
    if not np.all(np.isfinite(values)):
        raise ValueError(f"row {line}: coordinates must be finite, got {','.join(row[1:])}")
    _check_range(np.array(values), f"row {line}")
    if len(header) == 7 and not any(values[3:]):
        raise ValueError(f"row {line}: the approach direction ax,ay,az is zero: give the direction the probe moved")
    return values


def touch_csv(entries, plan_name, ball_radius_mm=0.0):
    """A touch CSV a user fills in: a plan's nominal probe points (a ball tip's centres when
    ``ball_radius_mm`` > 0), fixture frame, mm, with how to."""
    what = f"ball centres (--ball-radius {ball_radius_mm:g})" if ball_radius_mm > 0 else "points"
    lines = [f"# Touch plan {plan_name!r}: the nominal {what} in the fixture frame, mm. Replace each x,y,z",
             "# by the one the probe measured on that feature (measurement frame), keep the feature ids;",
             "# add or remove rows as you touch. Lines starting with # are skipped.",
             ",".join(CSV_COLUMNS)]
    for entry in entries:
        for x, y, z in np.asarray(entry["points"], float).reshape(-1, 3):
            lines.append(f"{entry['feature']},{x:.4f},{y:.4f},{z:.4f}")
    return "\n".join(lines) + "\n"


def read_touch_json(text, features):
    """Point touches by feature id, the other contacts, the ball radius, approaches and the touch
    labels (``touch K``, in the engine's touch order), from JSON text.

    Entries have the keys of the touch plans (``fixturecad/schema/touches.schema.json``):
    ``feature``, optional ``contact``, ``points`` (mm, measurement frame; one touch
    each), optional ``approaches`` (one per point), and for a sensor other than a
    point probe its ``sensor`` (one touch, ``points`` its contact point if known),
    optional ``rho`` and ``fixture``.
    """
    if not text.strip():
        raise ValueError("the touch file is empty")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"touch JSON is not valid JSON: {error.msg} at line {error.lineno}") from None
    except RecursionError:
        raise ValueError("touch JSON is nested too deeply: a touch file is an object of flat lists") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("touches"), list):
        raise ValueError('touch JSON must be an object with a "touches" list')
    unknown = set(doc) - {"ball_radius_mm", "touches"}
    if unknown:
        raise ValueError(f"touch JSON: unknown key {sorted(unknown)[0]!r}; keys are ball_radius_mm, touches")
    radius = ball_radius(doc.get("ball_radius_mm", 0.0), "ball_radius_mm")
    touches, contacts, approaches, labels = {}, [], {}, {}
    contact_labels = []
    for k, entry in enumerate(doc["touches"], start=1):
        where = f"touch {k}"
        if not isinstance(entry, dict):
            raise ValueError(f"{where}: expected an object with feature and points")
        unknown = set(entry) - ENTRY_KEYS
        if unknown:
            hint = ' (a list of points is "points": [[x, y, z], ...], as in the touch plans)' if "point" in unknown else ""
            raise ValueError(f"{where}: unknown key {sorted(unknown)[0]!r}{hint}; keys are {', '.join(sorted(ENTRY_KEYS))}")
        if entry.get("feature", "") is None:
            if {"contact", "sensor", "rho", "fixture"} & set(entry):
                raise ValueError(f"{where}: an unlabelled touch (feature null) is the probe's: no contact, sensor, "
                                 f"rho or fixture")
        else:
            _check_id(entry.get("feature"), features, where)
            _check_contact(entry, features[entry["feature"]], radius, where)
        points = _points(entry, "points", where, required="sensor" not in entry)
        if "rho" in entry:
            _json_array(entry["rho"], (), f"{where}: rho")
        if "fixture" in entry:
            _fixture_point(entry["fixture"], where)
        if "sensor" in entry:
            if "contact" not in entry:
                raise ValueError(f"{where}: a sensor entry needs its contact, e.g. \"PL/F-PL/F\"")
            if "approaches" in entry:
                raise ValueError(f"{where}: a sensor entry has no approaches (they are the probe's, one per point)")
            if len(points) > 1:
                raise ValueError(f"{where}: a sensor makes one touch: give at most one contact point")
            contacts.append(_sensor_contact(entry, points, where))
            contact_labels.append(where)
            continue
        if "approaches" in entry:
            approach = _points(entry, "approaches", where)
            if len(approach) != len(points):
                raise ValueError(f"{where}: {len(points)} points but {len(approach)} approaches")
            if not np.all(np.linalg.norm(approach, axis=1) > 0):
                raise ValueError(f"{where}: an approach is [0, 0, 0]: give the direction the probe moved")
        else:
            approach = np.full((len(points), 3), np.nan)
        touches.setdefault(entry["feature"], []).extend(points)
        approaches.setdefault(entry["feature"], []).extend(approach)
        labels.setdefault(entry["feature"], []).extend([where] * len(points))
    if not touches and not contacts:
        raise ValueError("the touch file has no touches")
    if sum(map(len, touches.values())) + len(contacts) > MAX_TOUCH_ROWS:
        raise ValueError(f"more than {MAX_TOUCH_ROWS:,} touches; a touch file holds at most that many")
    arrays = {key: np.array(value, dtype=float) for key, value in approaches.items()}
    if all(np.isnan(a).all() for a in arrays.values()):
        arrays = {}
    # The engine's order: labelled point touches by feature, the contacts, the unlabelled touches.
    rows = [label for key in touches if key is not None for label in labels[key]] + contact_labels \
        + labels.get(None, [])
    return {key: np.array(value) for key, value in touches.items()}, contacts, radius, arrays, rows


ENTRY_KEYS = {"feature", "contact", "points", "approaches", "sensor", "rho", "fixture"}


def _check_contact(entry, feature, radius, where):
    """An entry's contact, when given, is a contact type on the feature's element and, without a
    sensor, the probe's own: a point (P/F) or, with a ball radius, a ball (S/M)."""
    if "contact" not in entry:
        return
    if not isinstance(entry["contact"], str):
        raise ValueError(f"{where}: contact must be a string such as \"P/F-PL/M\", got {entry['contact']!r}")
    try:
        ctype = ContactType.parse(entry["contact"])
    except ValueError as error:
        raise ValueError(f"{where}: {error}") from None
    if ctype.fixture != feature.element:
        raise ValueError(f"{where}: contact {entry['contact']} touches a {element(ctype.fixture).kind} but "
                         f"{feature.id} is a {feature.kind}")
    sensor = entry.get("sensor")
    if isinstance(sensor, dict) and sensor.get("kind") in KINDS and element(sensor["kind"]).letter != ctype.sensor:
        raise ValueError(f"{where}: contact {entry['contact']} has a {element(ctype.sensor).kind} sensor, "
                         f"not a {sensor['kind']}")
    probe = ("S", False) if radius > 0 else ("P", True)
    if sensor is None and (ctype.sensor, ctype.sensor_fixed) != probe:
        raise ValueError(f"{where}: touches without a sensor are made by the probe's "
                         f"{'ball (S/M)' if radius > 0 else 'point (P/F)'}, not {entry['contact']}")


def _points(entry, key, where, required=True):
    """An entry's list of [x, y, z] (n, 3), finite numbers."""
    if key not in entry:
        if required:
            raise ValueError(f"{where}: needs \"{key}\": [[x, y, z], ...] in mm")
        return np.zeros((0, 3))
    array = _json_array(entry[key], (None, 3), f"{where}: {key}")
    _check_range(array, f"{where}: {key}")
    return array


def _fixture_point(fixture, where):
    """The known contact point of a fixed fixture side, ``{"o": [x, y, z]}`` (fixture frame, mm)."""
    if not isinstance(fixture, dict) or set(fixture) - {"o"}:
        raise ValueError(f"{where}: fixture must be an object such as {{\"o\": [x, y, z]}}, got {reprlib.repr(fixture)}")
    return {key: _json_array(value, (3,), f"{where}: fixture {key}").tolist() for key, value in fixture.items()}


def _sensor_contact(entry, points, where):
    """The engine's contact of a sensor entry."""
    sensor = entry["sensor"]
    if not isinstance(sensor, dict) or sensor.get("kind") not in KINDS:
        raise ValueError(f"{where}: sensor must be an object with a kind ({', '.join(KINDS)}) and its geometry")
    keys = element(sensor["kind"]).json_keys
    optional = tuple(EXTRA_SENSOR_KEYS.get(sensor["kind"], ()))
    if not {"kind", *keys} <= set(sensor) <= {"kind", *keys, *optional}:
        raise ValueError(f"{where}: a {sensor['kind']} sensor has the keys kind, {', '.join(keys)}"
                         + "".join(f" (and optionally {key})" for key in optional))
    for key, value in sensor.items():
        if key != "kind":
            array = _json_array(value, () if key == "radius" else (3,), f"{where}: sensor {key}")
            _check_range(array, f"{where}: sensor {key}")
            if array.ndim == 0 and array < 0:
                raise ValueError(f"{where}: sensor {key} must be a number of mm >= 0, got {value!r}")
    contact = {"feature": entry["feature"], "contact": entry["contact"], "sensor": sensor}
    if len(points):
        contact["point"] = points[0].tolist()
    if "rho" in entry:
        contact["rho"] = float(entry["rho"])
    if "fixture" in entry:
        contact["fixture"] = _fixture_point(entry["fixture"], where)
    ctype = ContactType.parse(entry["contact"])
    # A fixed fixture side is a known point of the feature: a point feature is its own, and a plane on a
    # plane touches along a face, where no point is needed.
    if (ctype.fixture_fixed and ctype.fixture != "P" and {ctype.sensor, ctype.fixture} != {"PL"}
            and "o" not in contact.get("fixture", {})):
        raise ValueError(f"{where}: contact {entry['contact']} fixes the fixture side: give its contact point, "
                         '"fixture": {"o": [x, y, z]} (fixture frame, mm)')
    return contact


def touch_json(touches, contacts=(), ball_radius_mm=0.0):
    """A JSON touch file's text from touches by feature id and the engine's contacts (the reader's inverse)."""
    entries = [{"feature": key, "points": np.asarray(value, float).reshape(-1, 3).tolist()}
               for key, value in touches.items()]
    for contact in contacts:
        entry = {"feature": contact["feature"], "contact": contact["contact"], "sensor": contact["sensor"]}
        if "point" in contact:
            entry["points"] = [list(contact["point"])]
        entry.update({key: contact[key] for key in ("rho", "fixture") if key in contact})
        entries.append(entry)
    # One entry a line, numbers exact (read back bit for bit): a file a user reads and edits.
    lines = [json.dumps(entry) for entry in entries]
    return (f'{{"ball_radius_mm": {float(ball_radius_mm)!r},\n "touches": [\n  '
            + ",\n  ".join(lines) + "\n ]\n}\n")


def ball_radius(value, where):
    """A ball tip radius (mm): a finite number >= 0."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < np.inf:
        raise ValueError(f"{where} must be a number of mm >= 0, got {value!r}")
    return float(value)


def _check_range(array, where):
    if np.abs(array).max(initial=0.0) > MAX_COORDINATE_MM:
        raise ValueError(f"{where}: coordinates beyond {MAX_COORDINATE_MM:g} mm, got {np.abs(array).max():g}")


def _check_id(feature_id, feature_ids, where):
    if not isinstance(feature_id, str) or feature_id not in feature_ids:
        raise ValueError(f"{where}: unknown feature {feature_id!r}; features are {', '.join(feature_ids)}")


# The numbers of touches.schema.json, by the shape of their lists (None: any length but 0).
_SHAPES = {(): "a number", (3,): "[x, y, z]", (None, 3): "a list of [x, y, z]"}


def _json_array(value, shape, where):
    """``value`` as touches.schema.json has it, an array: JSON numbers (not strings or booleans) in lists
    of ``shape``, finite."""
    if not _fits(value, shape):
        raise ValueError(f"{where} must be {_SHAPES[shape]}, got {reprlib.repr(value)}")
    try:
        array = np.array(value, dtype=float)
    except OverflowError:  # an integer of hundreds of digits
        array = np.array(np.inf)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{where} must be finite numbers, got {reprlib.repr(value)}")
    return array


def _fits(value, shape):
    if not shape:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return (isinstance(value, list) and 0 < len(value) == (shape[0] or len(value))
            and all(_fits(item, shape[1:]) for item in value))


def read_touch_file(path, features, units="mm"):
    """(touches, contacts, ball radius, approaches, rows) from a .csv or .json touch file, for
    ``features`` (dict id -> feature), its lengths in ``units`` (:data:`.units.UNITS_MM`) made mm.

    ``rows`` names every touch in the engine's order (point touches by feature,
    then the contacts) by where it is in the file: ``row 8 of touches.csv``.
    """
    touches, contacts, radius, approaches, rows = _read_touch_file(path, features)
    if units == "mm":
        return touches, contacts, radius, approaches, rows
    return ({key: from_units(value, units) for key, value in touches.items()},
            [_contact_from_units(contact, units) for contact in contacts], radius, approaches, rows)


def _contact_from_units(contact, units):
    """A sensor contact with its lengths (its points and radius, not its directions) in mm."""
    converted = {**contact, "sensor": {key: value if key in ("kind", "normal", "direction", "axis")
                                       else from_units(value, units).tolist() for key, value in contact["sensor"].items()}}
    if "point" in contact:
        converted["point"] = from_units(contact["point"], units).tolist()
    if "fixture" in contact:
        converted["fixture"] = {"o": from_units(contact["fixture"]["o"], units).tolist()}
    return converted


def _read_touch_file(path, features):
    name = os.path.basename(path)
    try:
        if str(path).lower().endswith(".json"):
            if os.path.getsize(path) > MAX_JSON_BYTES:
                raise ValueError(f"touch file {path} is over {MAX_JSON_BYTES // 10**6} MB: a JSON touch file holds "
                                 f"at most {MAX_TOUCH_ROWS:,} touches (a CSV is read row by row)")
            with open(path, encoding="utf-8") as handle:
                text = handle.read()
            touches, contacts, radius, approaches, labels = read_touch_json(text, features)
            return touches, contacts, radius, approaches, [f"{label} of {name}" for label in labels]
        with open(path, encoding="utf-8-sig", newline="") as handle:  # -sig: Excel's byte order mark
            touches, approaches, lines = read_touch_csv(handle, features)
    except OSError as error:
        raise ValueError(f"cannot read touch file {path}: {error.strerror}") from None
    except UnicodeDecodeError:
        raise ValueError(f"touch file {path} is not UTF-8 text") from None
    order = [key for key in touches if key is not None] + [None] * (None in touches)
    return touches, [], 0.0, approaches, [f"row {line} of {name}" for key in order for line in lines[key]]


def check_enough(features, touches, contacts, ball_radius_mm):
    """Refuse a touch set with fewer constraint rows than a pose needs."""
    from .problem import Problem
    from .touches import build_groups

    labelled = {key: value for key, value in touches.items() if key is not None}
    # An unlabelled touch lies on a surface: one row.
    rows = Problem(build_groups(features, labelled, ball_radius_mm, contacts)).size + len(touches.get(None, ()))
    if rows < MIN_ROWS:
        count = sum(len(v) for v in touches.values()) + len(contacts)
        raise ValueError(f"too few touches: {count} touches give {rows} constraints, a pose needs at least {MIN_ROWS}")


def register_file(features, register, path, sigma_mm=DEFAULT_SIGMA_MM, lever_mm=SENSOR_LEVER_MM,
                  ball_radius_mm=None, fixture_tolerance_mm=None, target_sigma=None, units=None, size=(None, None),
                  unlabelled=False, anywhere=False):
    """Check the options, read a touch file and register it; the result names every touch's row
    (``rows``, in the engine's touch order) and each flagged touch's.

    ``ball_radius_mm`` None: as the file says (a CSV: 0). ``target_sigma`` (mm, deg) or None. ``units``: the
    file's lengths (mm, m, in; None: mm, and the spread is checked for another unit). ``size``: the fixture's reachable touches by feature id and its volume
    (mm^3), either None, to tell touches in another unit (:mod:`.units`). The result has ``next_touch``
    (see ``register_touches``). Errors are one-line ``ValueError``: touches whose spread says they are in
    another unit, or ball centres registered as points. ``unlabelled``: take every point touch as
    unlabelled, its feature not said; ``anywhere``: the unlabelled touches lie anywhere on the part, not only on
    its sensing features (``register`` takes ``anywhere=True``).
    """
    if not 0 < sigma_mm < np.inf:
        raise ValueError(f"--sigma must be a positive number of mm, got {sigma_mm}")
    check_noise(sigma_mm, "--sigma")
    if not 0 < lever_mm < np.inf:
        raise ValueError(f"--lever must be a positive number of mm, got {lever_mm}")
    if fixture_tolerance_mm is not None and not 0 <= fixture_tolerance_mm < np.inf:
        raise ValueError(f"--fixture-tolerance must be a non-negative number of mm, got {fixture_tolerance_mm}")
    if ball_radius_mm is not None:
        ball_radius(ball_radius_mm, "--ball-radius")
    if target_sigma is not None and not all(x is None or 0 < x < np.inf for x in target_sigma):
        raise ValueError(f"--target-sigma and --target-sigma-deg must be positive numbers, got {target_sigma}")
    if units is not None and units not in UNITS_MM:
        raise ValueError(f"--units must be one of {', '.join(UNITS_MM)}, got {units!r}")
    touches, contacts, radius, approaches, rows = read_touch_file(path, features, units or "mm")
    radius = radius if ball_radius_mm is None else ball_radius_mm
    if unlabelled and touches:
        # Every point touch unlabelled, in the file's order of them; the contacts now come first.
        labelled = sum(len(v) for key, v in touches.items() if key is not None)
        rows = rows[labelled:labelled + len(contacts)] + rows[:labelled] + rows[labelled + len(contacts):]
        touches = {None: np.concatenate([v for key, v in touches.items() if key is not None]
                                        + ([touches[None]] if None in touches else []))}
        approaches = {}
    if anywhere and None not in touches:
        raise ValueError("--anywhere places unlabelled touches: the file has none (an empty feature, null in JSON, "
                         "or --unlabelled)")
    check_enough(features, touches, contacts, radius)
    points = [*touches.values(), *(np.reshape(c["point"], (1, 3)) for c in contacts if "point" in c)]
    # An unlabelled touch may lie on any surface: its spread is compared with all of them.
    surfaces = [f.id for f in features.values() if f.surface] if None in touches else []
    touched = [*(key for key in touches if key is not None), *surfaces, *(c["feature"] for c in contacts)]
    free = touches.pop(None, None)
    approaches.pop(None, None)
    if points and units is None:  # units given: the user has said
        check_spread(np.concatenate(points), touched, *size)
    check_ball_radius(radius, reach_mm(touched, *size))
    options = dict(sigma_mm=sigma_mm, contacts=contacts, approaches=approaches, lever_mm=lever_mm,
                   fixture_tolerance_mm=fixture_tolerance_mm)
    if free is not None:
        options["unlabelled"] = free
    if anywhere:
        options["anywhere"] = True
    result = register(touches, ball_radius_mm=radius, plan_next=True, target_sigma=target_sigma, **options)
    if radius == 0 and not contacts and free is None:
        _check_not_ball_centres(features, register, touches, result, options)
    result["touch_rows"] = rows
    labelled = sum(len(v) for v in touches.values()) + len(contacts)
    result["repeated_rows"] = repeated_rows(touches, rows) + (
        [] if free is None else repeated_rows({None: free}, rows[labelled:]))
    for flag in result["flagged"]:
        flag["row"] = rows[flag["touch"]]
    return result


def repeated_rows(touches, rows):
    """[[row, the earlier row it repeats], ...]: point touches given twice (same feature, same point), which
    check nothing but look as if they did. ``rows`` names the touches in the engine's order."""
    repeats, start = [], 0
    for points in touches.values():
        _, first, inverse = np.unique(np.asarray(points), axis=0, return_index=True, return_inverse=True)
        earlier = first[np.reshape(inverse, -1)]
        repeats += [[rows[start + k], rows[start + e]] for k, e in enumerate(earlier) if e != k]
        start += len(points)
    return repeats


def repeated_warning(result):
    """The one warning line of a result whose touch file repeats rows, or None."""
    repeats = result.get("repeated_rows")
    if not repeats:
        return None
    more = f" (and {len(repeats) - 1} more)" if len(repeats) > 1 else ""
    return (f"warning: {repeats[0][0]} repeats {repeats[0][1]}{more}: a repeated touch checks nothing; "
            "touch again elsewhere")


# The ball tips looked for: a common offset below the least may be the print, above the most (a 50 mm
# stylus ball) it is no tip.
MIN_BALL_RADIUS_MM, MAX_BALL_RADIUS_MM = 0.1, 25.0


def _check_not_ball_centres(features, register, touches, result, options):
    """Refuse point touches that only fit as a ball tip's centres: registered as points they do not (not
    unique, or a printed feature blamed), at the common offset they are all outside their surfaces they do."""
    if result["status"] == "unique" and not result["fixture_flagged"]:
        return
    poses = [result["pose"], *(s["pose"] for s in result["solutions"]), *(f["pose"] for f in result["flagged"])]
    try:
        radius = round(ball_radius_estimate(features, touches, [p for p in poses if p is not None][:1]), 3)
        if not MIN_BALL_RADIUS_MM <= radius <= MAX_BALL_RADIUS_MM:
            return
        as_ball = register(touches, ball_radius_mm=radius, **options)
    except np.linalg.LinAlgError:  # touches far from any common offset
        return
    if as_ball["status"] == "unique" and not as_ball["fixture_flagged"]:
        raise ValueError(f"every touch lies {radius:g} mm outside its surface, as a ball tip's centres do: "
                         f"give the tip's radius, --ball-radius {radius:g}")


SEARCH_WORDS = {
    "complete": "search: complete (every pose the touches admit was looked for{extent})",
    "nominal": "search: nominal (the pose near the nominal pose given; other poses may fit)",
    "local": "search: local (the closed-form starts only; other poses may fit)",
    "incomplete": "search: incomplete, {reason}: not proven (exit 6)",
}


def search_line(result):
    """The report's line on how the poses were looked for."""
    extent = result.get("search_extent_mm")
    extent = "" if not extent else f"; any other pose that passes moves a touch by at most {extent:.3g} mm"
    return SEARCH_WORDS[result["search"]].format(extent=extent, reason=result.get("search_reason", ""))


def format_result(result, pose_format="matrix"):
    """A short human-readable report of a registration result, the pose in a controller's convention
    (``pose_format`` None: without the pose)."""
    from .controllers import format_pose

    lines = [f"status: {result['status']}", search_line(result),
             f"rms residual: {result['rms_residual_mm']:.6f} mm"]
    if result["sigma_translation_mm"] is not None:
        lines.append(
            f"sigma: {result['sigma_translation_mm']:.6f} mm, {result['sigma_rotation_deg']:.6f} deg"
        )
    rows = result.get("touch_rows")
    if result["pose"] is not None:
        if pose_format is not None:
            lines.append(format_pose(pose_format, result["pose"], result["covariance"]))
    elif result["flagged"]:
        lines.append("pose: none (several touches could each explain the inconsistency: see flagged)")
    else:
        lines.append("pose: none (no single touch, label or printed feature explains the inconsistency)")
    for touch in result.get("assignment", []):
        where = rows[touch["touch"]] if rows else f"touch {touch['touch']}"
        on = touch["feature"] + (f" ({', '.join(touch['holds'])})" if touch.get("holds") else "")
        lines.append(f"assigned: {where} on {on} ({touch['residual_mm']:+.4f} mm)")
    if len(result["solutions"]) > 1:
        lines.append(f"{len(result['solutions'])} solutions pass the residual test")
    for motion in result["free_motions"]:
        lines.append(f"free: {motion}")
    for flag in result.get("fixture_flagged", []):
        lines.append(f"fixture: {flag['feature']} departs {flag['departure_mm']:.3f} mm from the drawing "
                     f"({flag['mode']} {flag['deviation']:.4g}), beyond its tolerance")
    for flag in result["flagged"]:
        where = flag.get("row", f"touch {flag['touch']}")
        fix = f"it fits on {flag['relabel']}" if flag["relabel"] else "the others fit without it"
        lines.append(f"flagged: {where} on {flag['feature']} ({flag['residual_mm']:.4f} mm off): {fix}")
    if result["culprit"] is not None:
        lines.append(f"culprit: {rows[result['culprit']] if rows else 'touch %d' % result['culprit']}")
    elif result["flagged"]:
        lines.append(f"{len({f['touch'] for f in result['flagged']})} touches could each explain it: "
                     "which one is wrong cannot be told (touch again)")
    if result["inadmissible"]:
        named = [rows[i] if rows else f"touch {i}" for i in result["inadmissible"]]
        lines.append("off its patch or touched from inside at this pose: " + ", ".join(named))
    lines.extend(_checked_lines(result, rows))
    if result["separating_touch"]:
        s = result["separating_touch"]
        lines.append(f"separating touch: {s['feature']} at {s['point_meas_mm']} (separates by {s['separation_mm']:.3f} mm)")
    elif result["status"] == "ambiguous":
        lines.append("separating touch: none on the patches tells these poses apart")
    if not result["separating_touch"] and result.get("next_touch"):
        n = result["next_touch"]
        point = ", ".join(f"{round(x, 3) + 0.0:.3f}" for x in n["point_meas_mm"])
        approach = ", ".join(f"{round(x, 3) + 0.0:.3f}" for x in n["approach_meas"])
        lines.append(f"next touch: {n['feature']} at ({point}) mm, approaching along ({approach})")
    if result.get("target"):
        t = result["target"]
        goal = ", ".join(f"{v:g} {unit}" for v, unit in ((t["sigma_translation_mm"], "mm"), (t["sigma_rotation_deg"], "deg"))
                         if v is not None)
        lines.append(f"target {goal}: met" if t["met"] else
                     f"target {goal}: not met; {t['more_touches']} more planned touches are predicted to meet it"
                     if t["more_touches"] else f"target {goal}: not met, nor within 30 more planned touches")
    return "\n".join(lines)


def _checked_lines(result, rows):
    """How well the touches check each other, in words (see :mod:`.redundancy`)."""
    check = result.get("redundancy")
    if not check or result["status"] == "underdetermined":
        return []
    named = [rows[i] if rows else f"touch {i}" for i in check["unchecked"]]
    if check["rows_beyond_six"] == 0:
        return ["checked: none (no rows beyond the six a pose needs): a wrong touch would go unnoticed"]
    found = [d for d in check["detectable_mm"] if d is not None]
    extra = check["rows_beyond_six"]
    line = f"checked: {extra} row{'s' if extra > 1 else ''} beyond the six a pose needs"
    if found:
        line += f"; an error of {max(found):.3f} mm in any checked touch is found"
    lines = [line]
    if named:
        lines.append("not checked by the others (a wrong one would go unnoticed): " + ", ".join(named))
    return lines


def main(features, register, argv=None, prog="register.py", default_sigma_mm=DEFAULT_SIGMA_MM,
         default_lever_mm=SENSOR_LEVER_MM, size=(None, None)):
    """Command line: ``register.py touches.csv [--json] [--format NAME]``; bad input is one line, exit 2.
    ``size``: the fixture's reachable touches and volume (see :func:`register_file`).

    The exit code tells the status: 0 unique, 3 ambiguous, 4 underdetermined,
    5 inconsistent (:data:`EXIT_CODES`), 6 a search that did not complete (:func:`exit_code`).
    """
    from .controllers import FORMATS

    parser = argparse.ArgumentParser(prog=prog, description="Pose of the fixture from touches.")
    parser.add_argument("touches", help="touch file: CSV feature,x,y,z (mm) or JSON")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--format", choices=FORMATS, default="matrix",
                        help="the pose in a robot controller's convention and units (see docs/robot-frames.md)")
    parser.add_argument("--sigma", type=float, default=default_sigma_mm,
                        help="sensor placement noise, mm (each axis)")
    parser.add_argument("--lever", type=float, default=default_lever_mm,
                        help="sensor size, mm: plane and line sensors tilt by sigma/lever rad")
    parser.add_argument("--ball-radius", type=float, default=None, help="ball tip radius, mm")
    parser.add_argument("--units", choices=UNITS_MM, default=None,
                        help="the touch file's lengths (default mm, and a file that looks like another unit is refused)")
    parser.add_argument("--fixture-tolerance", type=float, default=None,
                        help="profile tolerance zone width of the printed features, mm (default: as recorded; 0: exact)")
    parser.add_argument("--target-sigma", type=float, default=None,
                        help="accuracy wanted: RMS translation standard deviation, mm")
    parser.add_argument("--target-sigma-deg", type=float, default=None,
                        help="accuracy wanted: RMS rotation standard deviation, deg")
    parser.add_argument("--unlabelled", action="store_true",
                        help="take every point touch as unlabelled: on some plane, sphere or cylinder, not said which")
    parser.add_argument("--anywhere", action="store_true",
                        help="the unlabelled touches lie anywhere on the part, not only on its sensing features")
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a user sees the result and one-line errors, never Python warnings
            result = register_file(features, register, args.touches, args.sigma, args.lever, args.ball_radius,
                                   args.fixture_tolerance, target(args.target_sigma, args.target_sigma_deg),
                                   args.units, size, args.unlabelled, args.anywhere)
    except ValueError as error:
        print(f"{prog}: error: {str(error).splitlines()[0]}", file=sys.stderr)
        return 2
    if repeated_warning(result):
        print(f"{prog}: {repeated_warning(result)}", file=sys.stderr)
    try:
        print(report(result, args.format, args.json), flush=True)
    except BrokenPipeError:
        # The reader stopped (``| head``): say nothing more, and let Python's exit not complain either.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return exit_code(result)


def target(sigma_mm, sigma_deg):
    """The accuracy target (mm, deg) of --target-sigma and --target-sigma-deg; None when neither is given
    (one alone leaves the other free: None)."""
    return None if sigma_mm is None and sigma_deg is None else (sigma_mm, sigma_deg)


def report(result, pose_format="matrix", as_json=False):
    """What the command line prints: the JSON result (with the pose in ``pose_format`` under
    ``controller``: its numbers, their sigmas and the text) or the human-readable report; with the
    pose format ``json`` that is JSON too, the pose's object with ``status`` and the report's other
    lines (``report``) in it, so that stdout parses."""
    if not as_json:
        if pose_format != "json":
            return format_result(result, pose_format)
        from .controllers import format_pose, json_lines

        document = {"status": result["status"], "report": format_result(result, None).splitlines()}
        if result["pose"] is not None:
            document.update(json.loads(format_pose("json", result["pose"], result["covariance"])))
        return json_lines(document)
    from .controllers import format_pose, sigmas_from_covariance, values_from_pose

    if result["pose"] is None:
        return json.dumps(dict(result, controller=None), indent=2)
    covariance = result["covariance"]
    # A gimbal lock leaves an Euler angle without a first-order sigma: null in JSON.
    sigmas = None if covariance is None else [
        float(x) if np.isfinite(x) else None for x in sigmas_from_covariance(pose_format, result["pose"], covariance)]
    result = dict(result, controller={
        "format": pose_format,
        "values": values_from_pose(pose_format, result["pose"]).tolist(),
        "sigmas": sigmas,
        "text": format_pose(pose_format, result["pose"], covariance),
    })
    return json.dumps(result, indent=2)
