"""The stacked problem: whitened residuals and their twist Jacobian at any pose.

This module imports numpy only and nothing of fixturecad: it is
inlined into the generated standalone ``register.py``.
"""

import functools

import numpy as np

from .contacts import DIRECTION_KEYS, POINT_KEYS, residuals_and_jacobian
from .defaults import DEFAULT_SIGMA_MM, SENSOR_LEVER_MM
from .deviations import deviation_rows, mode_rows, whitening
from .noise import is_point_sensor, placement_centre, whitened
from .touches import TouchGroup

RADIUS_DERIVATIVE_REACH = 1e-2  # rad and mm: how far the pose may move before a radius derivative is redone
RADIUS_STEP_MM = 1e-4  # the radius derivative's central difference


class Problem:
    """A stacked touch plan: whitened residuals (m,) and twist Jacobian (m, 6) at any pose.

    Rows are whitened touch by touch under the sensor noise model
    (:func:`.noise.row_whitening`, at the pose evaluated) and, on a printed
    part (``tolerance``, a :class:`.deviations.FixtureTolerance`), for the
    features' deviations shared by their touches (:mod:`.deviations`). They
    stay in mm: their covariance is ``sigma_mm^2 I``.
    """

    def __init__(self, groups, sigma_mm=DEFAULT_SIGMA_MM, lever_mm=SENSOR_LEVER_MM, tolerance=None):
        if not (lever_mm > 0 and np.isfinite(lever_mm)):
            raise ValueError(f"the sensor lever must be a positive number of mm, got {lever_mm}")
        self.groups = [g if g.centre is not None else _with_centre(g) for g in groups if g.count]
        self.sigma = float(sigma_mm)
        self.lever = float(lever_mm)
        self._scale = None
        self.tolerance = tolerance if tolerance is not None and tolerance.size else None
        self._row_feature = None
        self._radius_derivative = None
        self._batch_layout = None

    @functools.cached_property
    def batches(self):
        """Rows are computed per contact type: groups of one type on different features are stacked into one call
        of the contact model. (Only when rows are asked for: the unlabelled search builds a problem per assignment
        the touches' shape admits, most of them only to search.)"""
        return _merge(self.groups)

    def point_touches(self):
        """The problem of its point and ball touches alone, on the part as drawn (itself when it is that)."""
        if self.tolerance is None and all(g.points is not None for g in self.groups):
            return self
        return Problem([g for g in self.groups if g.points is not None], self.sigma, self.lever)

    def sensor_rows(self, rotation, translation, grow=0.0):
        """Rows and Jacobian whitened for the sensor noise only (the fixture's deviations left in)."""
        rows = [self._rows(g, rotation, translation, grow) for g in self.batches]
        return np.concatenate([v for v, _ in rows]), np.concatenate([J for _, J in rows])

    def _rows(self, g, rotation, translation, grow=0.0):
        """One batch's rows (n,) and Jacobian (n, 6) whitened for the sensor noise; ``grow``: its sphere or
        cylinder grown by this many mm."""
        fixture, rho = _grown(g, grow)
        v, J = residuals_and_jacobian(g.ctype, g.sensor, fixture, rotation, translation, rho)
        g.rows = v.shape[1]
        if not is_point_sensor(g.sensor):
            v, J = whitened(v, J, g.centre, self.lever)
        return v.reshape(-1), J.reshape(-1, 6)

    def evaluate(self, rotation, translation):
        r, J = self.sensor_rows(rotation, translation)
        if self.tolerance is None:
            return r, J
        whiten = whitening(self.tolerance, deviation_rows(self, self.tolerance, rotation, translation, J), self.sigma)
        return whiten(r), whiten(J)

    def as_noise(self):
        """The same touches with the part's deviations taken as independent noise on every row."""
        sigma = float(np.hypot(self.sigma, self.tolerance.point_sigma_mm))
        return Problem(self.groups, sigma, self.lever)

    def radius_derivative(self, rotation, translation):
        """How each (whitened) row changes as its feature's radius grows, shape (m,) per mm.

        Exact where :func:`radius_change` knows it; elsewhere a central difference of the batch's rows, kept
        while the pose stays within ``RADIUS_DERIVATIVE_REACH`` (rad, mm): it hardly changes with the pose, and
        it costs two evaluations of the batch.
        """
        if self._radius_derivative is not None:
            R0, t0, value = self._radius_derivative
            if np.abs(rotation - R0).max() < RADIUS_DERIVATIVE_REACH and np.abs(translation - t0).max() < RADIUS_DERIVATIVE_REACH:
                return value
        self._count_rows()
        value = np.concatenate([np.zeros(0)] + [
            radius_rows(g, g.count * g.rows, lambda grow: self._rows(g, rotation, translation, grow)[0])
            for g in self.batches])
        self._radius_derivative = (rotation, translation, value)
        return value

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

    def evaluate_batch(self, rotations, translations, without=None):
        """Residuals (K, m) and fixture-frame Jacobians (K, m, 6) at K poses in one call, whitened as
        :meth:`evaluate` whitens them (its rows in the groups' order). ``without`` (K,): a touch index each
        pose's problem leaves out (:meth:`without`; -1: none), its rows zero.

        Each pose's sensors are mapped into the fixture frame (``R^T (x - t)``),
        all K copies stacked into one call of the contact model at the identity
        a contact type (:attr:`batches`).
        The translation columns give the fixture-frame translation ``v`` that
        moves the pose to ``t + R v``. In that frame a printed part's mode
        moves the rows by ``J twist`` at every pose (:func:`.deviations.mode_rows`;
        :meth:`evaluate` maps the twist to the measurement frame instead).
        """
        r, J, feature, touch = self._batch_rows(rotations, translations)
        if without is not None:
            # (a left-out touch's zero rows are zero in J_d too: whitening leaves them zero and the others as
            # the problem without it whitens them)
            kept = touch[None] != np.asarray(without)[:, None]
            r, J = r * kept, J * kept[..., None]
        if self.tolerance is None:
            return r, J

        def radius_derivative():
            K = len(rotations)
            drho = np.concatenate([
                radius_rows(g, (K, g.count * rows),
                            lambda grow: self._group_rows(g, rotations, translations, grow)[0].reshape(K, -1))
                for g, rows in zip(self.groups, self._batch_layout[2])], axis=1)
            return drho if without is None else drho * kept

        Jd = mode_rows(self.tolerance, feature, J, self.tolerance.twists, radius_derivative)
        whiten = whitening(self.tolerance, Jd, self.sigma)
        return whiten(r), whiten(J)

    def _batch_rows(self, rotations, translations, grow=0.0):
        """:meth:`evaluate_batch`'s rows whitened for the sensor noise only, and each row's feature id and touch
        index (m,); ``grow``: every sphere and cylinder grown by this many mm."""
        K = len(rotations)
        # One call of the contact model a contact type (:attr:`batches`), its rows then put in the groups' order.
        parts = [self._group_rows(b, rotations, translations, grow) for b in self.batches]
        if self._batch_layout is None:  # the same at every pose
            for b, (v, _) in zip(self.batches, parts):
                b.rows = v.shape[1]  # (a touch's, as :meth:`_rows` counts them)
            self._batch_layout = self._layout()
        feature, touch, _, order = self._batch_layout
        return (np.concatenate([v.reshape(K, -1) for v, _ in parts], axis=1)[:, order],
                np.concatenate([J.reshape(K, -1, 6) for _, J in parts], axis=1)[:, order], feature, touch)

    def _layout(self):
        """Each row's feature id and touch index (m,) in the groups' order, each group's rows a touch, and where
        each row lies in the batches' order (:attr:`row_touch`) (m,)."""
        touch = self.row_touch
        order = np.concatenate([np.flatnonzero(touch == t) for g in self.groups for t in g.index])
        return (self.row_feature[order], touch[order], [int(np.count_nonzero(touch == g.index[0])) for g in self.groups],
                order)

    def _group_rows(self, g, rotations, translations, grow=0.0):
        """One group's rows (K count, k) and Jacobian (K count, k, 6) at K poses, whitened for the sensor noise:
        its sensors mapped into the fixture frame, stacked into one call of the contact model at the identity."""
        K = len(rotations)
        geometry = {}
        for key, value in g.sensor.geometry.items():
            value = np.broadcast_to(value, (g.count,) + np.shape(value)[1:] if np.ndim(value) else (g.count,))
            if key in POINT_KEYS:
                moved = (value[None] - translations[:, None]) @ rotations
            elif key in DIRECTION_KEYS:
                moved = value[None] @ rotations
            else:
                moved = np.broadcast_to(value, (K,) + value.shape)
            geometry[key] = moved.reshape((K * g.count,) + moved.shape[2:])
        sensor = type(g.sensor)(g.sensor.kind, g.sensor.fixed, geometry)
        fixture, rho = _grown(g, grow)
        if g.feature is None:  # a batch of several features: its fixture geometry is per touch, as the sensors' is
            fixture = type(fixture)(fixture.kind, fixture.fixed, {
                key: np.tile(value, (K,) + (1,) * (np.ndim(value) - 1)) for key, value in fixture.geometry.items()})
        v, J = residuals_and_jacobian(g.ctype, sensor, fixture, np.eye(3), np.zeros(3), np.tile(rho, K))
        if not is_point_sensor(g.sensor):
            centres = (g.centre[None] - translations[:, None]) @ rotations
            v, J = whitened(v, J, centres.reshape(-1, 3), self.lever)
        return v, J

    def without(self, touch):
        """The plan with one touch (by caller index) left out."""
        groups = []
        for g in self.groups:
            keep = g.index != touch
            if keep.all():
                groups.append(g)
            elif keep.any():
                groups.append(subset(g, keep))
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


