"""Synthetic touches: what a touch plan produces at a pose, and sensors placed with the noise model.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .contacts import ContactType
from .defaults import SENSOR_LEVER_MM
from .pose import check_fixture2meas, rotation_from_vector

def plan_touches(entries, fixture2meas):
    """Touches a touch plan (fixture-frame entries) produces at a pose, for :func:`register_touches`.

    Returns (touches by feature id, contacts): point entries become probe
    points; entries with a sensor become contacts with the sensor mapped to
    the measurement frame and a fixed fixture side's known point attached.
    """
    T = check_fixture2meas(fixture2meas)
    R, t = T[:3, :3], T[:3, 3]
    touches, contacts = {}, []
    for entry in entries:
        points = np.asarray(entry["points"], dtype=np.float64).reshape(-1, 3)
        if "sensor" not in entry:
            touches.setdefault(entry["feature"], []).extend(points @ R.T + t)
            continue
        ctype = ContactType.parse(entry["contact"])
        for point in points:
            sensor = {"kind": entry["sensor"]["kind"]}
            for key, value in entry["sensor"].items():
                if key in ("point", "center"):
                    sensor[key] = (R @ np.asarray(value, float) + t).tolist()
                elif key in ("normal", "direction", "axis", "line"):
                    sensor[key] = (R @ np.asarray(value, float)).tolist()
                elif key != "kind":
                    sensor[key] = value
            contact = {"feature": entry["feature"], "contact": entry["contact"], "sensor": sensor,
                       "point": (R @ point + t).tolist()}
            if entry.get("rho") is not None:
                contact["rho"] = float(entry["rho"])
            if ctype.fixture_fixed:
                contact["fixture"] = {"o": point.tolist()}
            contacts.append(contact)
    return {key: np.array(value) for key, value in touches.items()}, contacts


def perturb_touches(touches, contacts, rng, sigma_mm, lever_mm=SENSOR_LEVER_MM):
    """Touches as made by sensors placed with the noise model's random rigid errors.

    Every touch's sensor is moved by a translation N(0, sigma_mm^2 I) and a
    rotation N(0, (sigma_mm / lever_mm)^2 I) (rotation vector, rad) about its
    contact point (a point probe's point, a ball's centre): point touches by
    the translation, contact sensors' points, directions and contact point by
    the whole motion. Returns new (touches, contacts) like :func:`plan_touches`.
    """
    touches = {key: np.asarray(value, float) + rng.normal(scale=sigma_mm, size=np.shape(value))
               for key, value in touches.items()}
    out = []
    for contact in contacts:
        sensor = dict(contact["sensor"])
        if sensor.get("kind") in ("point", "sphere") or "point" not in contact:
            centre = np.asarray(sensor.get("center", sensor.get("point")), float)
        else:
            centre = np.asarray(contact["point"], float)
        R = rotation_from_vector(rng.normal(scale=sigma_mm / lever_mm, size=3))
        shift = rng.normal(scale=sigma_mm, size=3)

        def place(x):
            return (centre + R @ (np.asarray(x, float) - centre) + shift).tolist()

        for key in ("point", "center"):
            if key in sensor:
                sensor[key] = place(sensor[key])
        for key in ("normal", "direction", "axis"):
            if key in sensor:
                sensor[key] = (R @ np.asarray(sensor[key], float)).tolist()
        contact = {**contact, "sensor": sensor}
        if "point" in contact:
            contact["point"] = place(contact["point"])
        out.append(contact)
    return touches, out
