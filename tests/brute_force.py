"""Every admissible pose of a fixture from its touches, by brute force: the answer the engine is judged by.

Independent of the engine on purpose: its pose parametrisation, residuals, starts and optimiser
(``scipy.optimize.least_squares``) are written here; only the features' own geometry is shared
(``Feature.signed_distance``, ``normal_at``, ``closest_point`` and ``contains``, what a touch on the part means).

Many seeded random starts (rotation uniform on SO(3), the touches' centroid mapped to a uniform point
of the fixture's bounding box), and the true pose when it is known, are each refined to a local
minimum of the touches' residuals: all together by a batched Levenberg-Marquardt descent (cheap), then
each by its own ``least_squares``, except a start whose descent converged to a minimum that does not
pass or reached a pose already refined. With noisy touches, a minimum that passes off the patches is
pulled onto them (its touches' distances beyond the patches as more rows), since poses near it may pass
on them. A pose is kept when it passes: every touch lies within
``PATCH_TOLERANCE_MM`` of its feature's finite patch, and the residuals are noise-free (RMS below
``EXACT_RMS_MM``) or pass a chi-square test at the touch noise sigma. Kept poses closer than
``SAME_ROTATION_RAD`` and ``SAME_TRANSLATION_MM`` are one.

Point touches, labelled or not (each then on the feature whose patch lies nearest it), and sensor contacts
(:func:`contact_model`) are modelled, each from its geometry, as what it means for the touch to have happened
at the pose (the feature in the fixture frame, the sensor's measurement-frame geometry mapped into it):

* the two sensors of the paper's Example One: a plane sensor lying on a plane feature (its normal against the
  feature's, its known point on the plane and on the patch) and a line sensor crossing a line feature, both
  mobile (the two lines meet, the crossing on the line's extent);
* on a boss, both mobile: a line sensor round it (the line the radius from the axis, where it touches on the
  patch) and a plane sensor lying on it (its normal square to the axis, the axis the radius along it, the
  contact line's point nearest the sensor's point on the patch);
* a fixed surface sensor (a ball, plane or cylinder; its contact point p and its outward normal there known)
  on a mobile plane, sphere or cylinder: p on the surface, and the feature's outward normal at p against the
  sensor's (two rows);
* a fixed line sensor (point p, direction d) on a mobile sphere or cylinder: p on the surface, d tangent to it;
* a fixed probe point on a mobile feature: a point touch;
* both sides fixed (the feature's contact point o known too): p maps onto o (three rows), and the sensor's
  normal against the feature's at o (two rows), perpendicular to a line feature, or a line sensor tangent to
  a surface (one row);
* a mobile ball (centre c, radius r) on a fixed feature side at o: c at o + r n on a surface (n its outward
  normal at o, three rows); on a line, a ball radius from o across the line (two rows: the line is tangent to
  the ball at o); on a point, a ball radius from o.

Each contact's known point (a fixed sensor's p, a ball's centre) must lie on its feature's patch. The rows
are whitened for the noise model the engine is tested with: each sensor placed with a random translation of
sigma (each axis) and a turn of sigma / ``PAD_LEVER_MM`` rad about its contact point (an orientation row is
scaled by ``PAD_LEVER_MM``; one that also sees the contact point slide over a curved surface is scaled back
by that slide's share).
"""

import copy
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2

from fixturecad.registration.patches import patch_points

PATCH_TOLERANCE_MM = 0.2  # how far off its feature's patch a touch may lie (the engine's admissibility)
CONFIDENCE = 0.999  # chi-square test: a correct pose passes 999 times in 1000
EXACT_RMS_MM = 1e-6  # a noise-free pose fits to this
SAME_ROTATION_RAD = 1e-3
SAME_TRANSLATION_MM = 0.01
STARTS = 150
STEP = 1e-6  # central-difference step of the Jacobian, rad and mm
DESCENT_ITERATIONS = 300  # batched damped steps taking every start to its minimum before least_squares
CONVERGED_DAMPING = 1e8  # a start whose steps were refused until its damping grew this large is at a minimum
EXACT_COST_MM2 = 1e-26  # ... as is one that fits this well
MIN_DAMPING = 1e-9  # relative to the diagonal: keeps a rank-deficient step solvable
REFINE_EVALUATIONS = 100  # least_squares evaluations from a start the descent left in a slow valley
PAD_LEVER_MM = 20.0  # a plane sensor's tilt (rad) is seen at this distance from its point, as mm
INSIDE_TARGET_MM = 0.1  # a pose pulled onto the patches aims at touches at most this far outside ...
INSIDE_WEIGHT = 10.0  # ... their distance beyond it weighted this much more than a residual


