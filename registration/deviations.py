"""The printed part's deviations as nuisance parameters of the registration.

Every feature's deviation modes (:mod:`.tolerance`) get a covariance *as
seen from the datum frame* (:mod:`.datums`): a deviation that only moves the
frame is no deviation at all, and the datum features' own deviations show
up in the others. Touches on one feature share its deviation, so their rows
are correlated: the rows' covariance becomes ``sigma^2 I + J_d S J_d^T``
with ``J_d`` the rows' change with each mode and ``S`` the modes'
covariance, and the rows are whitened by it (generalised least squares).
The modes are thereby marginalised: the pose covariance includes them.

This module imports numpy only and nothing of fixturecad: it is
inlined into the generated standalone ``register.py``.
"""

import copy

import numpy as np

from .datums import frame_change
from .elements import cross
from .patches import box_corners, patch_box, patch_points
from .pose import motion_from_twist, vector_from_rotation
from .tolerance import coordinates, deviated, modes, moved, random_coordinates

STEP = 1e-6  # finite-difference step of the linearised datum and mode maps (mm, rad)
FREED_ZONE_MM = 20.0  # the zone of a feature let free: far beyond any print, within linearity
ROOT_CUTOFF = 1e-12  # eigenvalues of the modes' covariance below this share of the largest are zero


