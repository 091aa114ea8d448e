"""Registration engine: the pose of a fixture from labelled touches.

A touch plan is a list of :class:`TouchGroup`: touches of one contact type on
one feature. Their residuals and twist Jacobians come from the contact model
(:mod:`.contacts`); nothing here re-derives contact geometry. The engine

1. initialises without a pose, from closed forms: a plane and a cylinder by
   the paper's Example Two steps; three or more sphere centres (each from
   three or more touches) by Kabsch; otherwise a plane's normal (from three
   touches, or a plane sensor) fixes one direction and a sweep about it, with
   the translation solved by batched Gauss-Newton (or from a sphere centre),
   seeds Levenberg-Marquardt; a nominal pose seeds it directly;
2. keeps every distinct converged pose whose residual passes a chi-square
   test and whose touches are admissible (inside their features' finite
   patches, touched from outside when the probe's approach is known);
3. names the status ``unique``, ``ambiguous`` (with the touch that best
   separates the candidates), ``inconsistent`` (with a touch flagged by a
   robust refit when one explains it) or ``underdetermined`` (with the free
   motions named relative to the features);
4. gives the pose covariance ``(J^T C^-1 J)^-1``, which at the true pose is
   the Cramer-Rao bound of the sensor noise model.

The sensor noise model: every touch is made by a sensor element placed with a
small random rigid error about its contact point, a translation of standard
deviation sigma (mm, each axis) and a rotation of sigma / lever (rad, each
axis; ``lever_mm``, by default ``SENSOR_LEVER_MM``). A point probe or a ball
tip is moved by the translation only, so its rows keep the iid noise sigma.
Moving the sensor by a twist is moving the fixture by the opposite twist, so
a touch's row covariance is ``C = J S J^T`` with J its rows' fixture twist
Jacobian and S the placement covariance (:func:`row_whitening`). Rows are
whitened touch by touch and scaled back to mm (covariance sigma^2 I):
Levenberg-Marquardt is then the maximum-likelihood estimator, the chi-square
test and ``rms_residual_mm`` use whitened rows, and the covariance is
``sigma^2 (J_w^T J_w)^-1``.

Covariances are over (rotation vector rad, fixture origin mm), both in the
measurement frame. This module imports numpy and scipy only and nothing of
fixturecad: it is inlined into the generated standalone ``register.py``.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy.special import gammaincinv

from .contacts import CORE, DIRECTION_KEYS, POINT_KEYS, ContactType, make_side, residuals_and_jacobian
from .pose import (
    apply_twist,
    check_fixture2meas,
    fixture2meas_from_rt,
    origin_error_map,
    rotation_aligning,
    rotation_angle,
    rotation_from_vector,
    random_rotation,
    skew,
)

DEFAULT_SIGMA_MM = 0.005  # touch noise standard deviation assumed by the chi-square test
SENSOR_LEVER_MM = 20.0  # sensor size: its placement tilts by sigma / lever rad about the contact point
CHI2_CONFIDENCE = 0.999  # residual test: a correct pose passes 999 times in 1000
EXTENT_TOLERANCE_MM = 0.2  # how far outside a feature's patch a touch may be judged to lie
EXTENT_SIGMAS = 3.0  # ... plus this many standard deviations of the touch's position under the pose
SWEEP_STEPS = 24  # angles tried about a measured plane normal when no pose is given
PLANE_CYLINDER_STEPS = 180  # axis directions tried on the cone about the plane normal
NORMAL_SWEEP_RAD = np.radians(2.0)  # plane touches this unsure of the normal (3 sigma) sweep it ...
NORMAL_SWEEP_STEPS = 60  # ... in this many turns about their line
CIRCLE_ITERATIONS = 6  # Gauss-Newton steps fitting a circle of the cylinder's radius to the touches
FALLBACK_STARTS = 48  # rotations tried when no plane gives a direction
UNSWEPT_PER_BLOCK = 6  # fallback starts per candidate centre refined before stopping at a solution
SAME_POSE_ROTATION_RAD = 1e-4
STEP_TOLERANCE = 1e-4  # LM stops once a step moves the touches less than this many sigma
STALLED_AFTER = 4  # LM iterations before a refinement may be abandoned as stalled ...
STALLED_COST_FACTOR = 1e4  # ... while its cost exceeds this many times sigma^2 per row ...
STALLED_DECREASE = 0.5  # ... and one iteration removes less than half of it
NEAR_KNOWN_RAD = 1e-3  # a refinement this close to a found solution is converging onto it
NEAR_KNOWN_MM = 0.05
SAME_POSE_TRANSLATION_MM = 1e-3
RANK_TOLERANCE = 1e-7  # singular values below this fraction of the largest count as zero


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

    @property
    def count(self) -> int:
        return len(self.index)


def fixture_side(feature, fixed: bool, **extra):
    """The contact-model side of a feature in the fixture frame."""
    kind = feature.kind
    if kind == "plane":
        return make_side("PL", fixed, q=feature.point, n=feature.normal, **extra)
    if kind == "sphere":
        return make_side("S", fixed, c=feature.center, r=feature.radius, **extra)
    if kind == "cylinder":
        return make_side("C", fixed, p=feature.point, d=feature.axis, r=feature.radius, **extra)
    if kind == "line":
        return make_side("L", fixed, p=feature.point, d=feature.direction, **extra)
    return make_side("P", True, c=feature.point, o=feature.point, **extra)


def point_touches(feature, points, index, ball_radius_mm=0.0) -> TouchGroup:
    """Point-probe touches (ball radius 0) or ball-tip centres on a feature."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = len(points)
    fixture_element = feature.element
    fixture_fixed = feature.kind == "point"
    if ball_radius_mm > 0.0:
        ctype = ContactType("S", False, fixture_element, fixture_fixed)
        sensor = make_side("S", False, c=points, r=np.full(n, ball_radius_mm))
        offset = {"plane": ball_radius_mm, "line": ball_radius_mm, "point": 0.0}
        rho = offset.get(feature.kind, getattr(feature, "radius", 0.0) + ball_radius_mm)
    else:
        ctype = ContactType("P", True, fixture_element, fixture_fixed)
        sensor = make_side("P", True, c=points, o=points)
        rho = 0.0
    return TouchGroup(
        feature, ctype, sensor, fixture_side(feature, fixture_fixed), np.full(n, float(rho)),
        np.asarray(index), points, centre=points,
    )


def placement_centre(kind, geometry, contact_point=None):
    """The point (..., 3) mm a sensor's placement error turns about: its contact point.

    A point probe's point or a ball tip's centre (turning about it moves
    nothing); otherwise the known contact point ``o``, the given
    ``contact_point``, or the sensor's own point (``q`` of a plane, ``p`` of a
    line or a cylinder).
    """
    if kind == "P" or (kind == "S" and "o" not in geometry):
        return geometry["c"]
    if "o" in geometry:
        return geometry["o"]
    if contact_point is not None:
        return np.asarray(contact_point, dtype=np.float64)
    return geometry["q" if CORE[kind] == "plane" else ("c" if CORE[kind] == "point" else "p")]


