"""Calibration of a printed fixture: its as-built features from points measured on it.

Points measured on the printed part (a CMM, or many probe touches), in a
frame fixturecad does not know, are fitted jointly for the pose of the part
and the deviation modes (:mod:`.tolerance`) of every feature: Gauss-Newton
on the point-on-feature rows of the contact model, the modes restricted to
those the datum frame leaves (:mod:`.deviations`), so the as-built features
come out in the part's own datum frame. Their covariance is what the
registration then uses in place of the print tolerance.

This module imports numpy only and nothing of fixturecad.
"""

from dataclasses import dataclass

import numpy as np

from .deviations import FixtureTolerance, deviation_rows
from .problem import Problem
from .solve import solve
from .touches import build_groups
from .pose import apply_twist
from .tolerance import departure_mm, deviated

ITERATIONS = 12  # Gauss-Newton steps at most; it converges in three or four
CONVERGED = 1e-9  # a step this small (mm, rad at the part's size) ends the iteration
RANK_TOLERANCE = 1e-9  # singular values below this fraction of the largest leave a parameter undetermined
FIRST_POINTS = 8  # points a feature the first pose is solved from
FAR_MM = 1.0  # a point this far from its feature after the fit (beyond the zone) is not on it


@dataclass
class Calibration:
    """The fitted part.

    ``features`` dict id -> as-built feature (datum frame); ``deviations``
    dict id -> mode coordinates (k,) (mm or rad, :mod:`.tolerance` names);
    ``covariances`` dict id -> (k, k); ``fixture2meas`` the pose of the
    datum frame in the measurement frame; ``rms_mm`` dict id -> RMS residual;
    ``counts`` dict id -> number of points; ``worst_mm`` dict id -> the
    largest distance of the as-built patch from the nominal one;
    ``sigma_mm`` the noise the covariance assumes (the stated sigma or the
    residual RMS, whichever is larger); ``mode_names`` dict id -> the names
    of the deviation coordinates.
    """

    features: dict
    deviations: dict
    covariances: dict
    fixture2meas: np.ndarray
    rms_mm: dict
    counts: dict
    worst_mm: dict
    sigma_mm: float
    mode_names: dict


def calibrate(features, scheme, points, sigma_mm, zone_mm, rows=None):
    """Fit the pose and every feature's deviation modes to measured points.

    Parameters
    ----------
    features : dict id -> nominal feature
    scheme : DatumScheme fixing the frame
    points : dict id -> array-like, shape (n, 3), mm, any frame
    sigma_mm : float, measurement noise (mm, each axis)
    zone_mm : float, the recorded tolerance zone (only for the first pose)
    rows : dict id -> file line numbers of the points, for messages

    Raises ValueError (one line) when a feature is not measured, its points
    leave a mode undetermined, or the points do not lie on this fixture.
    """
    points = {fid: np.asarray(p, float).reshape(-1, 3) for fid, p in points.items() if len(p)}
    missing = [fid for fid in features if fid not in points]
    if missing:
        raise ValueError(f"no points on feature {', '.join(missing)}: every sensing feature must be measured")
    tolerance = FixtureTolerance(features, scheme, zone_mm)
    # Orthonormal basis of the deviations the datum frame leaves.
    u, s, _ = np.linalg.svd(tolerance.projection)
    basis = u[:, s > 0.5]
    # First pose from a few points a feature, spread over it: the best local solution.
    rng = np.random.default_rng(0)
    few = {fid: p[rng.choice(len(p), FIRST_POINTS, replace=False)] if len(p) > FIRST_POINTS else p
           for fid, p in points.items()}
    first = solve(Problem(build_groups(features, few), float(np.hypot(sigma_mm, zone_mm))))[0]
    if first.rank < 6:
        raise ValueError("the points do not fix the part's pose: measure every sensing feature")
    R, t = first.rotation, first.translation
    z = np.zeros(basis.shape[1])
    for _ in range(ITERATIONS):
        current = _as_built(tolerance, basis @ z)
        problem = Problem(build_groups(current, points), sigma_mm)
        r, J = problem.evaluate(R, t)
        A = np.hstack([J, deviation_rows(problem, tolerance, R, t, J) @ basis])
        scale = np.maximum(np.linalg.norm(A, axis=0), 1e-300)
        step, *_ = np.linalg.lstsq(A / scale, -r, rcond=None)
        step /= scale
        R, t = apply_twist(R, t, step[:6])
        z = z + step[6:]
        if np.abs(step * scale).max() < CONVERGED * max(np.sqrt(np.mean(r**2)), 1e-12) + 1e-12:
            break
    current = _as_built(tolerance, basis @ z)
    problem = Problem(build_groups(current, points), sigma_mm)
    r, J = problem.evaluate(R, t)
    A = np.hstack([J, deviation_rows(problem, tolerance, R, t, J) @ basis])
    _check_determined(A, basis, tolerance)
    row_feature = problem.row_feature
    rms = {fid: float(np.sqrt(np.mean(r[row_feature == fid] ** 2))) for fid in features}
    _check_on_fixture(problem, r, points, rows, zone_mm)
    noise = max(sigma_mm, float(np.sqrt(np.sum(r**2) / max(len(r) - A.shape[1], 1))))
    covariance = noise**2 * np.linalg.inv(A.T @ A)
    delta = basis @ z
    delta_cov = basis @ covariance[6:, 6:] @ basis.T
    out = Calibration({}, {}, {}, np.eye(4), rms, {fid: len(p) for fid, p in points.items()}, {}, noise,
                      {fid: m.names for fid, m in tolerance.modes.items()})
    for fid, sl in tolerance.slices.items():
        out.deviations[fid] = delta[sl]
        out.covariances[fid] = delta_cov[sl, sl]
        out.features[fid] = current[fid]
        out.worst_mm[fid] = departure_mm(features[fid], current[fid])
    out.fixture2meas[:3, :3], out.fixture2meas[:3, 3] = R, t
    return out


