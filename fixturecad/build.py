"""``fixturecad build``: one template instance to fixture.step, fixture.stl, features.json, preview.png.

Everything is written into a temporary folder beside the target and moved into
place only when complete (:mod:`fixturecad.staging`), so a failed or
interrupted build leaves nothing behind and an existing folder is replaced
only with ``force``, only if fixturecad wrote it.
"""

import math
from pathlib import Path
from typing import TYPE_CHECKING

from fixturecad import features_json
from fixturecad.errors import InputError
from fixturecad.registration.defaults import DEFAULT_ZONE_MM
from fixturecad.staging import staged_folder

if TYPE_CHECKING:
    from fixturecad.templates.base import Template

FILES = {"step": "fixture.step", "stl": "fixture.stl", "3mf": "fixture.3mf", "features": "features.json",
         "preview": "preview.png", "register": "register.py", "touches": "touches.template.csv",
         "touches_json": "touches.template.json"}
# Relative agreement required between the BREP volume and the analytic one.
VOLUME_RELATIVE_TOLERANCE = 1e-6
# Chord tolerance of the STL tessellation unless asked otherwise, and the accepted range, mm.
DEFAULT_STL_TOLERANCE_MM = 0.01
STL_TOLERANCE_RANGE_MM = (1e-4, 1.0)
FIXTURE_TOLERANCE_LIMIT_MM = 2.0  # the widest zone accepted: a print that bad is no fixture
# Chord tolerance of the preview tessellation, as a fraction of the fixture size.
PREVIEW_CHORD_FRACTION = 0.004


def check_stl_tolerance(value: float) -> float:
    low, high = STL_TOLERANCE_RANGE_MM
    if not (math.isfinite(value) and low <= value <= high):
        raise InputError(f"--stl-tolerance must be between {low:g} and {high:g} mm, got {value!r}")
    return value


def check_fixture_tolerance(value: float) -> float:
    if not (math.isfinite(value) and 0.0 <= value <= FIXTURE_TOLERANCE_LIMIT_MM):
        raise InputError(f"--fixture-tolerance must be between 0 and {FIXTURE_TOLERANCE_LIMIT_MM:g} mm, got {value!r}")
    return value


def features_document(template: "Template", stl_tolerance: float = DEFAULT_STL_TOLERANCE_MM,
                      fixture_tolerance: float = DEFAULT_ZONE_MM, touch_candidates=None, faces=None) -> dict:
    """The features.json of a build of ``template`` (no CAD needed; the build adds its ``touch_candidates`` and
    ``faces``)."""
    files = {"step": FILES["step"], "stl": FILES["stl"], "3mf": FILES["3mf"], "stl_tolerance_mm": stl_tolerance,
             "preview": FILES["preview"]}
    return features_json.document(template, files, fixture_tolerance, touch_candidates, faces)


def touch_template(template: "Template") -> str:
    """touches.template.csv: the default plan's point touches when they locate the part and each is checked by
    the others (all of the default plan, or what a point probe makes of it), else the first plan that a point
    probe alone makes."""
    from fixturecad.registration.touchfile import touch_csv

    plans = template.touch_plans()
    points = [e for e in plans["default"].touches if "sensor" not in e]
    if points and all_checked(template.features(), points):
        return touch_csv(points, "default" if len(points) == len(plans["default"].touches) else "default, point touches")
    name = next(n for n in sorted(plans) if all("sensor" not in e for e in plans[n].touches))
    return touch_csv(plans[name].touches, name)


def all_checked(features, entries) -> bool:
    """Whether point-touch plan ``entries`` (fixture frame) locate the part with every touch checked by the
    others (a redundancy number above zero: an error in it shows in the residuals)."""
    import numpy as np

    from fixturecad.registration.problem import Problem
    from fixturecad.registration.redundancy import redundancy
    from fixturecad.registration.touches import build_groups
    from fixturecad.registration.verdict import Solution

    touches = {}
    for entry in entries:
        touches.setdefault(entry["feature"], []).extend(np.reshape(entry["points"], (-1, 3)).tolist())
    problem = Problem(build_groups({f.id: f for f in features}, touches))
    r, J = problem.evaluate(np.eye(3), np.zeros(3))
    rank = int(np.linalg.matrix_rank(J))
    return rank == 6 and not redundancy(problem, Solution(np.eye(3), np.zeros(3), r, J, rank))["unchecked"]