def row_whitening(jacobian, centres, lever_mm=SENSOR_LEVER_MM):
    """Per-touch whitening of the rows under the sensor noise model, shape (N, k, k).

    ``jacobian`` (N, k, 6): the rows' twist Jacobian of each touch (twists
    about the frame origin); ``centres`` (N, 3) mm: the sensor placement
    centres in the same frame. The placement error (translation sigma,
    rotation sigma / lever about the centre) is the twist ``A (dtheta, delta)``
    with ``A = [[I, 0], [skew(o), I]]``; the row covariance is
    ``sigma^2 (G G^T / lever^2 + J_v J_v^T)``, ``G = J_w + J_v skew(o)``. The
    whitening W = L^-1 (``C / sigma^2 = L L^T``) makes ``W r`` of covariance
    sigma^2 I; it does not depend on sigma.
    """
    J = np.asarray(jacobian, dtype=np.float64)
    o = np.broadcast_to(centres, (J.shape[0], 3))
    Jw, Jv = J[..., :3], J[..., 3:]
    # J_v skew(o): row j times skew(o) is o x j reversed, i.e. cross(j, o).
    G = Jw + np.cross(Jv, o[:, None, :])
    C = np.einsum("nki,nli->nkl", G, G) / lever_mm**2 + np.einsum("nki,nli->nkl", Jv, Jv)
    k = C.shape[-1]
    if k == 1:
        return 1.0 / np.sqrt(np.maximum(C, 1e-300))
    scale = np.maximum(np.einsum("nkk->n", C) / k, 1e-300)[:, None, None]
    L = np.linalg.cholesky(C + 1e-12 * scale * np.eye(k))
    return np.linalg.inv(L)


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
        kind = sensor["kind"]
        names = {"plane": {"point": "q", "normal": "n"}, "line": {"point": "p", "direction": "d"},
                 "sphere": {"center": "c", "radius": "r"}, "cylinder": {"point": "p", "axis": "d", "radius": "r"},
                 "point": {"point": "c"}}
        if kind not in names:
            raise ValueError(f"unknown sensor kind {kind!r}; choose from {', '.join(names)}")
        geometry = {names[kind][key]: np.asarray(value, dtype=np.float64)
                    for key, value in sensor.items() if key in names[kind]}
        for key in ("n", "d"):
            if key in geometry:
                geometry[key] = geometry[key] / np.linalg.norm(geometry[key])
    if ctype.sensor_fixed and "o" not in geometry:
        if contact_point is None:
            if ctype.sensor != "P":
                raise ValueError(f"a fixed {ctype.sensor} sensor needs its contact point")
            contact_point = geometry["c"]
        geometry["o"] = np.asarray(contact_point, dtype=np.float64)
    return geometry


def contact_touch(feature, contact: str, sensor: dict, index: int, rho=None, fixture=None,
                  contact_point=None) -> TouchGroup:
    """One touch of any contact type: the sensor element's geometry in the measurement frame.

    ``sensor`` see :func:`sensor_geometry`; ``fixture`` optional extra
    fixture-frame keys of a fixed fixture side (its known contact point ``o``).
    ``rho`` (mm) defaults to the sum of the radii of the two elements, the
    offset of two convex elements touching from outside (a ball tip on a
    plane: its radius; on a sphere: both radii; a plane sensor on a cylinder:
    the cylinder's radius).
    """
    ctype = ContactType.parse(contact)
    if ctype.fixture != feature.element:
        raise ValueError(
            f"contact {contact} touches a {ctype.fixture} element but feature {feature.id} is a {feature.kind}"
        )
    geometry = {key: value[None] for key, value in sensor_geometry(ctype, sensor, contact_point).items()}
    side = make_side(ctype.sensor, ctype.sensor_fixed, **geometry)
    extra = {key: np.asarray(value, dtype=np.float64) for key, value in (fixture or {}).items()}
    if ctype.fixture_fixed and "o" in extra and "u" not in extra and feature.kind in ("plane", "sphere", "cylinder"):
        extra["u"] = feature.normal_at(extra["o"])[0]
    fside = fixture_side(feature, ctype.fixture_fixed, **extra)
    if rho is None:
        rho = float(np.reshape(geometry.get("r", 0.0), -1)[0]) + float(getattr(feature, "radius", 0.0))
    centre = placement_centre(ctype.sensor, geometry, None if contact_point is None else np.reshape(contact_point, (1, 3)))
    return TouchGroup(feature, ctype, side, fside, np.array([float(rho)]), np.array([index]), centre=centre)


class Problem:
    """A stacked touch plan: whitened residuals (m,) and twist Jacobian (m, 6) at any pose.

    Rows are whitened touch by touch under the sensor noise model
    (:func:`row_whitening`, at the pose evaluated) and stay in mm: their
    covariance is ``sigma_mm^2 I``.
    """

    def __init__(self, groups, sigma_mm=DEFAULT_SIGMA_MM, lever_mm=SENSOR_LEVER_MM, tolerance=None):
        if not (lever_mm > 0 and np.isfinite(lever_mm)):
            raise ValueError(f"the sensor lever must be a positive number of mm, got {lever_mm}")
        self.groups = [g if g.centre is not None else _with_centre(g) for g in groups if g.count]
        self.sigma = float(sigma_mm)
        self.lever = float(lever_mm)
        self._scale = None
        # Rows are computed per contact type: groups of one type on different
        # features are stacked into one call of the contact model.
        self.batches = _merge(self.groups)
        self.tolerance = tolerance if tolerance is not None and tolerance.size else None
        self._row_feature = None

    def sensor_rows(self, rotation, translation, grow=0.0):
        """Rows and Jacobian whitened for the sensor noise only (the fixture's deviations left in)."""
        values, jacobians = [], []
        for g in self.batches:
            fixture, rho = g.fixture, g.rho
            if grow and "r" in fixture.geometry:
                # A grown sphere or cylinder: its radius, and the offset of the touches that include it.
                fixture = type(fixture)(fixture.kind, fixture.fixed, {**fixture.geometry, "r": fixture["r"] + grow})
                rho = rho + grow
            v, J = residuals_and_jacobian(g.ctype, g.sensor, fixture, rotation, translation, rho)
            g.rows = v.shape[1]
            if not _point_sensor(g.sensor):
                v, J = _whitened(v, J, g.centre, self.lever)
            values.append(v.reshape(-1))
            jacobians.append(J.reshape(-1, 6))
        return np.concatenate(values), np.concatenate(jacobians)

    def evaluate(self, rotation, translation):
        r, J = self.sensor_rows(rotation, translation)
        if self.tolerance is None:
            return r, J
        from scipy.linalg import cholesky, solve_triangular
        from .deviations import deviation_rows

        Jd = deviation_rows(self, self.tolerance, rotation, translation, J)
        C = np.eye(len(r)) + Jd @ self.tolerance.covariance @ Jd.T / self.sigma**2
        L = cholesky(C, lower=True)
        return solve_triangular(L, r, lower=True), solve_triangular(L, J, lower=True)

    def radius_derivative(self, rotation, translation, step=1e-4):
        """How each (whitened) row changes as its feature's radius grows, shape (m,) per mm."""
        grown = self.sensor_rows(rotation, translation, step)[0]
        shrunk = self.sensor_rows(rotation, translation, -step)[0]
        return (grown - shrunk) / (2 * step)

    @property
    def row_feature(self):
        """The feature id of every row of ``evaluate``, shape (m,)."""
        if self._row_feature is None:
            feature_of = {int(i): g.feature.id for g in self.groups for i in g.index}
            self._row_feature = np.array([feature_of[int(i)] for i in self.row_touch])
        return self._row_feature

    def _count_rows(self):
        if any(not g.rows for g in self.batches):
            self.sensor_rows(np.eye(3), np.zeros(3))

    @property
    def row_touch(self):
        """The touch index of every row of ``evaluate``, shape (m,)."""
        self._count_rows()
        if not self.batches:
            return np.zeros(0, int)
        return np.concatenate([np.repeat(g.index, g.rows) for g in self.batches])

    @property
    def size(self):
        """Number of rows m."""
        self._count_rows()
        return int(sum(g.rows * g.count for g in self.batches))

    def evaluate_batch(self, rotations, translations):
        """Residuals (K, m) and fixture-frame Jacobians (K, m, 6) at K poses in one call.

        Each pose's sensors are mapped into the fixture frame (``R^T (x - t)``),
        all K copies stacked into one call of the contact model at the identity.
        The translation columns give the fixture-frame translation ``v`` that
        moves the pose to ``t + R v``.
        """
        K = len(rotations)
        values, jacobians = [], []
        for g in self.groups:
            geometry = {}
            for key, value in g.sensor.geometry.items():
                value = np.broadcast_to(value, (g.count,) + np.shape(value)[1:] if np.ndim(value) else (g.count,))
                if key in POINT_KEYS:
                    moved = np.einsum("kji,knj->kni", rotations, value[None] - translations[:, None])
                elif key in DIRECTION_KEYS:
                    moved = np.einsum("kji,knj->kni", rotations, np.broadcast_to(value, (K,) + value.shape))
                else:
                    moved = np.broadcast_to(value, (K,) + value.shape)
                geometry[key] = moved.reshape((K * g.count,) + moved.shape[2:])
            sensor = type(g.sensor)(g.sensor.kind, g.sensor.fixed, geometry)
            v, J = residuals_and_jacobian(g.ctype, sensor, g.fixture, np.eye(3), np.zeros(3), np.tile(g.rho, K))
            if not _point_sensor(g.sensor):
                centres = np.einsum("kji,knj->kni", rotations, g.centre[None] - translations[:, None])
                v, J = _whitened(v, J, centres.reshape(-1, 3), self.lever)
            values.append(v.reshape(K, -1))
            jacobians.append(J.reshape(K, -1, 6))
        return np.concatenate(values, axis=1), np.concatenate(jacobians, axis=1)

    def without(self, touch):
        """The plan with one touch (by caller index) left out."""
        groups = []
        for g in self.groups:
            keep = g.index != touch
            if keep.all():
                groups.append(g)
            elif keep.any():
                groups.append(_subset(g, keep))
        return Problem(groups, self.sigma, self.lever, self.tolerance)

    def scale(self):
        """A length (mm) that balances rotation and translation columns of the Jacobian."""
        if self._scale is None:
            pts = [g.points for g in self.groups if g.points is not None]
            self._scale = 1.0
            if pts:
                pts = np.concatenate(pts)
                self._scale = max(float(np.sqrt(np.mean(np.sum((pts - pts.mean(0)) ** 2, axis=1)))), 1.0)
        return self._scale