def radius_change(group):
    """How each row of a group changes as its feature's radius grows, per mm, where that is known exactly: 0 on a
    feature with no radius (its rows do not hold one), -1 for point touches on a sphere or cylinder (their row is
    their distance from the surface, which the growth takes off); None for a sensor on one (a central
    difference)."""
    if "r" not in group.fixture.geometry:
        return 0.0
    return -1.0 if group.ctype.sensor == "P" else None


def radius_rows(group, shape, rows_at):
    """How a group's rows (``shape``) change as its feature's radius grows, per mm: :func:`radius_change`
    where it is exact, else the central difference of ``rows_at(grow)`` (its rows with the radius grown)."""
    change = radius_change(group)
    return np.full(shape, change) if change is not None else _radius_difference(rows_at)


def _radius_difference(rows_at):
    """How rows change as their features' radii grow, per mm: the central difference of ``rows_at(grow)``."""
    return (rows_at(RADIUS_STEP_MM) - rows_at(-RADIUS_STEP_MM)) / (2 * RADIUS_STEP_MM)


def _grown(group, grow):
    """The group's fixture geometry and touch offsets (rho) with its sphere or cylinder grown by ``grow`` mm: its
    radius, and the offset of the touches that include it."""
    fixture, rho = group.fixture, group.rho
    if grow and "r" in fixture.geometry:
        fixture = type(fixture)(fixture.kind, fixture.fixed, {**fixture.geometry, "r": fixture["r"] + grow})
        rho = rho + grow
    return fixture, rho


def _with_centre(group):
    """The group with its sensor placement centres filled in from the sensor's geometry."""
    centre = placement_centre(group.sensor.kind, group.sensor.geometry)
    group.centre = np.broadcast_to(np.asarray(centre, dtype=np.float64), (group.count, 3)).copy()
    return group


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


def subset(group, keep):
    """The group of only the touches ``keep`` (indices into it)."""
    def cut(side):
        geometry = {}
        for key, value in side.geometry.items():
            value = np.asarray(value)
            geometry[key] = value[keep] if value.ndim >= 1 and value.shape[0] == len(keep) else value
        return type(side)(side.kind, side.fixed, geometry)

    sensor = cut(group.sensor)
    rho = group.rho[keep]
    points = None if group.points is None else group.points[keep]
    approach = None if group.approach is None else group.approach[keep]
    return TouchGroup(group.feature, group.ctype, sensor, group.fixture, rho, group.index[keep], points, group.rows,
                      approach, group.centre[keep], group.located)