@dataclass
class Pose:
    """A kept pose: ``fixture2meas`` (4, 4), its residuals' RMS (mm) and squared sum (mm^2)."""

    fixture2meas: np.ndarray
    rms_mm: float
    cost_mm2: float


def rotations(w):
    """Rodrigues, batched: rotation matrices (k, 3, 3) of rotation vectors (k, 3) rad."""
    angle = np.linalg.norm(w, axis=1)[:, None, None]
    K = np.zeros((len(w), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K = K - K.transpose(0, 2, 1)
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0, np.sin(safe) / safe)
    b = np.where(small, 0.5, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * K + b * K @ K


def random_rotations(rng, count):
    """``count`` rotations (count, 3, 3) uniform on SO(3): normalised Gaussian quaternions."""
    q = rng.normal(size=(count, 4))
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], 1)


def bounding_box_mm(features):
    """(lower, upper) corners of all the features' patches, fixture frame, mm."""
    points = np.vstack([patch_points(f) for f in features.values()])
    return points.min(0), points.max(0)


def _beyond_patch_mm(feature, points):
    """How far (n,) mm beyond its feature's patch each fixture-frame point's projection on it lies (0 inside)."""
    q = feature.closest_point(points)
    core, anchor, direction, _ = feature.core()
    along = (q - anchor) @ direction if core == "line" else None
    return np.maximum(-feature.extent.margin(q, along), 0.0)


# Sensor contacts. A contact's sensor is given in the measurement frame; the models keep its points less the
# touches' centroid (:meth:`_Contact.centred`) and map them into the fixture frame at k poses (A, b) at once:
# a point s to A s + b, a direction d to A d.

FIXED_SIDES = ("F", "M")
SURFACES = ("plane", "sphere", "cylinder")  # features with an outward normal
NORMAL_SLOPE_STEP_MM = 1e-3  # central-difference step of a feature's normal along its surface


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _points(A, b, s):
    """A point s (3,) at k poses: (k, 3)."""
    return A @ s + b


def _normal_slope(feature, q, e):
    """How the feature's outward normal turns (k, 3) per mm as the point q (k, 3) moves along e (k, 3)."""
    h = NORMAL_SLOPE_STEP_MM
    return (feature.normal_at(q + h * e) - feature.normal_at(q - h * e)) / (2.0 * h)


def _whiten(rows, slopes):
    """Orientation rows (k, m), scaled by ``PAD_LEVER_MM``, whose noise is the sensor's turn (sigma each, not
    correlated) plus ``PAD_LEVER_MM`` times its contact point's slide (sigma each axis) along ``slopes`` (k, m,
    3): whitened, ``L^-1 rows`` with ``L L^T = I + PAD_LEVER_MM^2 slopes slopes^T``."""
    m = rows.shape[1]
    C = np.eye(m) + PAD_LEVER_MM**2 * np.einsum("kil,kjl->kij", slopes, slopes)
    L = np.linalg.cholesky(C)
    return np.linalg.solve(L, rows[..., None])[..., 0]


class _Contact:
    """One sensor contact: ``size`` rows, ``anchor`` (its measurement-frame point for the touches' centroid),
    ``rows(A, b)`` (k, size) and ``located(A, b)`` (k, 3): the fixture-frame point that must lie on the
    feature's patch."""

    POINT_KEYS = ()  # the attributes that are measurement-frame points

    def centred(self, centroid_mm):
        """The contact with its measurement-frame points less the touches' centroid."""
        out = copy.copy(self)
        for key in self.POINT_KEYS:
            setattr(out, key, getattr(self, key) - centroid_mm)
        return out


