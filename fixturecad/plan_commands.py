"""CLI: ``fixturecad plan``: a touch plan of a point probe or a ball tip designed on the Fisher information."""

from pathlib import Path
from typing import Annotated

import typer

from fixturecad.errors import InputError
from fixturecad.registration.defaults import DEFAULT_SIGMA_MM, SENSOR_LEVER_MM

app = typer.Typer()

PLANS_DIR = "plans"
PLAN_NAME = r"[a-z0-9][a-z0-9_-]*"  # a file name in PLANS_DIR, never a path out of it
MIN_TOUCHES = 6  # point-probe and ball-tip touches give one row each; a pose needs six
MAX_TOUCHES = 60
POINT_REACH = 20.0  # a point of interest farther than this many touch spreads is not one this fixture locates


def _criterion(text):
    """(criterion, point of interest (3,) or None) of --criterion; InputError if unreadable."""
    import numpy as np

    from fixturecad.registration.planning import CRITERIA

    if text in CRITERIA:
        return text, None
    if text.startswith("point:"):
        try:
            point = np.array([float(x) for x in text[6:].split(",")])
        except ValueError:
            point = np.zeros(0)
        if point.shape == (3,) and np.all(np.isfinite(point)):
            return "point", point
    raise InputError(f"--criterion must be d, a, e or point:X,Y,Z (mm), got {text!r}")


def _sensor(text) -> float:
    """The ball radius (mm) of --sensor, 0 for a point probe; InputError if unreadable."""
    import math

    if text == "point":
        return 0.0
    if text.startswith("ball:"):
        try:
            radius = float(text[5:])
        except ValueError:
            radius = math.nan
        if 0 < radius < math.inf:
            return radius
    raise InputError(f"--sensor must be point or ball:R, R the ball's radius in mm (more than 0), got {text!r}")


@app.command()
def plan(
    out_dir: Annotated[Path, typer.Argument(help="Fixture folder written by fixturecad build or design.")],
    touches: Annotated[int, typer.Option(help=f"Number of touches ({MIN_TOUCHES} to {MAX_TOUCHES}).")],
    sensor: Annotated[str, typer.Option(help="point: a point probe; ball:R: a ball tip of radius R mm (the plan "
                                             "gives the ball's centres).")] = "point",
    criterion: Annotated[str, typer.Option(help="d: det of the information; a: trace of the covariance; e: the "
                                                "worst direction; point:X,Y,Z: the position error of that point, "
                                                "mm, fixture frame (docs/plans.md).")] = "d",
    features: Annotated[str | None, typer.Option(help="Feature ids to touch, e.g. top,front (default: every "
                                                      "plane, sphere and cylinder).")] = None,
    margin: Annotated[float | None, typer.Option(help="Distance kept from every patch edge, mm [default: 1, "
                                                      "plus the ball's radius].")] = None,
    name: Annotated[str, typer.Option(help="Plan name: written to OUT_DIR/plans/NAME.json and NAME.csv.")] = "designed",
    force: Annotated[bool, typer.Option(help="Replace a plan of that name written earlier.")] = False,
    preview: Annotated[bool, typer.Option(help="Also draw the plan on the fixture: OUT_DIR/plans/NAME.png.")] = False,
):
    """Design a touch plan: where a point probe or a ball tip should touch to locate the fixture best."""
    import json
    import re

    import numpy as np

    from fixturecad import features_json
    from fixturecad.registration import planning
    from fixturecad.registration.features import features_from_json
    from fixturecad.registration.reach import reachable
    from fixturecad.registration.sampling import read_triangles
    from fixturecad.registration.touchfile import touch_csv
    from fixturecad.staging import check_files, staged_files
    from fixturecad.theory.catalogue import lookup

    if not MIN_TOUCHES <= touches <= MAX_TOUCHES:
        raise InputError(f"--touches must be {MIN_TOUCHES} to {MAX_TOUCHES}: a pose needs six point touches")
    radius = _sensor(sensor)
    margin = planning.DEFAULT_MARGIN_MM + radius if margin is None else margin
    if not (margin >= 0 and np.isfinite(margin)):
        raise InputError(f"--margin must be a non-negative number of mm, got {margin}")
    kind, point = _criterion(criterion)
    if not re.fullmatch(PLAN_NAME, name):
        raise InputError(f"--name must be lower-case letters, digits, - and _, got {name!r}")
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise InputError(f"fixture folder {out_dir} does not exist")
    document = features_json.read(out_dir)
    all_features = features_from_json(document)
    surfaces = [fid for fid, f in all_features.items() if f.surface]
    ids = surfaces if features is None else [fid.strip() for fid in features.split(",") if fid.strip()]
    unknown = [fid for fid in ids if fid not in all_features]
    if unknown or not ids:
        raise InputError(f"unknown feature {unknown[0] if unknown else features!r}; features are {', '.join(all_features)}")
    default = default_touches(document, ids, touches) if radius == 0 else None
    try:
        triangles = read_triangles(out_dir / "fixture.stl", document["volume_mm3"])
        chord = float(document["files"]["stl_tolerance_mm"])
        points = planning.candidate_points(all_features, ids, margin, also=default,
                                           keep=lambda p, n: reachable(triangles, p, n, radius, chord))
        candidates = planning.candidates(all_features, points, radius)
        if point is not None and np.linalg.norm(point - candidates.points.mean(0)) > POINT_REACH * candidates.length_mm:
            raise ValueError(f"the point of interest {criterion[6:]} lies {POINT_REACH:g} fixture sizes away: "
                             "no touch plan on this fixture locates it (give it in the fixture frame, mm)")
        chosen = planning.design(candidates, touches, kind, point, default and planning.indices(candidates, default))
    except ValueError as error:
        raise InputError(str(error)) from None
    outputs = (f"{name}.json", f"{name}.csv") + ((f"{name}.png",) if preview else ())
    folder = check_files(out_dir / PLANS_DIR, outputs, force)
    entries = _entries(candidates, chosen, all_features)
    robust = planning.robust(candidates.rows[chosen], candidates.length_mm)
    probe = "point-probe touches" if radius == 0 else f"touches of a ball tip of radius {radius:g} mm"
    note = (f"designed by fixturecad plan: {touches} {probe}, criterion {criterion}, margin "
            f"{margin:g} mm; {'robust to' if robust else 'NOT robust to'} the loss of any one touch")
    record = {"contact_class": "".join("{" + lookup(e["contact"]).contact_class + "}" for e in entries
                                       for _ in e["points"]),
              "note": note, "ball_radius_mm": radius, "touch_plan": entries}
    with staged_files(folder, outputs) as staging:
        (staging / f"{name}.json").write_text(json.dumps(record, indent=2) + "\n")
        (staging / f"{name}.csv").write_text(touch_csv(entries, name, radius))
        if preview:
            from fixturecad.preview import plan_scene, render

            title = f"{document['template']}: plan {name!r}, {touches} touches, criterion {criterion}"
            touched = [{**e, "points": (np.array(e["points"]) + radius * np.array(e["approaches"])).tolist()}
                       for e in entries]  # drawn where the probe touches the surface
            data = plan_scene(title, triangles.reshape(-1, 3), np.arange(3 * len(triangles)).reshape(-1, 3),
                              list(all_features.values()), touched, name)
            render(data, staging / f"{name}.png")
    typer.echo(_report(document, all_features, candidates, chosen, entries, robust, touches))
    typer.echo(f"plan: {folder / f'{name}.json'}\ntouch file to fill in: {folder / f'{name}.csv'}")