def _as_built(tolerance, delta):
    return {fid: deviated(m, delta[tolerance.slices[fid]]) for fid, m in tolerance.modes.items()}


def _check_determined(A, basis, tolerance):
    """Raise ValueError naming the feature and mode the points leave undetermined."""
    scale = np.maximum(np.linalg.norm(A, axis=0), 1e-300)
    _, s, vt = np.linalg.svd(A / scale, full_matrices=False)
    weak = s < RANK_TOLERANCE * s[0]
    if not weak.any():
        return
    unit = vt[np.flatnonzero(weak)[0]]  # in columns of equal weight
    if np.sum(unit[:6] ** 2) > 0.5:
        raise ValueError("the points do not fix the part's pose: measure every sensing feature")
    direction = unit / scale
    # The mode that moves most along the undetermined direction, in units of its tolerance.
    delta = basis @ direction[6:]
    best = None
    for fid, sl in tolerance.slices.items():
        m = tolerance.modes[fid]
        size = np.abs(delta[sl]) / m.half_range
        k = int(np.argmax(size))
        if best is None or size[k] > best[0]:
            best = (size[k], fid, m.names[k])
    raise ValueError(f"the points on {best[1]} leave its {best[2]} undetermined: "
                     "measure more points, spread over the whole patch")


def _check_on_fixture(problem, r, points, rows, zone_mm):
    """Raise ValueError when a point lies far from its feature: not a point of this fixture."""
    per_touch = {}
    for touch, value in zip(problem.row_touch, r):
        per_touch[int(touch)] = per_touch.get(int(touch), 0.0) + float(value) ** 2
    touch, worst = max(per_touch.items(), key=lambda item: item[1])
    distance = np.sqrt(worst)
    if distance > FAR_MM + zone_mm:
        feature_of = {int(i): g.feature.id for g in problem.groups for i in g.index}
        where = f"point {touch + 1}"
        if rows is not None:
            order = [(fid, k) for fid in points for k in range(len(points[fid]))]
            fid, k = order[touch]
            where = f"row {rows[fid][k]}"
        raise ValueError(f"{where} lies {distance:.3g} mm from {feature_of[touch]} after the fit: "
                         "these points are not from this fixture, or the feature ids are wrong")