def touch_template_json(template: "Template") -> str:
    """touches.template.json: the default plan's touches, sensors included, at their nominal places."""
    import numpy as np

    from fixturecad.registration.synthetic import plan_touches
    from fixturecad.registration.touchfile import touch_json

    return touch_json(*plan_touches(template.touch_plans()["default"].touches, np.eye(4)))


def touch_candidates(features, triangles) -> dict:
    """features.json's ``touch_candidates``: the point-probe touches the planner would consider by default
    (every surface feature, the default margin) that a probe reaches on the mesh ``triangles`` (m, 3, 3)."""
    from fixturecad.registration import planning
    from fixturecad.registration.reach import reachable

    features = {f.id: f for f in features}
    points = {}
    for fid in [fid for fid, f in features.items() if f.surface]:
        try:
            points.update(planning.candidate_points(features, [fid], planning.DEFAULT_MARGIN_MM,
                                                    keep=lambda p, n: reachable(triangles, p, n)))
        except ValueError:
            pass  # no reachable point that far in: the next touches go to the other features
    return planning.candidate_record(points, planning.DEFAULT_MARGIN_MM)


def default_target(template: "Template", out_root: Path | None = None) -> Path:
    """``out/<template>-<short parameters>`` under the current directory (or ``out_root``)."""
    return (Path("out") if out_root is None else Path(out_root)) / template.slug()


def build(template: "Template", target: Path, force: bool = False,
          stl_tolerance: float = DEFAULT_STL_TOLERANCE_MM, fixture_tolerance: float = DEFAULT_ZONE_MM) -> Path:
    """Write the fixture folder ``target``; return it. InputError if it exists and not ``force``
    (see :mod:`fixturecad.staging`)."""
    from fixturecad.sideprocess import SideProcess

    check_stl_tolerance(stl_tolerance)
    check_fixture_tolerance(fixture_tolerance)
    with staged_folder(target, force) as staging:
        side = SideProcess("preview", "register")  # imports matplotlib and scipy while we import cadquery
        try:
            _write_all(template, staging, stl_tolerance, fixture_tolerance, side)
        except BaseException:
            side.cancel()
            raise
    return Path(target)


def _write_all(template: "Template", folder: Path, stl_tolerance: float, fixture_tolerance: float, side) -> None:
    from fixturecad.cad.brep import match_features
    from fixturecad.cad.export import Named, export
    from fixturecad.cad.faces import faces_record
    from fixturecad.cad.mesh import triangulate
    from fixturecad.registration.sampling import read_triangles
    from fixturecad.cad.solid import fixture_solid
    from fixturecad.preview import feature_colours, fixture_scene

    shape = fixture_solid(template)
    if not shape.isValid() or len(shape.Solids()) != 1:
        raise RuntimeError(f"{template.slug()}: the CAD kernel did not give one valid solid")
    volume, expected = shape.Volume(), template.volume()
    if abs(volume - expected) > VOLUME_RELATIVE_TOLERANCE * expected:
        raise RuntimeError(f"{template.slug()}: solid volume {volume:.6f} mm^3 differs from the analytic {expected:.6f}")
    features = template.features()
    matches = match_features(shape, features)

    size = max(shape.BoundingBox().xlen, shape.BoundingBox().ylen, shape.BoundingBox().zlen)
    parts = triangulate(shape, PREVIEW_CHORD_FRACTION * size)
    # the side process draws preview.png while we write STEP and STL
    side.send(("preview", fixture_scene(template, features, matches, parts), folder / FILES["preview"]))
    colours = feature_colours([feature.id for feature in features])
    named = [Named(f.id, **{("edges" if f.kind == "line" else "faces"): tuple(matches[f.id])}, colour=colours[f.id])
             for f in features if f.kind != "point"]
    export(shape, [folder / FILES[kind] for kind in ("step", "stl", "3mf")], stl_tolerance, template.slug(), named)
    document = features_document(template, stl_tolerance, fixture_tolerance,
                                 touch_candidates(features, read_triangles(folder / FILES["stl"])), faces_record(shape))
    features_json.write(document, folder / FILES["features"])
    side.send(("register", document, folder / FILES["register"]))
    (folder / FILES["touches"]).write_text(touch_template(template), encoding="utf-8")
    (folder / FILES["touches_json"]).write_text(touch_template_json(template), encoding="utf-8")
    side.wait()
