"""Touch groups: touches of one contact type on one feature, from points, sensors and touch files.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

from dataclasses import dataclass

import numpy as np

from .contacts import ContactType, make_side
from .defaults import MAX_COORDINATE_MM
from .elements import element, outward
from .noise import placement_centre

# Sensor keys beyond the element's own, by kind: a fixed plane's known contact line with a line, a
# cylinder or a plane (the contact model's ``e``).
EXTRA_SENSOR_KEYS = {"plane": {"line": "e"}}


@dataclass
class TouchGroup:
    """Touches of one contact type on one feature.

    ``points`` (n, 3) mm in the measurement frame are the probe points (point
    touches) or ball centres (ball-tip touches); None for other sensors.
    ``approach`` (n, 3), optional: the direction the probe moved to make each
    touch (measurement frame; NaN rows unknown).
    ``index`` (n,) numbers the touches in the caller's order.
    ``centre`` (n, 3) mm, measurement frame: the point the sensor's placement
    error turns about (see :func:`placement_centre`); None: from the sensor.
    ``located``: that point is the sensor's known contact point on the feature.
    """

    feature: object
    ctype: ContactType
    sensor: object
    fixture: object
    rho: np.ndarray
    index: np.ndarray
    points: np.ndarray | None = None
    rows: int = 0
    approach: np.ndarray | None = None
    centre: np.ndarray | None = None
    located: bool = False  # a sensor's contact point (``centre``) is known: it must lie on the feature's patch

    @property
    def count(self) -> int:
        return len(self.index)


def fixture_side(feature, fixed: bool, **extra):
    """The contact-model side of a feature in the fixture frame (a point is always fixed, at itself)."""
    el = element(feature.kind)
    geometry = el.side_geometry(feature)
    if el.letter == "P":
        fixed, geometry["o"] = True, feature.point
    return make_side(el.letter, fixed, **{**geometry, **extra})


def point_touches(feature, points, index, ball_radius_mm=0.0) -> TouchGroup:
    """Point-probe touches (ball radius 0) or ball-tip centres on a feature."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = len(points)
    fixture_element = feature.element
    fixture_fixed = feature.kind == "point"
    if ball_radius_mm > 0.0:
        ctype = ContactType("S", False, fixture_element, fixture_fixed)
        sensor = make_side("S", False, c=points, r=np.full(n, ball_radius_mm))
        # The ball's centre keeps off the feature's core by both radii (a point's row needs none).
        rho = 0.0 if fixture_fixed else ball_radius_mm + feature.core()[3]
    else:
        ctype = ContactType("P", True, fixture_element, fixture_fixed)
        sensor = make_side("P", True, c=points, o=points)
        rho = 0.0
    return TouchGroup(
        feature, ctype, sensor, fixture_side(feature, fixture_fixed), np.full(n, float(rho)),
        np.asarray(index), points, centre=points,
    )


def sensor_geometry(ctype, sensor, contact_point=None):
    """Contact-model keys of a sensor element, measurement frame.

    ``sensor`` is either the touch-plan form ``{"kind": "plane", "point",
    "normal"}`` / ``{"kind": "line", "point", "direction"}`` /
    ``{"kind": "sphere" | "cylinder", ..., "radius"}``, or the contact model's
    keys (``q``, ``n``, ``p``, ``d``, ``c``, ``r``, ``o``...) directly.
    ``contact_point`` (3,) mm is the known contact point of a fixed sensor.
    """
    if "kind" not in sensor:
        geometry = {key: np.asarray(value, dtype=np.float64) for key, value in sensor.items()}
    else:
        names = {**dict(element(sensor["kind"]).keys), **EXTRA_SENSOR_KEYS.get(sensor["kind"], {})}
        geometry = {names[key]: np.asarray(value, dtype=np.float64) for key, value in sensor.items() if key in names}
        for key in ("n", "d", "e"):
            if key in geometry:
                length = np.linalg.norm(geometry[key])
                if not length > 1e-9:
                    raise ValueError(f"a {sensor['kind']} sensor's {dict(map(reversed, names.items()))[key]} "
                                     f"must be a non-zero vector")
                geometry[key] = geometry[key] / length
    if ctype.sensor_fixed and "o" not in geometry:
        if contact_point is None:
            if ctype.sensor != "P":
                raise ValueError(f"a fixed {ctype.sensor} sensor needs its contact point")
            contact_point = geometry["c"]
        geometry["o"] = np.asarray(contact_point, dtype=np.float64)
        el = element(ctype.sensor)
        if el.round:
            # a fixed ball or cylinder knows its normal at the contact point, and so its contact line's side
            core, anchor, direction, _ = el.core_of({json: geometry[side] for json, side in el.keys})
            geometry["u"] = outward(core, anchor, direction, geometry["o"][None])[0]
            if el.core == "line":
                geometry["m"] = geometry["u"]
    return geometry


