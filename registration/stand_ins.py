"""Sensor touches as the point touches that stand in for them in the complete search.

A sensor whose contact point is known on one side puts a point on an element, and the search
(:mod:`.search`) bounds point touches. Each sensor touch below is replaced, in the search only, by a
point touch at that point on that element (a feature, or its centre, axis or known point as a feature
of its own) whose squared distance ``d^2`` is at most the sensor touch's cost over ``kappa2``:

* a point probe or a line sensor with its contact point ``o`` known, on a mobile feature: ``o`` lies on
  the feature (the line's tangency row left out), ``kappa2 = 1``;
* a plane, ball or cylinder sensor with ``o`` and its normal ``u`` known, on a mobile feature that is
  not a plane's locus (a sphere, a cylinder, an edge; a ball on a plane): ``o + rho u`` lies on the
  feature's core (its centre, axis or plane; the normals' rows left out);
* both contact points known: they coincide (the orientation rows left out);
* a ball tip on a feature whose contact point ``o`` is known: the ball's centre lies at ``o + rho u``,
  or a ball radius from ``o`` on an edge or a point, ``kappa2 = 1``.

Why ``cost >= kappa2 d^2``: a sensor touch's cost is ``r^T C^-1 r`` with ``C = G G^T / L^2 + J_v J_v^T``
(:func:`.noise.row_whitening`; ``J_v`` the rows' translation Jacobian, ``G`` their turn about ``o``,
``L`` the sensor lever), which is at least ``r_S^T C_SS^-1 r_S`` for the rows S that put the point on
the element (leaving rows out of a Mahalanobis distance never raises it), and ``r_S^T C_SS^-1 r_S >=
|r_S|^2 / lambda_max(C_SS)``, ``|r_S| = d``. Those rows' ``J_v`` has orthonormal rows, and a turn about
``o`` moves the point ``o + rho u`` by ``rho`` times the turn: ``lambda_max(C_SS) <= 1 + (rho + g)^2 /
L^2``, ``g`` the gap between the point and its place on a centre (a point core: 0 on an axis or a plane,
where the rows across the core do not see the gap's own direction). Point probes and ball tips without a
known point are not whitened (``kappa2 = 1``). The gap is bounded by ``reach``: a pose that puts the point
farther than ``reach`` from a centre has ``d^2 kappa2 > T`` there (``kappa2`` falls as ``d`` grows, more
slowly than ``d^2`` rises), so it fails, and the search may take ``reach`` as the gap.

So a pose that passes (cost at most ``T``) has its stand-ins' cost at most ``T / min kappa2``: the search
with that threshold holds every pose that passes. Sensors that move on both sides, plane sensors on a
plane, a line or a cylinder (a locus), and every sensor on a printed part (whose deviations move the rows
in ways the point's own modes do not), have no stand-in: the search leaves them out and says so.

This module imports numpy only and nothing of fixturecad: it is inlined into the generated standalone
``register.py``.
"""

import numpy as np

from .contacts import DIRECTION_KEYS, POINT_KEYS
from .elements import element
from .features import Extent, Line, Point, Sphere
from .noise import is_point_sensor
from .patches import patch_size
from .touches import point_touches

REACH_STEPS = (2.0, 4.0, 8.0, 16.0, 32.0)  # multiples of sqrt(T) tried as the gap a centre's stand-in may have


def stand_ins(problem, threshold):
    """The point and ball touches of the problem with a stand-in for every sensor touch that has one:
    (groups, kappa2, left), ``kappa2`` the least of their factors (module doc) and ``left`` the number of
    sensor touches left out."""
    points = [g for g in problem.groups if g.points is not None]
    sensors = [g for g in problem.groups if g.points is None]
    if problem.tolerance is not None:
        return points, 1.0, sum(g.count for g in sensors)
    groups, kappa2, left = list(points), 1.0, 0
    for g in sensors:
        for k in range(g.count):
            found = stand_in(g, k, threshold, problem.lever)
            if found is None:
                left += 1
                continue
            feature, point, factor = found
            groups.append(point_touches(feature, point, g.index[k:k + 1]))
            kappa2 = min(kappa2, factor)
    return groups, kappa2, left


def stand_in(group, k, threshold, lever_mm):
    """Touch k of a sensor group as (feature, point (1, 3) mm in the measurement frame, kappa2), or None
    (module doc)."""
    ctype, feature = group.ctype, group.feature
    if ctype.is_locus:
        return None
    s = {key: value[k] for key, value in _rows(group.sensor.geometry, group.count).items()}
    f = {key: value[k] for key, value in _rows(group.fixture.geometry, group.count).items()}
    rho = float(group.rho[k])
    plain = is_point_sensor(group.sensor)
    name = f"{feature.id}#{int(group.index[k])}"
    if ctype.sensor_fixed and ctype.fixture_fixed:
        # Both points known: they coincide, the gap turning about o.
        return _centred(Point(name, f["o"]), s["o"], 0.0, threshold, lever_mm, plain)
    if ctype.sensor_fixed:
        if not element(ctype.sensor).surface:
            return feature, s["o"][None], 1.0  # a probe's or a line's known point on the feature
        target = s["o"] + rho * s["u"]
        core = element(ctype.fixture).core
        if core == "point":
            return _centred(Point(name, feature.core()[1]), target, rho, threshold, lever_mm, plain)
        if core == "plane":
            return (feature, target[None], 1.0) if rho == 0.0 else None
        if ctype.fixture == "L":
            return feature, target[None], 1.0 / (1.0 + (rho / lever_mm) ** 2)
        # The cylinder's axis, as far along it as the patch reaches and the offset can carry the point.
        return _axis(name, feature, rho), target[None], 1.0 / (1.0 + (rho / lever_mm) ** 2)
    if ctype.fixture_fixed and ctype.sensor == "S" and plain:
        if element(ctype.fixture).surface:
            return Point(name, f["o"] + rho * f["u"]), s["c"][None], 1.0  # the ball's centre at the offset point
        return Sphere(name, f["o"], float(s["r"])), s["c"][None], 1.0  # a ball radius from the known point
    return None


def _axis(name, cylinder, rho):
    """A cylinder's axis as a line feature, as far along it as the patch reaches and an offset of ``rho``
    (mm) from a point on the patch can carry a point (unbounded with the patch)."""
    try:
        size = patch_size(cylinder)
    except ValueError:
        return Line(name, cylinder.point, cylinder.axis)
    middle = float((size.centre - cylinder.point) @ cylinder.axis)
    half = float(size.half_extents_mm[0]) + rho
    return Line(name, cylinder.point, cylinder.axis, Extent(interval=(middle - half, middle + half)))


def _centred(centre, point, rho, threshold, lever_mm, plain):
    """A point that lies on a centre: kappa2 with the gap as large as a pose that passes can have it."""
    if plain:
        return centre, point[None], 1.0
    root = float(np.sqrt(threshold))
    for step in REACH_STEPS:
        reach = step * root
        kappa2 = 1.0 / (1.0 + ((rho + reach) / lever_mm) ** 2)
        if reach**2 * kappa2 > threshold:
            return centre, point[None], kappa2
    return None


def _rows(geometry, count):
    """A side's geometry with each key broadcast to one row per touch: (count, 3) or (count,)."""
    return {key: np.broadcast_to(np.reshape(value, (-1, 3)), (count, 3)) if key in POINT_KEYS | DIRECTION_KEYS
            else np.broadcast_to(np.reshape(value, -1), (count,)) for key, value in geometry.items()}