class _PlaneOnPlane(_Contact):
    """Example One's plane sensor lying on a plane feature (a face contact): the sensor's normal against the
    feature's (two rows scaled by ``PAD_LEVER_MM``) and its point on the plane; the point on the patch."""

    POINT_KEYS = ("s",)
    size = 3

    def __init__(self, feature, sensor):
        self.feature, self.s = feature, np.asarray(sensor["point"], float)
        self.d = _unit(sensor["normal"])
        self.anchor = self.s

    def rows(self, A, b):
        feature = self.feature
        s_fix, d_fix = _points(A, b, self.s), A @ self.d
        e = np.array(_perpendiculars(feature.normal))
        return np.hstack([PAD_LEVER_MM * (d_fix + feature.normal) @ e.T,
                          ((s_fix - feature.point) @ feature.normal)[:, None]])

    def located(self, A, b):
        return _points(A, b, self.s)


class _LinesCross(_Contact):
    """Example One's line sensor crossing a line feature, both mobile: the two lines meet (one row, mm); where
    they cross on the line's extent. Round a boss (a cylinder feature): the line at the radius from the axis (the
    lines' unsigned distance less it), touching the cylinder the radius from the axis towards the line."""

    POINT_KEYS = ("s",)
    size = 1

    def __init__(self, feature, sensor):
        self.feature, self.s = feature, np.asarray(sensor["point"], float)
        self.d = _unit(sensor["direction"])
        self.anchor = self.s
        _, self.point, self.axis, self.radius = feature.core()

    def rows(self, A, b):
        s_fix, d_fix = _points(A, b, self.s), A @ self.d
        m = np.cross(d_fix, self.axis)
        apart = np.einsum("ki,ki->k", s_fix - self.point, m) / np.linalg.norm(m, axis=1)
        return (apart if self.radius == 0.0 else np.abs(apart) - self.radius)[:, None]

    def located(self, A, b):
        # The point of the feature's line closest to the sensor line (where they cross), moved the radius out.
        s_fix, d_fix = _points(A, b, self.s), A @ self.d
        w = self.point - s_fix
        c = d_fix @ self.axis
        along = (c * np.einsum("ki,ki->k", d_fix, w) - w @ self.axis) / (1.0 - c * c)
        foot = self.point + along[:, None] * self.axis
        if self.radius == 0.0:
            return foot
        near = s_fix + np.einsum("ki,ki->k", d_fix, foot - s_fix)[:, None] * d_fix
        return foot + self.radius * (near - foot) / np.linalg.norm(near - foot, axis=1, keepdims=True)


class _PlaneOnCylinder(_Contact):
    """A plane sensor lying on a boss, both mobile: its normal square to the axis (one row, scaled by
    ``PAD_LEVER_MM``) and the axis, at the foot of the sensor's point, the radius from the plane along the
    sensor's normal (one row, mm); the point of the contact line nearest the sensor's point, on the patch."""

    POINT_KEYS = ("s",)
    size = 2

    def __init__(self, feature, sensor):
        self.feature, self.s = feature, np.asarray(sensor["point"], float)
        self.n = _unit(sensor["normal"])
        self.anchor = self.s
        _, self.point, self.axis, self.radius = feature.core()

    def rows(self, A, b):
        s_fix, n_fix = _points(A, b, self.s), A @ self.n
        # The axis's distance measured at the foot of the sensor's point (a turn of the sensor about its point
        # moves it little there, and far along the axis by the axis's length).
        foot = self.point + ((s_fix - self.point) @ self.axis)[:, None] * self.axis
        return np.stack([PAD_LEVER_MM * n_fix @ self.axis,
                         np.einsum("ki,ki->k", foot - s_fix, n_fix) - self.radius], axis=1)

    def located(self, A, b):
        s_fix, n_fix = _points(A, b, self.s), A @ self.n
        line = self.point - self.radius * n_fix  # a point of the contact line
        return line + np.einsum("ki,i->k", s_fix - line, self.axis)[:, None] * self.axis