class FixtureTolerance:
    """Every feature's deviation modes, with their covariance as seen from the datum frame.

    ``features`` dict id -> nominal feature; ``scheme`` the DatumScheme;
    ``zone_mm`` the profile tolerance zone width; or, for an as-built part,
    ``covariances`` dict id -> (k, k) covariance of every feature's mode
    coordinates from its calibration, already in the datum frame.
    :meth:`widened` lets one mode free (its zone ``FREED_ZONE_MM``), to test
    whether it explains the touches.
    """

    def __init__(self, features, scheme, zone_mm, covariances=None):
        if not (zone_mm >= 0 and np.isfinite(zone_mm)):
            raise ValueError(f"the fixture tolerance must be a non-negative number of mm, got {zone_mm}")
        scheme.check(features)
        self.features = features
        self.scheme = scheme
        self.zone_mm = float(zone_mm)
        self.modes = {fid: modes(f) for fid, f in features.items()}
        self.slices, start = {}, 0
        for fid, m in self.modes.items():
            self.slices[fid] = slice(start, start + len(m.names))
            start += len(m.names)
        self.size = start
        # Every mode's twist (size, 6), feature and whether it grows a radius, in the slices' order.
        self.twists = np.concatenate([np.zeros((0, 6))] + [m.twists for m in self.modes.values()])
        self.mode_feature = np.array([fid for fid, m in self.modes.items() for _ in m.names])
        self.mode_radius = np.concatenate([np.zeros(0, bool)] + [m.radius for m in self.modes.values()])
        self.projection = self._gauge_projection()
        self._given = covariances
        self._covariance(())

    def _covariance(self, widened):
        """Fill ``covariance`` and its ``root``, the modes ``widened`` let free."""
        if self._given is None:
            prior = np.zeros((self.size, self.size))
            for fid, m in self.modes.items():
                zones = [FREED_ZONE_MM if (fid, k) in widened else self.zone_mm for k in range(len(m.names))]
                prior[self.slices[fid], self.slices[fid]] = np.diag((m.sigma(1.0) * zones) ** 2)
            self.covariance = self.projection @ prior @ self.projection.T
        else:
            # A calibration states its covariances in the datum frame already.
            self.covariance = np.zeros((self.size, self.size))
            for fid, s in self.slices.items():
                self.covariance[s, s] = np.asarray(self._given[fid], float)
                freed = [k for k in range(s.stop - s.start) if (fid, k) in widened]
                self.covariance[s.start + np.array(freed, int), s.start + np.array(freed, int)] += \
                    self.modes[fid].sigma(FREED_ZONE_MM)[freed] ** 2
        # S = root root^T over the modes the prior does not pin (S is singular: the gauge is projected out).
        eigen, vectors = np.linalg.eigh(self.covariance)
        kept = eigen > ROOT_CUTOFF * max(eigen.max(initial=0.0), 1e-300)
        self.root = vectors[:, kept] * np.sqrt(eigen[kept])
        self._largest = {}

    def largest_variance(self, feature):
        """The largest variance (mm^2) of how far the feature's deviation moves a touch on its patch across its
        rows (:func:`largest_row_variance`): at the patch box's corners for a plane, where it is convex, on the
        patch grid otherwise. Computed once per feature (every search on the part asks it again)."""
        known, value = self._largest.get(feature.id, (None, None))
        if known is not feature:
            points = box_corners(*patch_box(feature)) if feature.kind == "plane" else patch_points(feature)
            value = largest_row_variance(self, feature, points)
            self._largest[feature.id] = feature, value
        return value

    @property
    def point_sigma_mm(self):
        """A standard deviation (mm) of a printed point off its nominal surface: a zone's spread evenly
        over it, or, for a calibrated part, the largest of its features' position uncertainties."""
        if self._given is None:
            return self.zone_mm / (2.0 * np.sqrt(3.0))
        mm = np.array([name.endswith("_mm") for m in self.modes.values() for name in m.names])
        return float(np.sqrt(np.max(np.diag(self.covariance)[mm], initial=0.0)))

    def widened(self, fid, mode):
        """The same tolerance with one mode (index) of feature ``fid`` let free (its modes and gauge shared)."""
        other = copy.copy(self)
        other._covariance(((fid, mode),))
        return other

    def _gauge_projection(self):
        """P (K, K): mode coordinates of the printed part -> the same seen from its datum frame.

        C (6, K) is how the datum frame moves with each mode; M (K, 6) how the
        modes change when the whole part moves rigidly. Seen from the datum
        frame, the part has moved back by C delta: delta' = (I - M (C M)^-1 C) delta.
        """
        nominal = self.features
        C = np.zeros((6, self.size))
        M = np.zeros((self.size, 6))
        try:
            D0 = self.scheme.frame(nominal)
        except np.linalg.LinAlgError:
            D0 = np.full((4, 4), np.nan)
        if not np.all(np.isfinite(D0)):
            raise ValueError(f"the datum features {', '.join(self.scheme.features)} do not fix the frame")
        for fid, m in self.modes.items():
            s = self.slices[fid]
            for j in range(len(m.names)):
                columns = []
                for sign in (1.0, -1.0):
                    delta = np.zeros(len(m.names))
                    delta[j] = sign * STEP
                    changed = dict(nominal)
                    changed[fid] = deviated(m, delta)
                    D = self.scheme.frame(changed) @ np.linalg.inv(D0)
                    columns.append(np.concatenate([vector_from_rotation(D[:3, :3]), D[:3, 3]]))
                C[:, s.start + j] = (columns[0] - columns[1]) / (2 * STEP)
        for k in range(6):
            rows = []
            for sign in (1.0, -1.0):
                R, t = motion_from_twist(sign * STEP * np.eye(6)[k])
                rows.append(np.concatenate([coordinates(m, moved(nominal[fid], R, t)) for fid, m in self.modes.items()]))
            M[:, k] = (rows[0] - rows[1]) / (2 * STEP)
        CM = C @ M
        if np.linalg.matrix_rank(CM, tol=1e-6) < 6:
            raise ValueError(f"the datum features {', '.join(self.scheme.features)} do not fix the frame")
        return np.eye(self.size) - M @ np.linalg.solve(CM, C)

    def random_deviations(self, rng, zone_mm=None):
        """A printed part's mode coordinates (dict id -> (k,)): each uniform over its range, or, for
        a calibrated part, drawn from the calibration's covariance."""
        if self._given is not None and zone_mm is None:
            return {fid: rng.multivariate_normal(np.zeros(s.stop - s.start), self.covariance[s, s])
                    for fid, s in self.slices.items()}
        zone = self.zone_mm if zone_mm is None else zone_mm
        return {fid: random_coordinates(m, zone, rng) for fid, m in self.modes.items()}

    def part(self, deviations):
        """The printed features (dict id -> feature, nominal frame) of given mode coordinates."""
        return {fid: deviated(self.modes[fid], deviations[fid]) for fid in self.modes}

    def random_part(self, rng, zone_mm=None):
        """A printed part (dict id -> feature, nominal frame) with every mode uniform over its range."""
        return self.part(self.random_deviations(rng, zone_mm))

    def printed_plan(self, entries, deviations):
        """Touch-plan entries (fixture frame) made on the printed part of given mode coordinates instead of the
        model (:func:`entry_on`), the part (:meth:`part`) and its datum frame in the nominal frame (4, 4)
        (:func:`.datums.frame_change`): each feature deviated once, however many entries touch it."""
        part = self.part(deviations)
        entries = [entry_on(e, self.modes[e["feature"]], deviations[e["feature"]], part[e["feature"]]) for e in entries]
        return entries, part, frame_change(self.scheme, self.features, part)

    def twists_at(self, rotation, translation):
        """Every mode's twist (size, 6) mapped into the measurement frame at a pose.

        A fixture-frame twist (w, v) is the measurement-frame twist
        (R w, R v + t x R w).
        """
        w = self.twists[:, :3] @ rotation.T
        v = self.twists[:, 3:] @ rotation.T + cross(translation, w)
        return np.hstack([w, v])