def _with_centre(group):
    """The group with its sensor placement centres filled in from the sensor's geometry."""
    centre = placement_centre(group.sensor.kind, group.sensor.geometry)
    group.centre = np.broadcast_to(np.asarray(centre, dtype=np.float64), (group.count, 3)).copy()
    return group


def _point_sensor(side):
    """A point probe or a ball tip: only shifted by its placement error, its rows' gradients
    along it orthonormal, so :func:`row_whitening` is the identity and is skipped."""
    return side.kind == "P" or (side.kind == "S" and "o" not in side.geometry)


def _whitened(values, jacobian, centres, lever_mm):
    """Rows (N, k) and Jacobian (N, k, 6) whitened touch by touch (:func:`row_whitening`)."""
    W = row_whitening(jacobian, centres, lever_mm)
    if W.shape[-1] == 1:
        return values * W[..., 0], jacobian * W
    return np.einsum("nkl,nl->nk", W, values), np.einsum("nkl,nlc->nkc", W, jacobian)


def _merge(groups):
    """Groups of one contact type stacked into one, fixture geometry repeated per touch."""
    by_type = {}
    for g in groups:
        key = (g.ctype, tuple(sorted(g.sensor.geometry)), tuple(sorted(g.fixture.geometry)))
        by_type.setdefault(key, []).append(g)
    batches = []
    for members in by_type.values():
        if len(members) == 1:
            batches.append(members[0])
            continue
        first = members[0]
        sensor = {key: np.concatenate([np.asarray(m.sensor.geometry[key]) for m in members])
                  for key in first.sensor.geometry}
        fixture = {}
        for key in first.fixture.geometry:
            parts = []
            for m in members:
                value = np.asarray(m.fixture.geometry[key])
                parts.append(np.broadcast_to(value, (m.count,) + value.shape))
            fixture[key] = np.concatenate(parts)
        batches.append(TouchGroup(
            None, first.ctype, type(first.sensor)(first.sensor.kind, first.sensor.fixed, sensor),
            type(first.fixture)(first.fixture.kind, first.fixture.fixed, fixture),
            np.concatenate([m.rho for m in members]), np.concatenate([m.index for m in members]),
            centre=np.concatenate([np.broadcast_to(m.centre, (m.count, 3)) for m in members]),
        ))
    return batches


def _subset(group, keep):
    def cut(side):
        geometry = {}
        for key, value in side.geometry.items():
            value = np.asarray(value)
            geometry[key] = value[keep] if value.ndim >= 1 and value.shape[0] == len(keep) else value
        return type(side)(side.kind, side.fixed, geometry)

    sensor = cut(group.sensor)
    rho = group.rho[keep]
    points = None if group.points is None else group.points[keep]
    return TouchGroup(group.feature, group.ctype, sensor, group.fixture, rho, group.index[keep], points, group.rows,
                      centre=group.centre[keep])


def levenberg_marquardt(problem, rotation, translation, weights=None, max_iterations=60, known=(),
                        may_give_up=True):
    """Minimise the (weighted) sum of squared rows from a pose; return R, t, residuals, Jacobian.

    ``known`` poses (R, t): stop early once the iterate comes close to one of
    them (it is falling into a basin already explored). ``may_give_up``:
    stop when the cost stalls far above any acceptable residual.
    """
    r, J = problem.evaluate(rotation, translation)
    w = np.ones(len(r)) if weights is None else weights
    cost = float(np.sum(w * r * r))
    hopeless = STALLED_COST_FACTOR * problem.sigma**2 * max(len(r), 1)
    length = problem.scale()
    lam = 1e-4
    for iteration in range(max_iterations):
        Jw = J * w[:, None]
        A = J.T @ Jw
        g = Jw.T @ r
        diag = np.diag(A).copy()
        diag[diag < 1e-12 * max(diag.max(), 1e-300)] = max(diag.max(), 1.0) * 1e-12
        improved = False
        for _ in range(12):
            step = -np.linalg.solve(A + lam * np.diag(diag), g)
            R2, t2 = apply_twist(rotation, translation, step)
            r2, J2 = problem.evaluate(R2, t2)
            cost2 = float(np.sum(w * r2 * r2))
            if cost2 <= cost:
                improved = True
                break
            lam *= 8.0
        if not improved:
            break
        small = np.linalg.norm(step[:3]) * length + np.linalg.norm(step[3:]) < STEP_TOLERANCE * problem.sigma
        tiny = cost - cost2 <= 1e-16 * max(cost, 1e-30) + 1e-30
        stalled = may_give_up and iteration >= STALLED_AFTER and cost2 > hopeless and cost2 > STALLED_DECREASE * cost
        rotation, translation, r, J, cost = R2, t2, r2, J2, cost2
        lam = max(lam / 10.0, 1e-9)
        if small or tiny or stalled:
            break
        for R_known, t_known in known:
            if rotation_angle(rotation @ R_known.T) < NEAR_KNOWN_RAD and np.linalg.norm(translation - t_known) < NEAR_KNOWN_MM:
                return R_known, t_known, r, J
    return rotation, translation, r, J