class _FixedOnMobile(_Contact):
    """A fixed sensor, its contact point p known, on a mobile feature: p on the feature's surface (signed
    distance, mm), and

    * a surface sensor (outward normal ``normal`` at p): the feature's outward normal at p against it, two
      rows across the sensor's normal, scaled by ``PAD_LEVER_MM`` and whitened for the slide of p over a
      curved feature;
    * a line sensor (direction ``direction``): tangent to the feature at p, one row ``d . n`` scaled and
      whitened alike;
    * a probe point: nothing more.
    """

    POINT_KEYS = ("p",)

    def __init__(self, feature, p, normal=None, direction=None):
        self.feature, self.p, self.anchor = feature, np.asarray(p, float), np.asarray(p, float)
        self.normal = None if normal is None else _unit(normal)
        self.direction = None if direction is None else _unit(direction)
        if self.normal is not None:
            self.across = np.array(_perpendiculars(self.normal))  # (2, 3), measurement frame
        self.size = 1 + (2 if self.normal is not None else 1 if self.direction is not None else 0)

    def rows(self, A, b):
        feature = self.feature
        q = _points(A, b, self.p)
        out = [feature.signed_distance(q)[:, None]]
        if self.normal is not None:
            n_f, n_s = feature.normal_at(q), A @ self.normal
            across = np.einsum("kij,mj->kmi", A, self.across)  # (k, 2, 3): the sensor's basis, fixture frame
            tilt = PAD_LEVER_MM * np.einsum("kmi,ki->km", across, n_f + n_s)
            slopes = np.stack([_normal_slope(feature, q, across[:, m]) for m in range(2)], axis=1)
            out.append(_whiten(tilt, slopes))
        elif self.direction is not None:
            d = A @ self.direction
            tilt = PAD_LEVER_MM * np.einsum("ki,ki->k", d, feature.normal_at(q))[:, None]
            out.append(_whiten(tilt, _normal_slope(feature, q, d)[:, None]))
        return np.hstack(out)

    def located(self, A, b):
        return _points(A, b, self.p)


class _FixedFixed(_Contact):
    """Both sides fixed: the sensor's contact point p maps onto the feature's known point o (three rows, mm), and

    * a surface sensor (outward ``normal`` at p) on a surface feature: the feature's outward normal at o
      against the sensor's, two rows across the feature's, scaled by ``PAD_LEVER_MM``;
    * a surface sensor on a line feature: its normal perpendicular to the line (one row, scaled alike);
    * a line sensor (``direction``) on a surface feature: tangent to it at o (one row, scaled alike);
    * otherwise (a probe point, a line sensor on a line, a point feature): nothing more.
    """

    POINT_KEYS = ("p",)

    def __init__(self, feature, p, o, normal=None, direction=None):
        self.feature, self.p, self.anchor = feature, np.asarray(p, float), np.asarray(p, float)
        self.o = np.asarray(o, float)
        self.normal = None if normal is None else _unit(normal)
        self.direction = None if direction is None else _unit(direction)
        self.orientation = None
        if self.normal is not None and feature.kind in SURFACES:
            self.feature_normal = feature.normal_at(self.o)[0]
            self.across = np.array(_perpendiculars(self.feature_normal))
            self.orientation = "normals"
        elif self.normal is not None and feature.kind == "line":
            self.orientation = "normal across the line"
        elif self.direction is not None and feature.kind in SURFACES:
            self.feature_normal = feature.normal_at(self.o)[0]
            self.orientation = "line tangent"
        self.size = 3 + {"normals": 2, None: 0}.get(self.orientation, 1)

    def rows(self, A, b):
        out = [_points(A, b, self.p) - self.o]
        if self.orientation == "normals":
            out.append(PAD_LEVER_MM * (A @ self.normal + self.feature_normal) @ self.across.T)
        elif self.orientation == "normal across the line":
            out.append(PAD_LEVER_MM * (A @ self.normal @ self.feature.direction)[:, None])
        elif self.orientation == "line tangent":
            out.append(PAD_LEVER_MM * (A @ self.direction @ self.feature_normal)[:, None])
        return np.hstack(out)

    def located(self, A, b):
        return _points(A, b, self.p)