def deviation_rows(problem, tolerance, rotation, translation, jacobian):
    """J_d (m, K): how the problem's (whitened) rows change with every mode coordinate at a pose
    (:func:`mode_rows`, the modes' twists mapped into the measurement frame)."""
    return mode_rows(tolerance, problem.row_feature, jacobian, tolerance.twists_at(rotation, translation),
                     lambda: problem.radius_derivative(rotation, translation))


def mode_rows(tolerance, row_feature, jacobian, twists, radius_rows):
    """J_d (..., m, K): how rows (their twist Jacobian (..., m, 6), each row's feature id (m,)) change with every
    mode coordinate.

    A mode moves one feature rigidly: its rows change as the fixture's rows
    do under that twist (``twists``: every mode's twist (K, 6) in the
    Jacobian's frame), the rows of other features not at all. A radius mode
    grows the feature: ``radius_rows()`` (..., m), how each row changes as its
    feature's radius grows, asked for only when one is touched.
    """
    own = np.asarray(row_feature)[:, None] == tolerance.mode_feature[None]  # (m, K)
    Jd = np.where(own, jacobian @ twists.T, 0.0)
    grown = own[:, tolerance.mode_radius]
    if grown.any():
        Jd[..., tolerance.mode_radius] = np.where(grown, radius_rows()[..., None], 0.0)
    return Jd


def whitening(tolerance, Jd, sigma_mm):
    """``x -> C^-1/2 x`` for the rows' covariance ``C = I + J_d S J_d^T / sigma^2`` (rows of x the rows; J_d
    (..., m, K) and x (..., m) or (..., m, c): each leading index its own rows).

    C is the identity plus a rank-k term ``U U^T`` (k modes, ``U = J_d root / sigma``): from U's thin SVD
    ``Q s``, ``C^-1/2 = I + Q (1 / sqrt(1 + s^2) - 1) Q^T``, in memory and time linear in the rows (a dense
    C of 10,000 rows took 800 MB and a minute). The symmetric root, not C's Cholesky factor: each whitened
    row stays nearest its own row, whatever the rows' order.
    """
    Q, s, _ = np.linalg.svd(Jd @ tolerance.root / sigma_mm, full_matrices=False)
    shrink = (1.0 / np.sqrt(1.0 + s**2) - 1.0)[..., None]

    def whiten(x):
        column = x.ndim < Q.ndim
        x = x[..., None] if column else x
        x = x + Q @ (shrink * (np.swapaxes(Q, -1, -2) @ x))
        return x[..., 0] if column else x

    return whiten


