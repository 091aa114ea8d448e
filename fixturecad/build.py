"""``fixturecad build``: one template instance to fixture.step, fixture.stl, features.json, preview.png.

Everything is written into a temporary folder beside the target and moved into
place only when complete, so a failed or interrupted build leaves nothing
behind and an existing folder is replaced only with ``force``.
"""

import json
import math
import os
import shutil
import tempfile
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from fixturecad.errors import InputError
from fixturecad.registration.tolerance import DEFAULT_ZONE_MM

if TYPE_CHECKING:
    from fixturecad.templates.base import Template

SCHEMA_ID = "fixturecad.features/1"
FILES = {"step": "fixture.step", "stl": "fixture.stl", "features": "features.json",
         "preview": "preview.png", "register": "register.py"}
# Relative agreement required between the BREP volume and the analytic one.
VOLUME_RELATIVE_TOLERANCE = 1e-6
# Chord tolerance of the STL tessellation unless asked otherwise, and the accepted range, mm.
DEFAULT_STL_TOLERANCE_MM = 0.01
STL_TOLERANCE_RANGE_MM = (1e-4, 1.0)
# The recorded manufacturing tolerance: its meaning, and the widest zone accepted (a print that bad is no fixture).
TOLERANCE_DEFINITION = ("ISO 1101 profile tolerance of every sensing patch: each point of the printed patch "
                        "lies within +-zone_mm/2 of its nominal surface; 0: the part is exact")
FIXTURE_TOLERANCE_LIMIT_MM = 2.0
# Chord tolerance of the preview tessellation, as a fraction of the fixture size.
PREVIEW_CHORD_FRACTION = 0.004


def load_schema() -> dict:
    """The JSON Schema of features.json shipped in the package."""
    text = resources.files("fixturecad").joinpath("schema/features.schema.json").read_text(encoding="utf-8")
    return json.loads(text)


def validate_document(document: dict) -> None:
    """Raise jsonschema.ValidationError if ``document`` does not follow the features.json schema."""
    import jsonschema

    jsonschema.validate(document, load_schema())


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
                      fixture_tolerance: float = DEFAULT_ZONE_MM) -> dict:
    """The features.json content of a template instance (no CAD needed)."""
    from importlib.metadata import version

    plans = template.touch_plans()
    return {
        "schema": SCHEMA_ID,
        "units": "mm",
        "generator": f"fixturecad {version('fixturecad')}",
        "template": template.name,
        "parameters": template.parameters_json(),
        "contact_class": template.contact_class,
        "frame": template.FRAME,
        "datums": template.DATUMS.to_json(template.DATUM_TEXT),
        "tolerance": {"zone_mm": fixture_tolerance, "definition": TOLERANCE_DEFINITION},
        "volume_mm3": template.volume(),
        "files": {"step": FILES["step"], "stl": FILES["stl"], "stl_tolerance_mm": stl_tolerance,
                  "preview": FILES["preview"]},
        "features": [feature.to_json() for feature in template.features()],
        "touch_plan": plans["default"].touches,
        "plans": {name: plan.to_json() for name, plan in plans.items()},
    }


def default_target(template: "Template", out_root: Path | None = None) -> Path:
    """``out/<template>-<short parameters>`` under the current directory (or ``out_root``)."""
    return (Path("out") if out_root is None else Path(out_root)) / template.slug()


def build(template: "Template", target: Path, force: bool = False,
          stl_tolerance: float = DEFAULT_STL_TOLERANCE_MM, fixture_tolerance: float = DEFAULT_ZONE_MM) -> Path:
    """Write the fixture folder ``target``; return it. InputError if it exists and not ``force``."""
    from fixturecad.sideprocess import SideProcess

    check_stl_tolerance(stl_tolerance)
    check_fixture_tolerance(fixture_tolerance)
    target = Path(target)
    if target.exists() and not force:
        raise InputError(f"{target} already exists; pass --force to replace it")
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent))
    staging.chmod(0o777 & ~_umask())  # mkdtemp makes it private; the result is an ordinary folder
    side = SideProcess(staging)  # imports matplotlib and scipy while we import cadquery
    try:
        _write_all(template, staging, stl_tolerance, fixture_tolerance, side)
        _move_into_place(staging, target)
    except BaseException:
        side.cancel()
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return target


def _write_all(template: "Template", folder: Path, stl_tolerance: float, fixture_tolerance: float, side) -> None:
    from fixturecad.brep import match_features
    from fixturecad.mesh import mesh_from_shape, triangulate, write_stl

    shape = template.solid()
    if not shape.isValid() or len(shape.Solids()) != 1:
        raise RuntimeError(f"{template.slug()}: the CAD kernel did not give one valid solid")
    volume, expected = shape.Volume(), template.volume()
    if abs(volume - expected) > VOLUME_RELATIVE_TOLERANCE * expected:
        raise RuntimeError(f"{template.slug()}: solid volume {volume:.6f} mm^3 differs from the analytic {expected:.6f}")
    features = template.features()
    matches = match_features(shape, features)

    size = max(shape.BoundingBox().xlen, shape.BoundingBox().ylen, shape.BoundingBox().zlen)
    parts = triangulate(shape, PREVIEW_CHORD_FRACTION * size)
    document = features_document(template, stl_tolerance, fixture_tolerance)
    (folder / FILES["features"]).write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    # the side process draws preview.png and writes register.py while we write STEP and STL
    side.send(_scene(template, features, matches, parts), folder / FILES["preview"],
              folder / FILES["features"], folder / FILES["register"])
    shape.exportStep(str(folder / FILES["step"]))
    vertices, faces = mesh_from_shape(shape, stl_tolerance)
    write_stl(folder / FILES["stl"], vertices, faces, template.slug())
    side.wait()