class _BallOnFixed(_Contact):
    """A mobile ball (centre c, radius r) on a fixed feature side, its contact point o known: the centre at
    ``o + r n`` on a surface (n its outward normal at o; three rows, mm); on a line, a ball radius from o and
    square to the line there (the line tangent to the ball at o; two rows); on a point, a ball radius from o
    (one row). The centre's projection on the feature must lie on its patch."""

    POINT_KEYS = ("c",)

    def __init__(self, feature, c, radius, o):
        self.feature, self.c, self.anchor = feature, np.asarray(c, float), np.asarray(c, float)
        self.radius, self.o = float(radius), np.asarray(o, float)
        if feature.kind in SURFACES:
            self.target = self.o + self.radius * feature.normal_at(self.o)[0]
            self.size = 3
        else:
            self.size = 2 if feature.kind == "line" else 1

    def rows(self, A, b):
        c = _points(A, b, self.c)
        if self.feature.kind in SURFACES:
            return c - self.target
        out = [(np.linalg.norm(c - self.o, axis=1) - self.radius)[:, None]]
        if self.feature.kind == "line":
            out.append(((c - self.o) @ self.feature.direction)[:, None])
        return np.hstack(out)

    def located(self, A, b):
        return _points(A, b, self.c)


def _contact_type(text):
    """The sides of a contact written ``X/F-Y/M``, sensor first: ((element, fixed), (element, fixed))."""
    sides = []
    for side in text.replace(" ", "").upper().split("-"):
        element, flag = side.split("/")
        if flag not in FIXED_SIDES:
            raise ValueError(f"cannot read contact {text!r}")
        sides.append((element, flag == "F"))
    return tuple(sides)


def _sensor_normal(sensor, p):
    """A surface sensor's outward unit normal at its contact point p (measurement frame), or None."""
    kind = sensor["kind"]
    if kind == "plane":
        return _unit(sensor["normal"])
    if kind == "sphere":
        return _unit(p - np.asarray(sensor["center"], float))
    if kind == "cylinder":
        axis = _unit(sensor["axis"])
        r = p - np.asarray(sensor["point"], float)
        return _unit(r - (r @ axis) * axis)
    return None


def contact_model(feature, contact):
    """The brute force's model of one sensor contact (as :func:`fixturecad.registration.synthetic.plan_touches`
    makes it): see the module doc; ValueError for a contact not modelled."""
    sensor = contact["sensor"]
    kind = sensor["kind"]
    (_, sensor_fixed), (_, fixture_fixed) = _contact_type(contact["contact"])
    pair = {kind, feature.kind}
    if pair == {"plane"}:
        return _PlaneOnPlane(feature, sensor)
    locus = "plane" in pair and len(pair - {"plane"} - {"line", "cylinder"}) == 0
    if kind == "line" and feature.kind in ("line", "cylinder") and not sensor_fixed and not fixture_fixed:
        return _LinesCross(feature, sensor)
    if kind == "plane" and feature.kind == "cylinder" and not sensor_fixed and not fixture_fixed:
        return _PlaneOnCylinder(feature, sensor)
    if sensor_fixed and not locus and "point" in contact:
        p = np.asarray(contact["point"], float)
        normal = _sensor_normal(sensor, p)
        direction = np.asarray(sensor["direction"], float) if kind == "line" else None
        if fixture_fixed and "fixture" in contact:
            return _FixedFixed(feature, p, contact["fixture"]["o"], normal, direction)
        if not fixture_fixed and (kind == "point" or feature.kind in SURFACES):
            return _FixedOnMobile(feature, p, normal, direction)
    if kind == "sphere" and not sensor_fixed and fixture_fixed and "fixture" in contact:
        return _BallOnFixed(feature, sensor["center"], sensor["radius"], contact["fixture"]["o"])
    raise ValueError(f"no brute-force model of a {kind} sensor on a {feature.kind} ({contact['contact']})")


