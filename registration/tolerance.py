"""Manufacturing tolerance: how a printed feature may deviate from its drawing.

A printed face is its nominal feature moved by a small rigid motion and, for
a sphere or a cylinder, grown or shrunk. Each feature has a few *deviation
modes*, each a coordinate with a unit (mm or rad):

========  ===================================================================
plane     ``offset_mm`` along the normal at the patch centre; ``tilt_1_rad``,
          ``tilt_2_rad`` about the patch's two principal directions through
          its centre
sphere    ``centre_x_mm``, ``centre_y_mm``, ``centre_z_mm``; ``radius_mm``
cylinder  ``shift_1_mm``, ``shift_2_mm`` of the axis at the middle of the
          patch; ``tilt_1_rad``, ``tilt_2_rad`` of the axis about that
          point; ``radius_mm``
line      as a cylinder without the radius
point     ``x_mm``, ``y_mm``, ``z_mm``
========  ===================================================================

The manufacturing tolerance is the width ``zone_mm`` of an ISO 1101 profile
zone: every point of a printed sensing patch lies within ``+-zone_mm / 2`` of
its nominal surface. The zone is shared out between the modes (``SHARES``):
with every coordinate within its ``+-half range``, no point of the patch
leaves the zone. "Deviations spread evenly over the zone" means each
coordinate uniform over its range, of standard deviation ``half range /
sqrt(3)``: that is the prior the registration gives them.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

from dataclasses import dataclass, replace

import numpy as np

from .elements import cross
from .patches import patch_points, patch_size
from .pose import motion_from_twist

# Each mode's share of the half zone (zone_mm / 2): position, orientation and size add up to 1.
SHARES = {
    "plane": {"offset": 0.5, "tilt": 0.25},  # two tilts, a quarter each at the patch's reach
    "sphere": {"centre": 0.5, "radius": 0.5},
    "cylinder": {"shift": 1 / 3, "tilt": 1 / 3, "radius": 1 / 3},
    "line": {"shift": 0.5, "tilt": 0.5},
    "point": {"position": 1.0},
}


@dataclass(frozen=True)
class Modes:
    """The deviation modes of one feature.

    ``centre`` (3,) mm: the point the tilts turn about (a plane's patch
    centre, the middle of a cylinder's or line's axis on the patch).
    ``twists`` (k, 6): the rigid motion of each mode per unit of its
    coordinate, a fixture-frame twist (omega rad, v mm) moving a point p by
    ``omega x p + v``; zero for a radius mode. ``radius`` (k,) bool: the mode
    grows the radius by its coordinate (mm). ``half_range`` (k,): the range
    of each coordinate (mm or rad) in a zone 1 mm wide.
    """

    feature: object
    names: tuple
    centre: np.ndarray
    twists: np.ndarray
    radius: np.ndarray
    half_range: np.ndarray

    def sigma(self, zone_mm):
        """Standard deviation (k,) of each coordinate spread evenly over a zone ``zone_mm`` wide."""
        return self.half_range * zone_mm / np.sqrt(3.0)


def _about(axis, point):
    """The unit twist of a rotation about ``axis`` through ``point``."""
    return np.concatenate([axis, cross(point, axis)])


def _shift(direction):
    return np.concatenate([np.zeros(3), direction])


def modes(feature) -> Modes:
    """The deviation modes of a feature (see the module doc)."""
    kind = feature.kind
    share = SHARES[kind]
    half = 0.5  # ranges per mm of zone: the half zone
    if kind == "plane":
        size = patch_size(feature)
        c, n = size.centre, feature.normal
        twists = [_shift(n)] + [_about(d, c) for d in size.directions]
        # A tilt about one principal direction lifts the patch along the other.
        ranges = [half * share["offset"]] + [half * share["tilt"] / h for h in size.half_extents_mm[::-1]]
        return Modes(feature, ("offset_mm", "tilt_1_rad", "tilt_2_rad"), c, np.array(twists), np.zeros(3, bool),
                     np.array(ranges))
    if kind == "sphere":
        a = half * share["centre"] / np.sqrt(3.0)  # the corner of the cube of ranges stays in the ball
        twists = [_shift(e) for e in np.eye(3)] + [np.zeros(6)]
        return Modes(feature, ("centre_x_mm", "centre_y_mm", "centre_z_mm", "radius_mm"), feature.center,
                     np.array(twists),
                     np.array([False, False, False, True]), np.array([a, a, a, half * share["radius"]]))
    if kind in ("cylinder", "line"):
        size = patch_size(feature)
        c, reach = size.centre, size.half_extents_mm[0]
        shift = half * share["shift"] / np.sqrt(2.0)
        tilt = half * share["tilt"] / np.sqrt(2.0) / reach
        twists = [_shift(d) for d in size.directions] + [_about(d, c) for d in size.directions]
        names = ("shift_1_mm", "shift_2_mm", "tilt_1_rad", "tilt_2_rad")
        ranges = [shift, shift, tilt, tilt]
        radius = [False] * 4
        if kind == "cylinder":
            twists.append(np.zeros(6))
            names += ("radius_mm",)
            ranges.append(half * share["radius"])
            radius.append(True)
        return Modes(feature, names, c, np.array(twists), np.array(radius), np.array(ranges))
    if kind == "point":
        a = half * share["position"] * 2.0 / np.sqrt(3.0)  # a point's zone is a ball of radius zone / 2
        return Modes(feature, ("x_mm", "y_mm", "z_mm"), feature.point, np.array([_shift(e) for e in np.eye(3)]),
                     np.zeros(3, bool), np.full(3, a))
    raise ValueError(f"unknown feature kind {kind!r}")


def moved(feature, rotation, translation, radius_change_mm=0.0):
    """The feature moved rigidly by ``x -> R x + t`` (its patch with it) and its radius grown."""
    changes = {}
    for name in ("point", "center"):
        if hasattr(feature, name):
            changes[name] = rotation @ getattr(feature, name) + translation
    for name in ("normal", "axis", "direction"):
        value = getattr(feature, name, None)
        if isinstance(value, np.ndarray):
            changes[name] = rotation @ value
    if hasattr(feature, "radius"):
        changes["radius"] = feature.radius + radius_change_mm
    if feature.kind != "point":
        changes["extent"] = _moved_extent(feature.extent, rotation, translation)
    return replace(feature, **changes)


def _moved_extent(extent, rotation, translation):
    halfspaces = extent.halfspaces.copy()
    halfspaces[:, :3] = extent.halfspaces[:, :3] @ rotation.T
    halfspaces[:, 3] = extent.halfspaces[:, 3] + halfspaces[:, :3] @ translation
    balls = extent.balls.copy()
    balls[:, :3] = extent.balls[:, :3] @ rotation.T + translation
    cylinders = extent.cylinders.copy()
    cylinders[:, :3] = extent.cylinders[:, :3] @ rotation.T + translation
    cylinders[:, 3:6] = extent.cylinders[:, 3:6] @ rotation.T
    # An axial interval is measured from the feature's own point along its axis: it moves with it.
    return replace(extent, halfspaces=halfspaces, balls=balls, cylinders=cylinders)


def deviated(mode_set: Modes, coordinates):
    """The feature as printed with the given mode coordinates (k,): exact rigid motion and radius."""
    coordinates = np.asarray(coordinates, float)
    twist = coordinates @ mode_set.twists
    R, t = motion_from_twist(twist)
    return moved(mode_set.feature, R, t, float(coordinates @ mode_set.radius))


def coordinates(mode_set: Modes, actual):
    """The mode coordinates (k,) of a printed feature ``actual`` (to first order in the deviation)."""
    f = mode_set.feature
    kind = f.kind
    if kind == "plane":
        offset = ((actual.point - mode_set.centre) @ actual.normal) / (f.normal @ actual.normal)
        tilts = [actual.normal @ cross(t[:3], f.normal) for t in mode_set.twists[1:]]
        return np.array([offset] + tilts)
    if kind == "sphere":
        return np.concatenate([actual.center - f.center, [actual.radius - f.radius]])
    if kind == "point":
        return actual.point - f.point
    axis, actual_axis = (f.axis, actual.axis) if kind == "cylinder" else (f.direction, actual.direction)
    directions, centre = mode_set.twists[:2, 3:], mode_set.centre
    # The printed axis where it crosses the plane normal to the nominal axis through the pivot.
    crossing = actual.point + ((centre - actual.point) @ axis) / (actual_axis @ axis) * actual_axis
    out = [d @ (crossing - centre) for d in directions]
    out += [actual_axis @ cross(t[:3], axis) for t in mode_set.twists[2:4]]
    if kind == "cylinder":
        out.append(actual.radius - f.radius)
    return np.array(out)


def random_coordinates(mode_set: Modes, zone_mm, rng):
    """Mode coordinates spread evenly over the zone: each uniform over its range."""
    a = mode_set.half_range * zone_mm
    return rng.uniform(-a, a)


def departure_mm(nominal, actual):
    """The largest distance (mm) of the actual surface from the nominal one over the nominal patch."""
    return float(np.abs(actual.signed_distance(patch_points(nominal))).max())