def estimated_deviations(problem, tolerance, rotation, translation):
    """The mode coordinates (K,) the touches suggest at a pose: S J_d^T C^-1 r (best linear estimate)."""
    r, J = problem.sensor_rows(rotation, translation)
    Jd = deviation_rows(problem, tolerance, rotation, translation, J)
    whiten = whitening(tolerance, Jd, problem.sigma)
    return tolerance.covariance @ Jd.T @ whiten(whiten(-r)) / problem.sigma**2


def tolerance_from_document(features, document, zone_mm=None):
    """The FixtureTolerance of a features.json document, or None for an exact part.

    ``zone_mm`` overrides the recorded tolerance zone; an as-built document's
    calibration covariances apply unless it does.
    """
    from .datums import DatumScheme

    if "datums" not in document:
        return None
    scheme = DatumScheme.from_json(document["datums"])
    calibration = document.get("calibration")
    if calibration is not None and zone_mm is None:
        covariances = {fid: np.asarray(entry["covariance"], float) for fid, entry in calibration["features"].items()}
        if set(features) - set(covariances):
            raise ValueError("an as-built part's faces have no calibration (only its sensing features): give a "
                             "--fixture-tolerance for touches anywhere")
        return FixtureTolerance(features, scheme, 0.0, covariances)
    zone = float(document.get("tolerance", {}).get("zone_mm", 0.0)) if zone_mm is None else float(zone_mm)
    # An as-built part is its own features even when taken as exact.
    return FixtureTolerance(features, scheme, zone) if zone > 0 or calibration is not None else None


def entry_on(entry, mode_set, coordinates, printed=None):
    """A touch-plan entry (fixture frame) on ``mode_set``'s feature deviated by ``coordinates`` (``printed``:
    that feature, :func:`.tolerance.deviated`, where the caller has it).

    Point touches go to the nearest point of the deviated surface; a sensor
    moves with its feature, and off a grown sphere or cylinder.
    """
    c = np.asarray(coordinates, float)
    printed = deviated(mode_set, c) if printed is None else printed
    points = np.asarray(entry["points"], float).reshape(-1, 3)
    if "sensor" not in entry:
        return {**entry, "points": printed.closest_point(points).tolist()}
    R, t = motion_from_twist(c @ mode_set.twists)
    grow = float(c @ mode_set.radius)
    points = points @ R.T + t
    points = points + grow * printed.normal_at(points)
    sensor = dict(entry["sensor"])
    for key in ("point", "center"):
        if key in sensor:
            moved_point = R @ np.asarray(sensor[key], float) + t
            sensor[key] = (moved_point + grow * printed.normal_at(moved_point)[0]).tolist()
    for key in ("normal", "direction", "axis"):
        if key in sensor:
            sensor[key] = (R @ np.asarray(sensor[key], float)).tolist()
    return {**entry, "points": points.tolist(), "sensor": sensor}


def largest_row_variance(tolerance, feature, points):
    """The largest variance (mm^2), over fixture ``points`` (n, 3), of how far the feature's deviation moves
    a touch there across its rows: along the surface normal, or off a line or a point core in every
    direction. The search's deviation bound (:mod:`.search`) rests on it."""
    s = tolerance.slices[feature.id]
    m = tolerance.modes[feature.id]
    S = tolerance.covariance[s, s]
    points = np.asarray(points, float).reshape(-1, 3)
    # Each mode moves the surface point p by omega x p + v, or a radius mode along the outward normal.
    moved = cross(m.twists[None, :, :3], points[:, None]) + m.twists[None, :, 3:]
    normal = feature.normal_at(points)
    moved[:, m.radius] = normal[:, None]
    core, _, direction, radius = feature.core()
    if core == "plane" or radius:
        moved = np.einsum("nki,ni->nk", moved, normal)[..., None]
    elif core == "line":
        moved = moved - np.einsum("nki,i->nk", moved, direction)[..., None] * direction
    return float(np.max(np.einsum("nki,kl,nli->n", moved, S, moved), initial=0.0))