class TouchResiduals:
    """The residual rows of touches at batches of poses, each pose as (A, b): ``q = A (p - c) + b``
    takes a measured point p into the fixture frame, c the touches' centroid, so that a turn and a
    shift are not coupled over the distance to the measurement origin (which slows the descent).

    Rows, in order: each feature's point touches (signed distance, mm), then each contact's rows
    (:func:`contact_model`).
    """

    def __init__(self, features, touches, contacts=()):
        groups = [(features[fid], np.asarray(p, float).reshape(-1, 3)) for fid, p in touches.items() if np.size(p)]
        models = [contact_model(features[contact["feature"]], contact) for contact in contacts]
        self.centroid_mm = np.vstack([p for _, p in groups] + [m.anchor[None] for m in models]).mean(0)
        self.groups = [(feature, p - self.centroid_mm) for feature, p in groups]
        self.contacts = [m.centred(self.centroid_mm) for m in models]
        self.size = sum(len(p) for _, p in self.groups) + sum(m.size for m in self.contacts)

    def fixture2meas(self, A, b):
        """The ``fixture2meas`` (4, 4) of a pose (A, b)."""
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = A.T, self.centroid_mm - A.T @ b
        return T

    def pose_of(self, fixture2meas):
        """The pose (A, b) of a ``fixture2meas``."""
        R, t = fixture2meas[:3, :3], fixture2meas[:3, 3]
        return R.T, R.T @ (self.centroid_mm - t)

    def rows(self, A, b, inside=False):
        """Residuals (k, size) at k poses, A (k, 3, 3), b (k, 3); ``inside``: and the point touches' and
        contact locations' distances beyond their patches, less ``INSIDE_TARGET_MM``, weighted ``INSIDE_WEIGHT``
        (k, touches)."""
        k, out = len(A), []
        if inside:
            out.append(INSIDE_WEIGHT * np.maximum(self.outside_mm(A, b) - INSIDE_TARGET_MM, 0.0))
        for feature, P in self.groups:
            q = np.einsum("kij,nj->kni", A, P) + b[:, None]
            out.append(feature.signed_distance(q.reshape(-1, 3)).reshape(k, len(P)))
        for model in self.contacts:
            out.append(model.rows(A, b))
        return np.hstack(out)

    def contact_points(self, A, b):
        """(feature, fixture-frame point) of every touch and contact location at one pose (A, b)."""
        out = [(feature, P @ A.T + b) for feature, P in self.groups]
        out += [(model.feature, model.located(A[None], b[None])) for model in self.contacts]
        return out

    def outside_mm(self, A, b):
        """How far (k, touches) mm beyond its feature's patch each point touch and contact location lies at k
        poses (0 inside)."""
        k, out = len(A), []
        located = [(feature, (np.einsum("kij,nj->kni", A, P) + b[:, None]).reshape(-1, 3))
                   for feature, P in self.groups]
        located += [(model.feature, model.located(A, b)) for model in self.contacts]
        for feature, q in located:
            out.append(_beyond_patch_mm(feature, q).reshape(k, -1))
        return np.hstack(out) if out else np.zeros((k, 0))

    def admissible(self, A, b, tolerance_mm=PATCH_TOLERANCE_MM):
        """Whether every touch and contact location lies on its feature's patch at the pose (A, b)."""
        return all(np.all(feature.contains(points, tolerance_mm)) for feature, points in self.contact_points(A, b))

    def passing_cost_mm2(self, sigma_mm):
        """The largest squared residual sum that passes: noise-free, or the chi-square test."""
        if sigma_mm == 0.0:
            return self.size * EXACT_RMS_MM**2
        # A set without redundancy fits exactly: one degree of freedom tolerates the solver's residue.
        return sigma_mm**2 * chi2.ppf(CONFIDENCE, max(self.size - 6, 1))

    def jacobians(self, A, b, inside=False):
        """Residuals (k, rows) and their Jacobians (k, rows, 6) over (w, b) at ``A = exp(w) A``, by
        central differences, all k poses in one evaluation (``inside``: see :meth:`rows`)."""
        steps = STEP * np.vstack([np.eye(6), -np.eye(6)])
        k = len(A)
        moved_A = (rotations(np.tile(steps[:, :3], (k, 1))).reshape(k, 12, 3, 3) @ A[:, None]).reshape(-1, 3, 3)
        moved_b = (b[:, None] + steps[:, 3:]).reshape(-1, 3)
        values = self.rows(moved_A, moved_b, inside).reshape(k, 12, -1)
        return self.rows(A, b, inside), ((values[:, :6] - values[:, 6:]) / (2.0 * STEP)).transpose(0, 2, 1)

    def descend(self, A, b, inside=False, iterations=DESCENT_ITERATIONS):
        """Levenberg-Marquardt on k starts at once (A (k, 3, 3), b (k, 3)), each with its own damping:
        brings every start to, or near, its local minimum cheaply before :meth:`refine` (``inside``: see
        :meth:`rows`). Returns the poses and whether each has converged (no step lowers its cost)."""
        A, b = A.copy(), b.copy()
        damping = np.full(len(A), 1e-3)
        r, J = self.jacobians(A, b, inside)
        cost = np.einsum("km,km->k", r, r)
        active = np.arange(len(A))
        for _ in range(iterations):
            H = J.transpose(0, 2, 1) @ J
            g = np.einsum("kmi,km->ki", J, r)
            # Marquardt's scaling, floored so that a parameter the residuals do not see stays solvable.
            diagonal = np.einsum("kii->ki", H)
            diagonal = np.maximum(diagonal, 1e-12 * diagonal.max(axis=1, keepdims=True) + 1e-18)
            lm = H + damping[active, None, None] * diagonal[:, :, None] * np.eye(6)
            step = -np.linalg.solve(lm, g[..., None])[..., 0]
            A_try, b_try = rotations(step[:, :3]) @ A[active], b[active] + step[:, 3:]
            r_try = self.rows(A_try, b_try, inside)
            cost_try = np.einsum("km,km->k", r_try, r_try)
            better = cost_try < cost[active]
            A[active[better]], b[active[better]], cost[active[better]] = A_try[better], b_try[better], cost_try[better]
            damping[active] = np.where(better, np.maximum(damping[active] / 3.0, MIN_DAMPING), damping[active] * 4.0)
            active = active[(damping[active] < CONVERGED_DAMPING) & (cost[active] > EXACT_COST_MM2)]
            if not len(active):
                break
            r, J = self.jacobians(A[active], b[active], inside)
        converged = np.ones(len(A), bool)
        converged[active] = False
        return A, b, converged

    def refine(self, A0, b0, inside=False):
        """The local minimum (A, b, residuals) from a start: ``A = exp(w) A0``, least squares over (w, b).

        ``inside``: with the rows of the point touches' distances beyond their patches (:meth:`rows`): the
        pose near the start that the patches admit, where the least-squares pose is off them but poses on
        them may pass too (noisy, poorly determined touches).
        """
        def pose(x):
            return rotations(x[None, :3])[0] @ A0, x[3:]

        def fun(x):
            A, b = pose(x)
            return self.rows(A[None], b[None], inside)[0]

        def jac(x):
            A, b = pose(x)
            return self.jacobians(A[None], b[None], inside)[1][0]

        fit = least_squares(fun, np.concatenate([np.zeros(3), b0]), jac=jac, method="lm", x_scale="jac",
                            xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=REFINE_EVALUATIONS)
        A, b = pose(fit.x)
        return A, b, self.rows(A[None], b[None])[0]