def write_register_script(document: dict, path: Path) -> None:
    """register.py beside features.json (run in the side process)."""
    from fixturecad.registration.generate import write_register_script as generate

    generate(document, path)


def _scene(template: "Template", features, matches: dict, parts) -> dict:
    """Preview data: tessellated faces tagged with their feature, labels, default touch plan."""
    import numpy as np

    from fixturecad.preview import scene, view_from_direction

    face_owner = {}
    for feature in features:
        if feature.kind in ("plane", "sphere", "cylinder"):
            for index in matches[feature.id]:
                face_owner[index] = feature.id
    faces = []
    for index, (_, nodes, triangles) in enumerate(parts):
        faces.append((nodes, triangles, face_owner.get(index)))
    plan = template.touch_plans()["default"]
    touches, number = [], 0
    anchors = {}
    by_id = {feature.id: feature for feature in features}
    for entry in plan.touches:
        for point in entry["points"]:
            number += 1
            normal = _label_normal(by_id[entry["feature"]], np.array(point), features)
            touches.append({"point": np.array(point), "normal": normal, "label": str(number),
                            "text": f"{number:>2} {entry['contact']:<10} {entry['feature']}"})
            anchors.setdefault(entry["feature"], []).append(point)
    feature_rows = []
    for feature in features:
        segment = None
        if feature.kind == "line":
            t0, t1 = feature.extent.interval
            segment = np.array([feature.point + t0 * feature.direction, feature.point + t1 * feature.direction])
        if feature.id in anchors:
            anchor = np.mean(anchors[feature.id], axis=0)
        else:
            nodes = np.vstack([parts[i][1] for i in matches[feature.id] if i < len(parts)] or [feature.point])
            anchor = nodes.mean(axis=0)
        if feature.kind != "line":
            anchor = anchor + 0.08 * _span(parts) * feature.normal_at(anchor)[0]
        normal = _label_normal(feature, anchor, features)
        feature_rows.append({"id": feature.id, "kind": feature.kind, "element": feature.element,
                             "anchor": anchor, "normal": normal, "segment": segment})
    parameters = ", ".join(f"{k} {v:g}" for k, v in template.parameters_json().items() if k != "base")
    title = (f"{template.name} ({parameters}{', base' if template.base else ''}): {template.contact_class}"
             f" - default plan, {number} touches")
    views = tuple(view_from_direction(d) for d in template.VIEW_DIRECTIONS)
    label_normals = {row["id"]: row["normal"] for row in feature_rows}
    sensors = [{**_sensor_drawing(entry["sensor"], 0.35 * _span(parts)), "normal": label_normals[entry["feature"]]}
               for entry in plan.touches if "sensor" in entry]
    return scene(title, faces, feature_rows, touches, views, sensors)


def _sensor_drawing(sensor: dict, size: float) -> dict:
    """A non-point sensor of the plan as something to draw: a square of the plane or a segment of the line."""
    import numpy as np

    point = np.array(sensor["point"])
    if sensor["kind"] == "line":
        d = np.array(sensor["direction"])
        return {"kind": "line", "points": np.array([point - size * d, point + size * d])}
    n = np.array(sensor["normal"])
    a = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    corners = [point + size / 2 * (sa * a + sb * b) for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return {"kind": "plane", "points": np.array(corners)}


def _label_normal(feature, anchor, features):
    """Outward normal used to hide a label from views that face away; for a line or point, the
    mean normal of the surfaces that meet there."""
    import numpy as np

    if feature.kind not in ("line", "point"):
        return feature.normal_at(anchor)[0]
    near = [f.normal_at(anchor)[0] for f in features
            if f.kind in ("plane", "sphere", "cylinder") and abs(f.signed_distance(anchor)[0]) < 1e-6 and f.contains(anchor)[0]]
    total = np.sum(near, axis=0) if near else np.zeros(3)
    return total / np.linalg.norm(total) if np.linalg.norm(total) > 1e-9 else None


def _span(parts) -> float:
    import numpy as np

    nodes = np.vstack([p[1] for p in parts])
    return float((nodes.max(axis=0) - nodes.min(axis=0)).max())


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _move_into_place(staging: Path, target: Path) -> None:
    if target.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old", dir=target.parent))
        os.replace(target, old / target.name)
        os.replace(staging, target)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(staging, target)