def laid_sensor(kind, point, normal, tangent, radius_mm) -> dict:
    """A sensor of element ``kind`` (a letter) touching a surface at ``point`` from outside (outward unit
    ``normal`` there), in the touch-plan form: a probe point; a ball or a cylinder (its axis along the
    unit ``tangent``) one ``radius_mm`` out; a plane tangent there; a line along ``tangent``."""
    point, normal, tangent = (np.asarray(v, dtype=np.float64) for v in (point, normal, tangent))
    return {"P": lambda: {"kind": "point", "point": point},
            "S": lambda: {"kind": "sphere", "center": point + radius_mm * normal, "radius": radius_mm},
            "PL": lambda: {"kind": "plane", "point": point, "normal": -normal},
            "L": lambda: {"kind": "line", "point": point, "direction": tangent},
            "C": lambda: {"kind": "cylinder", "point": point + radius_mm * normal, "axis": tangent,
                          "radius": radius_mm}}[kind]()


def contact_touch(feature, contact: str, sensor: dict, index: int, rho=None, fixture=None,
                  contact_point=None) -> TouchGroup:
    """One touch of any contact type: the sensor element's geometry in the measurement frame.

    ``sensor`` see :func:`sensor_geometry`; ``fixture`` optional extra
    fixture-frame keys of a fixed fixture side (its known contact point ``o``).
    ``rho`` (mm) defaults to the offset of two convex elements touching from
    outside: the sum of the radii of the mobile sides (a ball tip on a plane:
    its radius; on a sphere: both radii; a fixed ball's known point on a
    mobile plane: 0; a plane sensor on a cylinder: the cylinder's radius).
    """
    ctype = ContactType.parse(contact)
    if ctype.fixture != feature.element:
        raise ValueError(
            f"contact {contact} touches a {ctype.fixture} element but feature {feature.id} is a {feature.kind}"
        )
    geometry = {key: value[None] for key, value in sensor_geometry(ctype, sensor, contact_point).items()}
    side = make_side(ctype.sensor, ctype.sensor_fixed, **geometry)
    extra = {key: np.asarray(value, dtype=np.float64) for key, value in (fixture or {}).items()}
    if ctype.fixture_fixed and "o" in extra and "u" not in extra and element(feature.kind).surface:
        extra["u"] = feature.normal_at(extra["o"])[0]
        if feature.kind == "cylinder":
            extra["m"] = extra["u"]  # the known contact line's side of the axis
    fside = fixture_side(feature, ctype.fixture_fixed, **extra)
    if rho is None:
        # From a side's known surface point to the other's mobile core, that core's radius; between two
        # mobile cores, or a line's or a cylinder's axis above a plane, both radii.
        radii = (float(np.reshape(geometry.get("r", 0.0), -1)[0]), float(feature.core()[3]))
        rho = sum(r for r, fixed in zip(radii, (ctype.sensor_fixed, ctype.fixture_fixed)) if ctype.is_locus or not fixed)
    centre = placement_centre(ctype.sensor, geometry, None if contact_point is None else np.reshape(contact_point, (1, 3)))
    return TouchGroup(feature, ctype, side, fside, np.array([float(rho)]), np.array([index]), centre=centre,
                      located=contact_point is not None or "o" in geometry)


def build_groups(features, touches, ball_radius_mm=0.0, contacts=(), approaches=None):
    """Touch groups from point touches by feature id and generic contact touches.

    ``approaches`` optional dict id -> (n, 3): probe approach directions of the touches.
    """
    approaches = approaches or {}
    groups, index = [], 0
    for feature_id, points in touches.items():
        if feature_id not in features:
            raise ValueError(f"unknown feature {feature_id!r}; features are {', '.join(features)}")
        pts = np.asarray(points, dtype=np.float64)
        if pts.size == 0:
            continue  # no touches on this feature
        if pts.ndim == 1 and pts.size == 3:
            pts = pts[None]
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"touches on {feature_id} must have shape (n, 3) in mm, got shape {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise ValueError(f"touches on {feature_id} must be finite, got NaN or inf")
        if np.abs(pts).max(initial=0.0) > MAX_COORDINATE_MM:
            raise ValueError(f"touches on {feature_id} lie beyond {MAX_COORDINATE_MM:g} mm: check the units")
        ids = np.arange(index, index + len(pts))
        index += len(pts)
        group = point_touches(features[feature_id], pts, ids, ball_radius_mm)
        if feature_id in approaches:
            approach = np.asarray(approaches[feature_id], dtype=np.float64).reshape(-1, 3)
            if approach.shape != pts.shape:
                raise ValueError(f"approaches on {feature_id} must have shape {pts.shape}, got {approach.shape}")
            group.approach = approach
        groups.append(group)
    for contact in contacts:
        feature_id = contact.get("feature")
        if feature_id not in features:
            raise ValueError(f"unknown feature {feature_id!r}; features are {', '.join(features)}")
        groups.append(
            contact_touch(
                features[feature_id], contact["contact"], contact["sensor"], index,
                contact.get("rho"), contact.get("fixture"), contact.get("point"),
            )
        )
        index += 1
    return groups