def _plane_normal(points):
    """Closed form: unit normal of the plane through points (n >= 3), or None if collinear."""
    centred = points - points.mean(axis=0)
    _, s, vt = np.linalg.svd(centred, full_matrices=False)
    if len(s) < 3 or s[1] < 1e-6 * max(s[0], 1e-12) or s[1] < 1e-6:
        return None
    return vt[2]


def sphere_centres(points, radius):
    """Closed form: candidate centres of a sphere of known radius through points (n >= 3)."""
    points = np.asarray(points, float)
    if len(points) >= 4:
        A = np.hstack([2.0 * points, np.ones((len(points), 1))])
        b = np.sum(points**2, axis=1)
        sol, _, rank, _ = np.linalg.lstsq(A, b, rcond=None)
        if rank == 4:
            return [sol[:3]]
    a, b, c = points[:3]
    n = np.cross(b - a, c - a)
    if np.linalg.norm(n) < 1e-9:
        return []
    # Circumcentre of the three points, then up and down the normal to the radius.
    ab, ac = b - a, c - a
    centre = a + (np.cross(n, ab) * (ac @ ac) + np.cross(ac, n) * (ab @ ab)) / (2.0 * (n @ n))
    rc = np.linalg.norm(centre - a)
    if rc > radius:
        return [centre]
    h = np.sqrt(radius**2 - rc**2)
    u = n / np.linalg.norm(n)
    return [centre + h * u, centre - h * u]


def _plane_directions(problem):
    """(fixture normal, measured normal up to sign) pairs, best determined first.

    Closed forms: a sensing plane lying on a fixture plane gives the normal
    directly; three or more point or ball touches on a plane give it by a fit.
    """
    pairs = []
    for g in problem.groups:
        if g.feature.kind != "plane":
            continue
        if g.ctype.sensor == "PL" and g.ctype.is_locus:
            pairs.append((np.inf, g.feature.normal, g.sensor["n"].reshape(-1, 3)[0]))
        elif g.points is not None and g.count >= 3:
            n_meas = _plane_normal(g.points)
            if n_meas is not None:
                pairs.append((g.count, g.feature.normal, n_meas))
    pairs.sort(key=lambda item: -item[0])
    return [(a, b) for _, a, b in pairs]


def _anchor(feature):
    for name in ("center", "point"):
        if hasattr(feature, name):
            return np.asarray(getattr(feature, name), float)
    return np.zeros(3)


def initial_poses(problem):
    """Candidate starting poses (R, t) without a nominal pose: closed forms, then sweeps.

    Returns (starts, blocks, mode): the starts come in ``blocks`` equal
    blocks (one per candidate sphere centre); ``mode`` is "closed" (closed
    forms), "sweep" (each block made of sweeps of ``SWEEP_STEPS`` rotations
    about a measured direction) or "random" (no direction known).
    """
    starts = plane_cylinder_starts(problem)
    if starts:
        return starts, len(starts), "closed"
    point_groups = [g for g in problem.groups if g.points is not None]
    centres = _sphere_centre_candidates(point_groups)
    rotations = []
    for n_fix, n_meas in _plane_directions(problem):
        for sign in (1.0, -1.0):
            R0 = rotation_aligning(n_fix, sign * n_meas)
            for k in range(SWEEP_STEPS):
                angle = 2.0 * np.pi * k / SWEEP_STEPS
                rotations.append(rotation_from_vector(angle * n_meas) @ R0)
        break
    if len(centres) >= 3 and not rotations:
        # Closed form: Kabsch on three or more sphere centres, one start per candidate set.
        fixed = np.array([f for f, _ in centres])
        starts = []
        for combo in _combinations([m for _, m in centres]):
            R, t = kabsch(fixed, np.array(combo))
            if R is not None:
                starts.append((R, t))
        if starts:
            return starts, len(starts), "closed"
    if len(centres) >= 2 and not rotations:
        # The line through two sphere centres fixes a direction: sweep about it.
        (f1, m1), (f2, m2) = centres[:2]
        for c1 in m1:
            for c2 in m2:
                axis = (c2 - c1) / max(np.linalg.norm(c2 - c1), 1e-12)
                R0 = rotation_aligning(f2 - f1, axis)
                for k in range(SWEEP_STEPS):
                    rotations.append(rotation_from_vector(2.0 * np.pi * k / SWEEP_STEPS * axis) @ R0)
    mode = "sweep" if rotations else "random"
    if not rotations:
        rng = np.random.default_rng(0)
        rotations = [random_rotation(rng) for _ in range(FALLBACK_STARTS)]
    if point_groups:
        measured = np.concatenate([g.points for g in point_groups]).mean(axis=0)
        anchors = np.concatenate([np.tile(_anchor(g.feature), (g.count, 1)) for g in point_groups]).mean(axis=0)
    else:
        measured = anchors = np.zeros(3)
    if centres:
        # Translation in closed form from each candidate centre of a sphere.
        f, ms = centres[0]
        return [(R, m - R @ f) for m in ms for R in rotations], len(ms), mode
    return [(R, measured - R @ anchors) for R in rotations], 1, mode