def default_touches(document, ids, count):
    """The default plan's touches [(feature id, point)] when it is a point-probe plan of ``count`` touches on
    the features ``ids`` (the plan designed is then no worse than it in either bound), else None."""
    entries = document["plans"]["default"]["touch_plan"]
    touches = [(e["feature"], p) for e in entries for p in e["points"]]
    usable = all("sensor" not in e and e["contact"].startswith("P/F-") and e["feature"] in ids for e in entries)
    return touches if usable and len(touches) == count else None


def _entries(candidates, chosen, features) -> list:
    """Touch-plan entries (features.json's form), by feature, with the approach of every touch: against the
    outward normal. A ball tip's touches (``S/M``) give the ball's centres, as a touch file does."""
    ball = candidates.ball_radius_mm > 0
    entries = {}
    for k in chosen:
        fid = candidates.features[k]
        entry = entries.setdefault(fid, {"contact": f"{'S/M' if ball else 'P/F'}-{features[fid].element}/M",
                                         "feature": fid, "points": [], "approaches": []})
        entry["points"].append(candidates.centres[k].tolist())
        entry["approaches"].append((-candidates.normals[k]).tolist())
    return list(entries.values())


def _bound(problem_rows, sigma_mm=DEFAULT_SIGMA_MM):
    """(translation um, rotation mdeg) of the bound per um of noise, from rows (m, 6) at the nominal pose."""
    import numpy as np

    from fixturecad.registration.uncertainty import covariance, sigmas

    t, r = sigmas(covariance(problem_rows, np.zeros(3), sigma_mm))
    # mm per mm of noise is um per um; deg per mm is mdeg per um
    return (None, None) if t is None else (t / sigma_mm, r / sigma_mm)


def _report(document, features, candidates, chosen, entries, robust, count) -> str:
    import numpy as np

    from fixturecad.registration.problem import Problem
    from fixturecad.registration.synthetic import plan_touches
    from fixturecad.registration.touches import build_groups

    ball = candidates.ball_radius_mm > 0
    lines = [f"{'#':>2} {'feature':12s} {'ball centre mm' if ball else 'point mm':>28s} {'approach':>24s}"]
    # The entries' order, as the touch file and the preview number them.
    listed = [(e["feature"], p, n) for e in entries for p, n in zip(e["points"], e["approaches"])]
    for number, (fid, p, n) in enumerate(listed, start=1):
        lines.append(f"{number:2d} {fid:12s} ({p[0]:7.2f}, {p[1]:7.2f}, {p[2]:7.2f}) ({n[0]:6.3f}, {n[1]:6.3f}, {n[2]:6.3f})")
    planned = _bound(candidates.rows[chosen])
    default = document["plans"]["default"]["touch_plan"]
    touches, contacts = plan_touches(default, np.eye(4))
    _, J = Problem(build_groups(features, touches, 0.0, contacts), DEFAULT_SIGMA_MM, SENSOR_LEVER_MM).evaluate(
        np.eye(3), np.zeros(3))
    standard = _bound(J)
    made = sum(len(e["points"]) for e in default)
    lines.append("bound per um of touch noise: translation um, rotation mdeg")
    lines.append(f"  planned ({count} {'ball-tip ' if ball else ''}touches): {planned[0]:.3f} um, {planned[1]:.3f} mdeg")
    if standard[0] is not None:
        lines.append(f"  default plan ({made} touches): {standard[0]:.3f} um, {standard[1]:.3f} mdeg")
    lines.append("robust to the loss of any one touch" if robust else
                 "not robust: losing one of these touches leaves the pose undetermined (more touches help)")
    return "\n".join(lines)
