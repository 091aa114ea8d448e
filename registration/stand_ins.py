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
with that threshold holds every pose that passes. On a printed part a pose passes when its rows are ``n +
J_d z`` with ``|n|^2 <= T`` and ``z^T S^-1 z <= q`` (docs/registration.md); the same argument on ``r -
J_d z`` bounds the stand-in's rows less their deviation, and the stand-in takes its sensor's feature's
modes (:attr:`StandIn.source`): rigidly with the element, and a radius mode along the sensor's or the
feature's normal; its deviation bound is :func:`deviation_bound_mm` (a point touch's own where it lies on
the feature itself). Sensors that move on both sides and plane sensors on a plane, a line or a cylinder
(a locus) have no stand-in: the search leaves them out and says so.

This module imports numpy only and nothing of fixturecad: it is inlined into the generated standalone
``register.py``.
"""

from dataclasses import dataclass, field

import numpy as np

from .contacts import DIRECTION_KEYS, POINT_KEYS
from .elements import cross, element
from .features import Extent, Line, Point, Sphere
from .noise import is_point_sensor
from .patches import box_corners, patch_box, patch_size
from .problem import Problem
from .touches import point_touches

REACH_STEPS = (2.0, 4.0, 8.0, 16.0, 32.0)  # multiples of sqrt(T) tried as the gap a centre's stand-in may have
PLACES_GROWTH_MM = 2.0  # a patch's box grown by this holds where a stand-in on it is measured (its slack is less)


@dataclass
class StandIn:
    """A sensor touch's stand-in: a point touch at ``point`` (1, 3) mm, measurement frame, on ``feature``,
    costing at most the touch's cost over ``kappa2``. On a printed part the sensor's own ``source`` feature's
    modes move it: rigidly with its element, whose places lie in the hull of ``places`` (n, 3) mm, fixture
    frame; a radius mode (per mm) moves the element off the point by ``move`` (fixture frame) or by the pose's
    turn of ``sensor_move`` (measurement frame: the sensor's own normal); ``own``: the stand-in lies on the
    source itself, a point touch like any other."""

    feature: object
    point: np.ndarray
    kappa2: float
    source: object
    places: np.ndarray = None
    move: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sensor_move: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def own(self):
        return self.feature is self.source


def stand_ins(problem, threshold):
    """The point and ball touches of the problem, then a stand-in for every sensor touch that has one:
    (groups, kappa2, left, stand-ins, without), ``kappa2`` the least of their factors (module doc), ``left``
    the number of sensor touches not searched in full (no stand-in, or one with fewer rows than the touch: a
    normal's or a tangency's rows left out), the :class:`StandIn` of each of the last groups, and the (group,
    k) of each sensor touch with no stand-in (among ``left``)."""
    groups = [g for g in problem.groups if g.points is not None]
    kappa2, left, found, without = 1.0, 0, [], []
    for g in (g for g in problem.groups if g.points is None):
        rows = Problem([g]).size // g.count  # each touch's rows
        for k in range(g.count):
            one = stand_in(g, k, threshold, problem.lever)
            if one is None or (problem.tolerance is not None and not one.own and not np.all(np.isfinite(one.places))):
                left += 1
                without.append((g, k))
                continue
            group = point_touches(one.feature, one.point, g.index[k:k + 1])
            left += Problem([group]).size < rows
            groups.append(group)
            kappa2 = min(kappa2, one.kappa2)
            found.append(one)
    return groups, kappa2, left, found, without


def stand_in(group, k, threshold, lever_mm):
    """Touch k of a sensor group's :class:`StandIn`, or None (module doc)."""
    ctype, feature = group.ctype, group.feature
    s, f = touch_side(group.sensor, group.count, k), touch_side(group.fixture, group.count, k)
    rho = float(group.rho[k])
    plain = is_point_sensor(group.sensor)
    name = f"{feature.id}#{int(group.index[k])}"
    if ctype.is_locus:
        return _on_a_known_line(group, s, rho, name, threshold, lever_mm)
    if ctype.sensor_fixed and ctype.fixture_fixed:
        # Both points known: they coincide, the gap turning about o; a radius mode moves the known point outward.
        kappa2 = _centred(0.0, threshold, lever_mm, plain)
        return kappa2 and StandIn(Point(name, f["o"]), s["o"][None], kappa2, feature, f["o"][None],
                                  f.get("u", np.zeros(3)))
    if ctype.sensor_fixed:
        if not element(ctype.sensor).surface:
            return StandIn(feature, s["o"][None], 1.0, feature)  # a probe's or a line's known point on the feature
        target = s["o"] + rho * s["u"]  # a radius mode moves it along the sensor's normal, off the element
        core = element(ctype.fixture).core
        if core == "point":
            centre = feature.core()[1]
            kappa2 = _centred(rho, threshold, lever_mm, plain)
            return kappa2 and StandIn(Point(name, centre), target[None], kappa2, feature, centre[None],
                                      sensor_move=-s["u"])
        if core == "plane":
            return StandIn(feature, target[None], 1.0, feature) if rho == 0.0 else None
        kappa2 = 1.0 / (1.0 + (rho / lever_mm) ** 2)
        if ctype.fixture == "L":
            return StandIn(feature, target[None], kappa2, feature)
        axis = _axis(name, feature, rho)
        return StandIn(axis, target[None], kappa2, feature, _corners(axis), sensor_move=-s["u"])
    if ctype.fixture_fixed and ctype.sensor == "S" and plain:
        if element(ctype.fixture).surface:  # the ball's centre at the offset point, which moves with the feature
            offset = f["o"] + rho * f["u"]
            return StandIn(Point(name, offset), s["c"][None], 1.0, feature, offset[None], f["u"])
        # A ball radius from the known point of an edge or a point (which have no radius).
        return StandIn(Sphere(name, f["o"], float(s["r"])), s["c"][None], 1.0, feature, f["o"][None])
    return None


def _on_a_known_line(group, s, rho, name, threshold, lever_mm):
    """A plane sensor with its contact line known (point ``o``, direction ``e``) under a cylinder or an edge:
    the point ``tau = o + rho n`` lies on the axis or the edge. Its rows are ``n.d``, ``n.(p - o) - rho``,
    ``d.f`` and ``f.(p - o)`` (``f = n x e``, ``p`` and ``d`` the axis's anchor and direction, tangency and
    pointwise rows left out), so with ``w = p - tau = r_2 n + r_4 f + lambda e`` and ``d = r_1 n + r_3 f + c
    e`` the distance of tau from the axis is ``|P_d w| <= |A r|``, ``A r = (r_2 - (lambda/c) r_1, r_4 -
    (lambda/c) r_3)`` (``P_d e = -P_d (r_1 n + r_3 f) / c``). Then ``cost >= |A r|^2 / lambda_max(A C
    A^T)``; ``A J_v`` has the orthonormal rows n and f, and ``A G`` is ``e`` times ``(|A r|_f, rho + |A
    r|_n)`` (a turn about o moves the anchor less ``lambda / c`` times the direction by the turn of ``(rho
    + ...) n + ... f``), so ``lambda_max <= 1 + (rho + |A r|)^2 / L^2``: the gap form of :func:`_centred`."""
    ctype, feature = group.ctype, group.feature
    if not (ctype.sensor == "PL" and ctype.sensor_fixed and ctype.fixture in ("C", "L") and "f" in s
            and abs(float(s["n"] @ (s["o"] - s["q"]))) <= 1e-9 * (1.0 + float(np.abs(s["o"]).max()))):
        return None
    kappa2 = _centred(rho, threshold, lever_mm, False)
    target = s["o"] + rho * s["n"]  # a radius mode moves it along the plane's normal, off the axis
    if not kappa2:
        return None
    if ctype.fixture == "L":
        return StandIn(feature, target[None], kappa2, feature)
    axis = _axis(name, feature, rho)
    return StandIn(axis, target[None], kappa2, feature, _corners(axis), sensor_move=-s["n"])


def deviation_bound_mm(tolerance, feature, places, q):
    """How far (mm) the printed feature's deviation can move a stand-in's rows, ``e = sqrt(q) max (sqrt(
    lambda_max(A_x^T S A_x)) + sqrt(s_r))`` over the places x: a mode moves the element at x by ``omega x x +
    v`` (the rows of ``A_x``), a radius mode moves the stand-in's point along a unit direction (``s_r`` the
    variance of the radius's change), and ``z^T S^-1 z <= q`` for the modes of a pose that passes (``S``
    their covariance), so each row vector moves by at most that. ``sqrt(lambda_max)`` of an affine map of x
    is convex in x: its largest over a box is at a corner."""
    s = tolerance.slices[feature.id]
    m = tolerance.modes[feature.id]
    S = tolerance.covariance[s, s]
    twist = np.where(m.radius[:, None], 0.0, m.twists)
    A = cross(twist[None, :, :3], np.asarray(places, float)[:, None]) + twist[None, :, 3:]  # (n, k, 3)
    radius = m.radius.astype(float)
    return float(np.sqrt(q) * (np.max(largest_move(A, S)) + np.sqrt(max(radius @ S @ radius, 0.0))))


def largest_move(A, S):
    """The largest move ``sqrt(lambda_max(A^T S A))`` of maps A (..., k, 3) from mode coordinates z to a vector,
    over ``z^T S^-1 z <= 1`` (S (k, k) the modes' covariance): times sqrt(q) for the modes of a pose that passes."""
    return np.sqrt(np.maximum(np.linalg.eigvalsh(np.swapaxes(A, -1, -2) @ S @ A)[..., -1], 0.0))


def _corners(feature):
    """The corners (8, 3) of the feature's patch box grown by ``PLACES_GROWTH_MM`` (infinite when unbounded)."""
    low, high = patch_box(feature)
    return box_corners(low - PLACES_GROWTH_MM, high + PLACES_GROWTH_MM)


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


def _centred(rho, threshold, lever_mm, plain):
    """kappa2 of a point that lies on a centre, with the gap as large as a pose that passes can have it
    (None when no gap of ``REACH_STEPS`` fails by itself)."""
    if plain:
        return 1.0
    root = float(np.sqrt(threshold))
    for step in REACH_STEPS:
        reach = step * root
        kappa2 = 1.0 / (1.0 + ((rho + reach) / lever_mm) ** 2)
        if reach**2 * kappa2 > threshold:
            return kappa2
    return None


def touch_side(side, count, k):
    """Touch k's geometry of a side of a group of ``count`` touches: {key: (3,) or scalar}, each key given once
    for the group or once a touch."""
    return {key: (np.broadcast_to(np.reshape(value, (-1, 3)), (count, 3)) if key in POINT_KEYS | DIRECTION_KEYS
                  else np.broadcast_to(np.reshape(value, -1), (count,)))[k] for key, value in side.geometry.items()}