def plane_cylinder_starts(problem, steps=PLANE_CYLINDER_STEPS, keep=4):
    """Starting poses by the paper's Example Two steps (a plane and a cylinder, point touches).

    1. the plane normal from three or more touches (closed form, either sign);
       touches nearly on a line leave its turn about that line open, so it is
       also swept all the way round;
    2. the cylinder axis on the cone of the known plane-axis angle about that
       normal, where the touches best fit a circle of the known radius in the
       plane normal to it (a one-angle search, the best local minima kept);
       touches on a short arc fit two such circles, mirror images across
       their chord, each searched;
    3. a point on the axis from that circle's centre;
    4. the frame from normal and axis, its origin where the axis meets the plane.
    """
    def point_group(kind):
        found = [g for g in problem.groups
                 if g.points is not None and g.feature.kind == kind and g.ctype.sensor == "P" and g.count >= 3]
        return max(found, key=lambda g: g.count) if found else None

    plane, cylinder = point_group("plane"), point_group("cylinder")
    if plane is None or cylinder is None:
        return []
    n_meas = _plane_normal(plane.points)
    n_fix, a_fix = plane.feature.normal, cylinder.feature.axis
    cos_a = float(n_fix @ a_fix)
    if n_meas is None or abs(cos_a) > 0.999 or abs(cos_a) < 1e-3:
        return []
    from .contacts import perpendicular_basis

    sin_a = np.sqrt(1.0 - cos_a**2)
    radius, pts = cylinder.feature.radius, cylinder.points
    theta = np.linspace(0.0, 2.0 * np.pi, steps, endpoint=False)
    # The fixture's origin of the frame: where its axis meets its plane.
    origin_fix = cylinder.feature.point + ((plane.feature.point - cylinder.feature.point) @ n_fix / cos_a) * a_fix
    frame_fix = _frame(n_fix, a_fix)
    step = 2.0 * np.pi / steps

    def circle_fits(n, e1, e2, theta):
        """Axis directions, in-plane bases, circle centres and misfit for axis angles theta."""
        axes = cos_a * n + sin_a * (np.cos(theta)[:, None] * e1 + np.sin(theta)[:, None] * e2)
        u1, u2 = perpendicular_basis(axes)
        q = np.stack([pts @ u1.T, pts @ u2.T], axis=-1).transpose(1, 0, 2)  # (K, n, 2)
        # Circle through the touches in each axis' normal plane: 2 q.c + k = |q|^2, linear in (c, k).
        A = np.concatenate([2.0 * q, np.ones(q.shape[:2] + (1,))], axis=2)
        b = np.sum(q**2, axis=2)
        gram = np.einsum("kni,knj->kij", A, A) + 1e-12 * np.eye(3)
        centre = np.linalg.solve(gram, np.einsum("kni,kn->ki", A, b)[..., None])[:, :2, 0]
        # Touches on a short arc fix that circle poorly: its mirror image across
        # the touches' chord line is the twin centre. Both are refined to the known
        # radius (Gauss-Newton); centres (K, 2, 2), misfits (K, 2): index 0 the
        # centre on the side of the chord line the plane normal points to.
        mean = q.mean(axis=1)
        x = q - mean[:, None]
        chord = 0.5 * np.arctan2(2.0 * np.sum(x[..., 0] * x[..., 1], axis=1),
                                 np.sum(x[..., 0] ** 2 - x[..., 1] ** 2, axis=1))
        w = np.stack([-np.sin(chord), np.cos(chord)], axis=1)  # normal to the chord line
        w = w * np.where(w[:, :1] * (u1 @ n)[:, None] + w[:, 1:] * (u2 @ n)[:, None] < 0, -1.0, 1.0)
        mirror = centre - 2.0 * np.einsum("ki,ki->k", centre - mean, w)[:, None] * w
        centres = np.stack([centre, mirror], axis=1)
        for _ in range(CIRCLE_ITERATIONS):
            d = centres[:, :, None] - q[:, None]  # (K, 2, n, 2)
            length = np.maximum(np.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2), 1e-12)
            jx, jy = d[..., 0] / length, d[..., 1] / length
            res = length - radius
            # The 2x2 normal equations solved in closed form.
            a, b, c = np.sum(jx * jx, 2) + 1e-9, np.sum(jx * jy, 2), np.sum(jy * jy, 2) + 1e-9
            gx, gy = np.sum(jx * res, 2), np.sum(jy * res, 2)
            det = a * c - b * b
            centres = centres - np.stack([c * gx - b * gy, a * gy - b * gx], axis=-1) / det[..., None]
        flip = np.einsum("kci,ki->kc", centres - mean[:, None], w)[:, 0] < 0
        centres[flip] = centres[flip][:, ::-1]
        cost = np.sum((np.linalg.norm(centres[:, :, None] - q[:, None], axis=3) - radius) ** 2, axis=2)
        return axes, u1, u2, centres, cost

    normal_sets = [[n_meas], [-n_meas]]
    # Touches nearly on a line fix the normal only up to a turn about that
    # line: sweep it all the way round as well (a flipped normal is a half turn).
    _, spread, vt = np.linalg.svd(plane.points - plane.points.mean(axis=0), full_matrices=False)
    if EXTENT_SIGMAS * problem.sigma > NORMAL_SWEEP_RAD * spread[1]:
        turns = 2.0 * np.pi * np.arange(NORMAL_SWEEP_STEPS) / NORMAL_SWEEP_STEPS
        normal_sets.append([rotation_from_vector(a * vt[0]) @ n_meas for a in turns])
    starts = []
    for normals in normal_sets:
        bases = [perpendicular_basis(n) for n in normals]
        theta = np.arange(steps) * step
        costs = np.array([circle_fits(n, e1, e2, theta)[4] for n, (e1, e2) in zip(normals, bases)])  # (P, K, 2)
        # Local minima of either centre's misfit over the axis angle (and the
        # normal's turn when swept), the best ``keep`` (twice that when swept).
        found = []
        for c in range(2):
            cost = costs[..., c]
            low = np.ones(cost.shape, bool)
            for axis in (0, 1):
                for shift in (1, -1):
                    low &= cost <= np.roll(cost, shift, axis=axis)
            for j, k in zip(*np.nonzero(low)):
                if c and abs(costs[j, k, 1] - costs[j, k, 0]) < 1e-12 * max(costs[j, k, 0], 1e-300) + 1e-15:
                    continue  # both centres the same: found once
                # A parabola through the minimum and its neighbours refines the angle.
                before, after = cost[j, k - 1], cost[j, (k + 1) % steps]
                curvature = before - 2.0 * cost[j, k] + after
                shift = 0.5 * (before - after) / curvature if curvature > 0 else 0.0
                found.append((cost[j, k], j, theta[k] + step * float(np.clip(shift, -1.0, 1.0)), c))
        chosen = sorted(found)[:keep * (1 if len(normals) == 1 else 2)]
        for j in sorted({j for _, j, _, _ in chosen}):
            n = normals[j]
            picks = [(angle, c) for _, jj, angle, c in chosen if jj == j]
            axes, u1, u2, centres, _ = circle_fits(n, *bases[j], np.array([angle for angle, _ in picks]))
            for k, (_, c) in enumerate(picks):
                s = axes[k]
                R = _frame(n, s) @ frame_fix.T
                on_axis = centres[k, c, 0] * u1[k] + centres[k, c, 1] * u2[k]
                along = n @ (plane.points.mean(axis=0) - on_axis) / (n @ s)
                starts.append((R, on_axis + along * s - R @ origin_fix))
    return starts


def _frame(normal, axis):
    """Orthonormal frame (3, 3), columns: the normal, the axis made perpendicular to it, their cross."""
    second = axis - (axis @ normal) * normal
    second /= np.linalg.norm(second)
    return np.column_stack([normal, second, np.cross(normal, second)])


def _sphere_centre_candidates(point_groups):
    """(fixture centre, [measured centre candidates]) of touched spheres, best determined first."""
    out = []
    for g in point_groups:
        if g.feature.kind == "sphere" and g.count >= 3:
            radius = g.rho[0] if g.ctype.sensor == "S" else g.feature.radius
            candidates = sphere_centres(g.points, radius)
            if candidates:
                out.append((len(candidates), g.feature.center, candidates))
    out.sort(key=lambda item: item[0])
    return [(f, m) for _, f, m in out]


def _combinations(lists, limit=16):
    combos = [[]]
    for options in lists:
        combos = [c + [o] for c in combos for o in options][:limit]
    return combos


def kabsch(fixed_points, measured_points):
    """Closed form: the rotation and translation best mapping fixture points onto measured ones."""
    a, b = np.asarray(fixed_points, float), np.asarray(measured_points, float)
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    H = (a - ca).T @ (b - cb)
    U, S, Vt = np.linalg.svd(H)
    if S[1] < 1e-9 * max(S[0], 1e-300):
        return None, None
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cb - R @ ca


def _same_pose(a, b):
    return (
        rotation_angle(a[0] @ b[0].T) < SAME_POSE_ROTATION_RAD
        and np.linalg.norm(a[1] - b[1]) < SAME_POSE_TRANSLATION_MM
    )


@dataclass
class Solution:
    rotation: np.ndarray
    translation: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray
    rank: int = 6
    passes: bool = True
    admissible: bool = True
    outside: list = field(default_factory=list)

    @property
    def fixture2meas(self):
        return fixture2meas_from_rt(self.rotation, self.translation)

    @property
    def cost(self):
        return float(self.residuals @ self.residuals)

    @property
    def rms(self):
        return float(np.sqrt(np.mean(self.residuals**2))) if len(self.residuals) else 0.0


def jacobian_rank(jacobian, length):
    """Rank of a stacked Jacobian with rotation columns scaled by ``length`` mm."""
    if len(jacobian) == 0:
        return 0
    scaled = jacobian / np.array([length] * 3 + [1.0] * 3)
    s = np.linalg.svd(scaled, compute_uv=False)
    return int(np.sum(s > RANK_TOLERANCE * max(s[0], 1e-300)))


def chi_square_quantile(probability, dof):
    """The chi-square quantile (scipy.stats.chi2.ppf without importing scipy.stats)."""
    return 2.0 * float(gammaincinv(0.5 * dof, probability))