class UnlabelledResiduals(TouchResiduals):
    """Point touches on some plane, sphere or cylinder, not said which: each touch's row is its signed distance
    from the feature whose patch lies nearest it at the pose (its distance off the surface plus how far beyond
    the patch its nearest surface point lies), and it must lie on that feature's patch."""

    def __init__(self, features, points):
        self.candidates = [f for f in features.values() if f.kind in ("plane", "sphere", "cylinder")]
        points = np.asarray(points, float).reshape(-1, 3)
        self.centroid_mm = points.mean(0)
        self.points = points - self.centroid_mm
        self.groups, self.contacts, self.size = [(None, self.points)], [], len(points)

    def chosen(self, A, b):
        """Each touch's feature index (k, n), signed distance (k, n) and distance beyond the patch (k, n)."""
        q = (np.einsum("kij,nj->kni", A, self.points) + b[:, None]).reshape(-1, 3)
        distance, beyond = [], []
        for feature in self.candidates:
            distance.append(feature.signed_distance(q))
            near = feature.closest_point(q)
            core, anchor, direction, _ = feature.core()
            along = (near - anchor) @ direction if core == "line" else None
            beyond.append(np.maximum(-feature.extent.margin(near, along), 0.0))
        distance, beyond = np.array(distance), np.array(beyond)  # (features, k n)
        choice = np.argmin(np.abs(distance) + beyond, axis=0)
        pick = np.arange(len(choice))
        shape = (len(A), len(self.points))
        return (choice.reshape(shape), distance[choice, pick].reshape(shape), beyond[choice, pick].reshape(shape))

    def rows(self, A, b, inside=False):
        _, distance, beyond = self.chosen(A, b)
        if inside:
            return np.hstack([INSIDE_WEIGHT * np.maximum(beyond - INSIDE_TARGET_MM, 0.0), distance])
        return distance

    def contact_points(self, A, b):
        choice = self.chosen(A[None], b[None])[0][0]
        q = self.points @ A.T + b
        return [(f, q[choice == k]) for k, f in enumerate(self.candidates) if np.any(choice == k)]

    def outside_mm(self, A, b):
        return self.chosen(A, b)[2]