def chi_square_passes(cost, rows, rank, sigma):
    dof = max(rows - rank, 1)
    return cost / sigma**2 <= chi_square_quantile(CHI2_CONFIDENCE, dof)


def inadmissible(problem, rotation, translation, jacobian=None, tolerance=EXTENT_TOLERANCE_MM):
    """Touch indices that cannot have happened at this pose.

    A touch is inadmissible when its contact, mapped into the fixture frame,
    lies off the feature's finite patch, or when the probe's approach
    direction (if known) points along the outward surface normal there. With
    the Jacobian, the patch is widened by three standard deviations of where
    the pose puts each touch, so a poorly determined pose is not refused for
    its own uncertainty.
    """
    twist_cov = None
    if jacobian is not None:
        F = jacobian.T @ jacobian
        if np.linalg.cond(F) < 1e14:
            twist_cov = problem.sigma**2 * np.linalg.inv(F)
    bad = set()
    for g in problem.groups:
        if g.points is None:
            continue
        local = (g.points - translation) @ rotation
        slack = tolerance
        if twist_cov is not None:
            # A spatial twist moves the touch's fixture point p by omega x p + v.
            spread = np.zeros(len(g.points))
            for k, point in enumerate(g.points):
                J = np.hstack([-skew(point), np.eye(3)])
                spread[k] = np.sqrt(max(np.trace(J @ twist_cov @ J.T), 0.0))
            slack = tolerance + EXTENT_SIGMAS * spread
        inside = np.asarray(g.feature.contains(local, slack))
        bad.update(int(i) for i in g.index[~inside])
        if g.approach is not None and g.feature.kind in ("plane", "sphere", "cylinder"):
            outward = g.feature.normal_at(local) @ rotation.T
            away = np.einsum("ij,ij->i", outward, g.approach) > 0.0
            bad.update(int(i) for i in g.index[away & np.all(np.isfinite(g.approach), axis=1)])
    return sorted(bad)


def solve(problem, initial_pose=None, batch=6):
    """All distinct local solutions from the starts, best first (list of Solution).

    Starts are refined ``batch`` at a time, best predicted first, until one
    batch yields an admissible solution that passes the residual test.
    """
    if initial_pose is not None:
        T = check_fixture2meas(initial_pose)
        starts, first_batch, mode = [(T[:3, :3], T[:3, 3])], 1, "nominal"
    else:
        starts, first_batch, mode = _best_starts(problem, *initial_poses(problem))
    length = problem.scale()
    solutions = []
    # The first batch holds every local minimum of the sweep: all solutions are looked for.
    bounds = [0, max(first_batch, 1)]
    while bounds[-1] < len(starts):
        bounds.append(bounds[-1] + batch)
    for first, last in zip(bounds[:-1], bounds[1:]):
        for R, t in starts[first:last]:
            known = [(s.rotation, s.translation) for s in solutions]
            # Far starts (no sweep) may take many slow steps: never abandon them.
            R, t, r, J = levenberg_marquardt(problem, R, t, known=known, may_give_up=mode != "random")
            if any(_same_pose((R, t), pose) for pose in known):
                continue
            solutions.append(_judged(problem, Solution(R, t, r, J), length))
        if any(s.passes and s.admissible for s in solutions):
            break
    # Closed-form alternatives: a sphere touched three times has two candidate
    # centres; re-seed each solution with the other one.
    point_groups = [g for g in problem.groups if g.points is not None]
    for f, ms in _sphere_centre_candidates(point_groups):
        if len(ms) < 2:
            continue
        for found in [s for s in solutions if s.passes and s.admissible]:
            for m in ms:
                R, t = found.rotation, m - found.rotation @ f
                if np.linalg.norm(t - found.translation) < SAME_POSE_TRANSLATION_MM:
                    continue
                known = [(s.rotation, s.translation) for s in solutions]
                R, t, r, J = levenberg_marquardt(problem, R, t, known=known)
                if any(_same_pose((R, t), pose) for pose in known):
                    continue
                solutions.append(_judged(problem, Solution(R, t, r, J), length))
    solutions.sort(key=lambda s: (not (s.passes and s.admissible), s.cost))
    return solutions


def _judged(problem, candidate, length):
    """A solution with its rank, residual test and extent check filled in."""
    candidate.rank = jacobian_rank(candidate.jacobian, length)
    candidate.passes = chi_square_passes(candidate.cost, len(candidate.residuals), candidate.rank, problem.sigma)
    candidate.outside = inadmissible(problem, candidate.rotation, candidate.translation, candidate.jacobian)
    candidate.admissible = not candidate.outside
    return candidate


def _best_starts(problem, starts, blocks, mode):
    """Solve each start's translation (batched Gauss-Newton) and order the starts.

    Returns (starts, first): the ``first`` ones are those to refine in any
    case: in sweeps, every start whose cost is no higher than its two
    neighbours; otherwise the best few of each block. The rest follow by cost.
    """
    if not starts:
        return [], 0, mode
    Rs = np.array([R for R, _ in starts])
    ts = np.array([t for _, t in starts], dtype=float)
    for _ in range(2):
        r, J = problem.evaluate_batch(Rs, ts)
        Jv = J[:, :, 3:]
        A = np.einsum("kmi,kmj->kij", Jv, Jv) + 1e-9 * np.eye(3)
        b = np.einsum("kmi,km->ki", Jv, r)
        v = -np.linalg.solve(A, b[..., None])[..., 0]
        ts = ts + np.einsum("kij,kj->ki", Rs, v)
    predicted = r + np.einsum("kmi,ki->km", Jv, v)
    cost = np.sum(predicted**2, axis=1)
    order = np.argsort(cost)
    if mode == "sweep":
        sweep = cost.reshape(-1, SWEEP_STEPS)
        minima = (sweep <= np.roll(sweep, 1, axis=1)) & (sweep <= np.roll(sweep, -1, axis=1))
        chosen = [k for k in order if minima.reshape(-1)[k]]
    else:
        size = len(starts) // blocks
        block = np.arange(len(starts)) // size
        chosen = [k for k in order if np.sum(block[order[: list(order).index(k)]] == block[k]) < UNSWEPT_PER_BLOCK]
    picked = set(chosen)
    ordered = chosen + [k for k in order if k not in picked]
    return [(Rs[k], ts[k]) for k in ordered], len(chosen), mode


def covariance(jacobian, translation, sigma):
    """Pose covariance (6, 6) over (rotation vector rad, fixture origin mm); None if singular.

    ``jacobian`` (m, 6): whitened rows (covariance sigma^2 I, see :class:`Problem`).
    """
    F = jacobian.T @ jacobian
    try:
        C = sigma**2 * np.linalg.inv(F)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(C)):
        return None
    A = origin_error_map(translation)
    return A @ C @ A.T


def cramer_rao_bound(problem, fixture2meas, sigma):
    """Cramer-Rao bound (6, 6) of the pose under the sensor noise model with placement noise sigma (mm).

    The sensors' placement error: translation sigma, rotation sigma / lever
    about each contact point (``problem.lever``), see :func:`row_whitening`.
    """
    T = check_fixture2meas(fixture2meas)
    _, J = problem.evaluate(T[:3, :3], T[:3, 3])
    return covariance(J, T[:3, 3], sigma)


def sigmas(cov):
    """RMS translation (mm) and rotation (deg) standard deviations of a covariance."""
    if cov is None:
        return None, None
    return float(np.sqrt(np.trace(cov[3:, 3:]))), float(np.degrees(np.sqrt(np.trace(cov[:3, :3]))))


def robust_flag(problem, solution):
    """A touch whose removal makes the touches consistent, found by a Cauchy-weighted refit.

    The robust (Cauchy) fit ranks the touches by residual; the worst are left
    out in turn. Returns (touch index, refit Solution, its residual mm) or None.
    """
    sigma = problem.sigma
    R, t = solution.rotation, solution.translation
    scale = 3.0 * sigma
    r = solution.residuals
    for _ in range(5):
        weights = 1.0 / (1.0 + (r / scale) ** 2)
        R, t, r, _ = levenberg_marquardt(problem, R, t, weights=weights, max_iterations=20)
    per_touch = {}
    for touch, value in zip(problem.row_touch, r):
        per_touch[int(touch)] = per_touch.get(int(touch), 0.0) + float(value) ** 2
    # Leave out the worst touches in turn and solve again from scratch.
    for touch in sorted(per_touch, key=lambda k: -per_touch[k]):
        reduced = problem.without(touch)
        if reduced.size <= 6:
            continue
        good = [s for s in solve(reduced) if s.passes and s.admissible and s.rank == 6]
        if good:
            return touch, good[0], float(np.sqrt(per_touch[touch]))
    return None


def features_beyond_tolerance(problem, solutions, starts=4):
    """Feature deviations beyond the tolerance that explain touches failing the residual test.

    Each mode of each touched feature is let free in turn
    (:meth:`FixtureTolerance.widened`) and the pose refitted from each of the
    best ``starts`` solutions; a mode is named when a refit passes. Returns [(feature id, mode name, its estimated
    coordinate mm or rad, the feature's departure from the drawing mm, refit
    Solution)] of the modes whose departure leaves the zone, the smallest first.
    """
    from .deviations import estimated_deviations
    from .tolerance import deviated, departure_mm

    found = []
    length = problem.scale()
    for fid in dict.fromkeys(g.feature.id for g in problem.groups):
        modes = problem.tolerance.modes[fid]
        for k, name in enumerate(modes.names):
            tolerance = problem.tolerance.widened(fid, k)
            freed = Problem(problem.groups, problem.sigma, problem.lever, tolerance)
            for solution in solutions[:starts]:
                R, t, r, J = levenberg_marquardt(freed, solution.rotation, solution.translation)
                refit = _judged(freed, Solution(R, t, r, J), length)
                if refit.passes and refit.admissible and refit.rank == 6:
                    break
            else:
                continue
            delta = estimated_deviations(freed, tolerance, R, t)[tolerance.slices[fid]]
            departure = departure_mm(tolerance.features[fid], deviated(modes, delta))
            if departure > problem.tolerance.zone_mm / 2:
                found.append((fid, name, float(delta[k]), departure, refit))
    return sorted(found, key=lambda item: item[3])


# ---------------------------------------------------------------- free motions


def _feature_directions(problem, rotation, features=None):
    """(description, unit direction in the measurement frame, feature): touched features first."""
    out = []
    seen = set()
    listed = [g.feature for g in problem.groups] + list((features or {}).values())
    for f in listed:
        if f is None or f.id in seen:
            continue
        seen.add(f.id)
        if f.kind == "plane":
            out.append((f"the normal of {f.id}", rotation @ f.normal, f))
        elif f.kind == "cylinder":
            out.append((f"the axis of {f.id}", rotation @ f.axis, f))
        elif f.kind == "line":
            out.append((f"the direction of {f.id}", rotation @ f.direction, f))
    return out


def _vec(v):
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"


def free_motions(problem, solution, features=None):
    """Names of the motions the touches do not constrain, relative to the features.

    Directions are matched with the touched features first, then with the
    other ``features`` (dict id -> feature) of the fixture.
    """
    length = problem.scale()
    D = np.array([length] * 3 + [1.0] * 3)
    scaled = solution.jacobian / D
    _, s, vt = np.linalg.svd(scaled, full_matrices=True)
    rank = solution.rank
    null = (vt[rank:] / D).T  # (6, k) twists
    if null.shape[1] == 0:
        return []
    R, t = solution.rotation, solution.translation
    directions = _feature_directions(problem, R, features)
    names = []
    # Pure translations: the null space of the rotation part within the null space.
    _, sw, vw = np.linalg.svd(null[:3], full_matrices=True)
    rank_w = int(np.sum(sw > 1e-9 * max(np.abs(null).max(), 1e-300)))
    trans = null @ vw[rank_w:].T  # (6, k - rank_w)
    rot = null @ vw[:rank_w].T
    if trans.shape[1]:
        T_dirs = np.linalg.qr(trans[3:])[0]
        if T_dirs.shape[1] == 1:
            u = T_dirs[:, 0]
            match = [name for name, d, _ in directions if abs(d @ u) > 0.999]
            planes = [(f.id, d) for _, d, f in directions if f.kind == "plane"]
            match += [f"both {a} and {b}" for i, (a, da) in enumerate(planes) for b, db in planes[i + 1:]
                      if abs(da @ u) < 1e-3 and abs(db @ u) < 1e-3 and abs(da @ db) < 0.999]
            if match and match[0].startswith("both "):
                names.append("translation parallel to " + match[0])
            else:
                names.append("translation along " + (match[0] if match else _vec(u)))
        elif T_dirs.shape[1] == 2:
            n = np.cross(T_dirs[:, 0], T_dirs[:, 1])
            match = [f.id for name, d, f in directions if f.kind == "plane" and abs(d @ n) > 0.999]
            names.append("translation in the plane of " + match[0] if match else f"translation normal to {_vec(n)}")
        else:
            names.append("translation in every direction")
    if rot.shape[1]:
        omega_basis = np.linalg.qr(rot[:3])[0]
        shifts = trans[3:] if trans.shape[1] else np.zeros((3, 0))

        def twist_with(w):
            """The free twist whose rotation part is ``w`` and the axis point (m, 3)."""
            coeff = np.linalg.lstsq(null[:3], w, rcond=None)[0]
            v = null[3:] @ coeff
            return np.cross(w, v) / (w @ w)

        def on_axis(points, w):
            """Whether the points lie on the free axis along w (shifted by free translations)."""
            off = points - twist_with(w)
            off = off - np.outer(off @ w, w)
            moves = np.cross(w, shifts.T).T if shifts.shape[1] else np.zeros((3, 0))
            if moves.shape[1]:
                q = np.linalg.qr(moves)[0]
                off = off - (off @ q) @ q.T
            return bool(np.all(np.linalg.norm(off, axis=1) < 1e-6 * length))

        def take(w):
            nonlocal omega_basis
            if omega_basis.shape[1] == 0 or np.linalg.norm(omega_basis @ (omega_basis.T @ w) - w) > 1e-6:
                return False
            rest = omega_basis - np.outer(w, w @ omega_basis)
            q, sv, _ = np.linalg.svd(rest, full_matrices=False)
            omega_basis = q[:, sv > 1e-6]
            return True

        # Axes through collinear touches, then feature directions, then anything left.
        for g in problem.groups:
            if g.points is None or g.count < 2:
                continue
            d = g.points[-1] - g.points[0]
            d = d / np.linalg.norm(d)
            if on_axis(g.points, d) and take(d):
                names.append(f"rotation about the line through the touches on {g.feature.id}")
        for name, d, f in directions:
            if take(d):
                names.append("rotation about " + name)
        for k in range(omega_basis.shape[1]):
            w = omega_basis[:, k]
            label = None
            spheres = [g.feature for g in problem.groups if getattr(g.feature, "kind", None) == "sphere"]
            for i, a in enumerate(spheres):
                for b in spheres[i + 1:]:
                    centres = np.array([R @ a.center + t, R @ b.center + t])
                    if label is None and on_axis(centres, w):
                        label = f"the line through the centres of {a.id} and {b.id}"
            for g in problem.groups if label is None else ():
                if getattr(g.feature, "kind", None) == "sphere":
                    c = R @ g.feature.center + t
                    if on_axis(c[None], w):
                        label = f"an axis {_vec(w)} through the centre of {g.feature.id}"
                        break
            names.append("rotation about " + (label or f"the axis {_vec(w)} through {_vec(twist_with(w))} mm"))
    return names