def same(a, b):
    """Whether two ``fixture2meas`` are one pose (the brute force's resolution)."""
    return _same_rotation(a[:3, :3], b[:3, :3]) and np.linalg.norm(a[:3, 3] - b[:3, 3]) < SAME_TRANSLATION_MM


def _same_rotation(a, b):
    return np.arccos(np.clip(0.5 * (np.trace(a @ b.T) - 1.0), -1.0, 1.0)) < SAME_ROTATION_RAD


def admissible_poses(features, touches, contacts=(), sigma_mm=0.0, truth=None, starts=STARTS, seed=0,
                     unlabelled=False):
    """Every admissible pose the brute force finds, best (lowest cost) first (list of :class:`Pose`).

    Parameters
    ----------
    features : dict id -> feature
    touches : dict id -> array-like, shape (n, 3), mm, measurement frame (point-probe touches)
    contacts : plane or line sensor contacts as :func:`fixturecad.registration.synthetic.plan_touches` makes them
    sigma_mm : float, touch noise (each axis); 0 for noise-free touches
    truth : array-like (4, 4), optional ``fixture2meas`` tried as one more start
    unlabelled : the touches' labels are not known (:class:`UnlabelledResiduals`; no contacts)
    """
    problem = UnlabelledResiduals(features, np.vstack(list(touches.values()))) if unlabelled else \
        TouchResiduals(features, touches, contacts)
    rng = np.random.default_rng(seed)
    lower, upper = bounding_box_mm(features)
    A0 = random_rotations(rng, starts)
    b0 = rng.uniform(lower, upper, size=(starts, 3))  # where the touches' centroid lands, fixture frame
    if truth is not None:
        A, b = problem.pose_of(np.asarray(truth, float))
        A0, b0 = np.vstack([A0, A[None]]), np.vstack([b0, b])
    passing = problem.passing_cost_mm2(sigma_mm)
    minima = _minima(problem, A0, b0, passing)
    # Where a passing pose is off the patches, noisy touches may pass at a pose near it on the patches:
    # pulled onto them. (Noise-free, a pose passes only where it is exact: no other pose near it does.)
    off = [(A, b) for A, b, r in minima if r @ r <= passing and not problem.admissible(A, b)]
    if off and (problem.groups or problem.contacts) and sigma_mm > 0.0:
        minima += _minima(problem, np.array([A for A, _ in off]), np.array([b for _, b in off]), passing, inside=True)
    kept = [Pose(problem.fixture2meas(A, b), float(np.sqrt(r @ r / len(r))), float(r @ r))
            for A, b, r in minima if r @ r <= passing and problem.admissible(A, b)]
    kept.sort(key=lambda p: p.cost_mm2)
    distinct = []
    for pose in kept:
        if not any(same(pose.fixture2meas, other.fixture2meas) for other in distinct):
            distinct.append(pose)
    return distinct


def _minima(problem, A0, b0, passing, inside=False):
    """(A, b, residuals) of the local minima from starts (A0, b0): the batched descent, then each start's
    own least_squares, except a start whose descent converged to a minimum that does not pass or reached
    a pose already refined (``inside``: see :meth:`TouchResiduals.rows`)."""
    A0, b0, converged = problem.descend(A0, b0, inside)
    r = problem.rows(A0, b0)
    cost = np.einsum("km,km->k", r, r)
    out, refined = [], []
    for k in np.argsort(cost):
        if converged[k] and cost[k] > passing:
            continue
        start = problem.fixture2meas(A0[k], b0[k])
        if any(same(start, T) for T in refined):
            continue
        out.append(problem.refine(A0[k], b0[k], inside))
        refined.append(problem.fixture2meas(*out[-1][:2]))
    return out


def _perpendiculars(normal):
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)