# ---------------------------------------------------------------- separating touch


def _patch_samples(feature, count=400, seed=0):
    """Points (fixture frame) on a feature's finite patch, for choosing an extra touch."""
    rng = np.random.default_rng(seed)
    kind = feature.kind
    if kind == "point":
        return feature.point[None]
    size = 50.0
    if kind == "plane":
        from .contacts import perpendicular_basis

        e1, e2 = perpendicular_basis(feature.normal)
        uv = rng.uniform(-size, size, size=(count, 2))
        pts = feature.point + uv[:, :1] * e1 + uv[:, 1:] * e2
    elif kind == "sphere":
        u = rng.normal(size=(count, 3))
        pts = feature.center + feature.radius * u / np.linalg.norm(u, axis=1, keepdims=True)
    elif kind == "cylinder":
        from .contacts import perpendicular_basis

        e1, e2 = perpendicular_basis(feature.axis)
        lo, hi = feature.extent.interval or (-size, size)
        s = rng.uniform(lo, hi, count)
        a = rng.uniform(0, 2 * np.pi, count)
        pts = feature.point + s[:, None] * feature.axis + feature.radius * (
            np.cos(a)[:, None] * e1 + np.sin(a)[:, None] * e2
        )
    else:
        lo, hi = feature.extent.interval or (-size, size)
        pts = feature.point + np.linspace(lo, hi, count)[:, None] * feature.direction
    inside = feature.contains(pts, 1e-6)
    return pts[inside] if inside.any() else pts[:0]


def separating_touch(features, solutions):
    """The point touch that best tells the best candidate pose from all the others.

    Over points on every feature's patch, the touch the best candidate
    predicts (``point_meas_mm``) is scored by how far it would lie off that
    feature under each other candidate; the smallest of these distances is
    maximised (``separation_mm``).
    """
    if len(solutions) < 2:
        return None
    a, others = solutions[0], solutions[1:]
    best = None
    for feature in features.values():
        pts = _patch_samples(feature)
        if not len(pts):
            continue
        meas = pts @ a.rotation.T + a.translation
        gap = np.full(len(pts), np.inf)
        for b in others:
            local_b = (meas - b.translation) @ b.rotation
            gap = np.minimum(gap, np.abs(feature.signed_distance(local_b)))
        k = int(np.argmax(gap))
        if best is None or gap[k] > best["separation_mm"]:
            best = {
                "feature": feature.id,
                "point_fixture_mm": pts[k].tolist(),
                "point_meas_mm": meas[k].tolist(),
                "separation_mm": float(gap[k]),
            }
    return best


# ---------------------------------------------------------------- front door


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
        if pts.ndim == 1 and pts.size == 3:
            pts = pts[None]
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"touches on {feature_id} must have shape (n, 3) in mm, got shape {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise ValueError(f"touches on {feature_id} must be finite, got NaN or inf")
        if len(pts) == 0:
            continue
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


def register_touches(features, touches, initial_pose=None, sigma_mm=DEFAULT_SIGMA_MM, ball_radius_mm=0.0,
                     contacts=(), approaches=None, lever_mm=SENSOR_LEVER_MM, tolerance=None):
    """Register a fixture from labelled touches; return the result dict (see module doc).

    Parameters
    ----------
    features : dict id -> feature
    touches : dict id -> array-like, shape (n, 3), mm, measurement frame
    initial_pose : array-like, shape (4, 4), optional nominal ``fixture2meas``
    sigma_mm : float, sensor placement noise (mm, each axis) for the chi-square test and covariance
    ball_radius_mm : float, radius of a ball tip (0 for a point probe); touches are ball centres
    contacts : list of dict, touches of other contact types (see ``contact_touch``)
    approaches : dict id -> array-like, shape (n, 3), optional probe approach directions;
        a pose at which a probe would have touched a surface from inside is rejected
    lever_mm : float, sensor size: plane, line and fixed-surface sensors tilt by
        sigma_mm / lever_mm rad about their contact points (see the module doc)

    Returns
    -------
    dict with ``pose`` (4x4 nested list, fixture2meas), ``status`` ("unique",
    "ambiguous", "inconsistent" or "underdetermined"), ``rms_residual_mm``,
    ``solutions`` (each ``pose``, ``rms_residual_mm``, of the whitened rows; every admissible pose that
    passes the chi-square test, best first), ``covariance`` (6x6 over rotation
    vector rad and fixture origin mm, None when underdetermined),
    ``sigma_translation_mm``, ``sigma_rotation_deg``, ``free_motions`` (names),
    ``separating_touch`` (ambiguous: where one more touch tells the candidates
    apart), ``flagged`` (inconsistent: the touch left out, e.g. mislabelled),
    ``inadmissible`` (touches off their patch or touched from inside at
    ``pose``), ``touches``, ``rows``, ``rank``.
    """
    groups = build_groups(features, touches, ball_radius_mm, contacts, approaches)
    problem = Problem(groups, sigma_mm, lever_mm, tolerance)
    if not problem.groups:
        raise ValueError("no touches given")
    solutions = solve(problem, initial_pose)
    best = solutions[0]
    result = {"flagged": [], "fixture_flagged": [], "free_motions": [], "separating_touch": None,
              "inadmissible": best.outside}
    good = [s for s in solutions if s.passes and s.admissible and s.rank == 6]
    if best.rank < 6:
        status = "underdetermined"
        result["free_motions"] = free_motions(problem, best, features)
    elif len(good) == 1:
        status = "unique"
        best = good[0]
    elif len(good) > 1:
        status = "ambiguous"
        best = good[0]
        result["separating_touch"] = separating_touch(features, good)
    else:
        status = "inconsistent"
        # Two kinds of explanation, both listed: a touch that is off, a feature printed beyond its tolerance.
        off = features_beyond_tolerance(problem, solutions) if problem.tolerance is not None else []
        result["fixture_flagged"] = [{"feature": fid, "mode": mode, "deviation": value, "departure_mm": mm}
                                     for fid, mode, value, mm, _ in off]
        flagged = robust_flag(problem, best) if problem.size > 7 else None
        if flagged is None and off:
            best = off[0][-1]
            good = [item[-1] for item in off]
        elif flagged is not None:
            touch, refit, size = flagged
            feature_of = {int(i): g.feature.id for g in groups for i in g.index}
            result["flagged"] = [{"touch": touch, "feature": feature_of[touch], "residual_mm": size}]
            best = refit
            good = [refit]
    shown = good if good else [best]
    cov = covariance(best.jacobian, best.translation, problem.sigma) if best.rank == 6 else None
    s_t, s_r = sigmas(cov)
    result.update(
        {
            "pose": best.fixture2meas.tolist(),
            "status": status,
            "rms_residual_mm": best.rms,
            "solutions": [{"pose": s.fixture2meas.tolist(), "rms_residual_mm": s.rms} for s in shown],
            "covariance": None if cov is None else cov.tolist(),
            "sigma_translation_mm": s_t,
            "sigma_rotation_deg": s_r,
            "touches": int(sum(g.count for g in groups)),
            "rows": problem.size,
            "rank": best.rank,
        }
    )
    return result


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
                elif key in ("normal", "direction", "axis"):
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
