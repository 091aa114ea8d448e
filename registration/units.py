"""Lengths in another unit than mm, and ball centres registered as probe points.

fixturecad reads mm. Touches (or measured points) in metres or inches spread
1000 or 25.4 times less than the features they name, in micrometres 1000
times more: their spread is compared with how far those features reach on
the fixture (the reachable touches a build stores, or else the cube root of
the part's volume), and a unit that brings the two together is named.
Touches made with a ball tip but registered as points lie the tip's radius
outside every surface: :func:`ball_radius_estimate` finds that common offset.
A noise over 1 mm or a ball larger than the features is micrometres given as mm.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

# The units a file may be converted from (--units), in mm.
UNITS_MM = {"mm": 1.0, "m": 1000.0, "in": 25.4}
UNIT_NAMES = {"m": "metres", "in": "inches", "um": "micrometres"}
# Touches spread over between these shares of their features' reach are taken to be in mm: a plan needs
# some spread to locate a part, and touches on it cannot spread far beyond it (a ball tip adds its radius).
SMALLEST_SHARE = 0.1
LARGEST_SHARE = 3.0
# The slips looked for: the factor by which mm are too many (> 1) or too few (< 1).
SLIPS = {"m": 1000.0, "in": 25.4, "um": 1e-3}
MAX_NOISE_MM = 1.0  # a touch noise beyond any probe: --noise 10 is 10 um given as mm
RADIUS_STEP_MM = 1e-3  # the finite-difference step of the ball radius, and its least value
COMMON_TIPS_MM = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0)  # ball radii of common styli: where the search for one starts


def check_noise(value_mm, option):
    """Refuse (one-line ValueError) a noise standard deviation beyond any probe: micrometres given as mm."""
    if value_mm > MAX_NOISE_MM:
        raise ValueError(f"{option} is in mm and at most {MAX_NOISE_MM:g}, got {value_mm:g}: "
                         f"for {value_mm:g} um give {option} {value_mm / 1000:g}")


def check_ball_radius(radius_mm, reach):
    """Refuse (one-line ValueError) a ball tip larger than the ``reach`` (mm) of the features it touches: not mm."""
    if reach > 0 and radius_mm > reach:
        raise ValueError(f"--ball-radius is in mm: {radius_mm:g} mm is more than the touched features reach "
                         f"({reach:.4g} mm); for {radius_mm:g} um give {radius_mm / 1000:g}")


def spread_mm(points):
    """How far the points (n, 3) lie from their centroid at most, mm: linear in n."""
    points = np.asarray(points, float).reshape(-1, 3)
    return float(np.linalg.norm(points - points.mean(axis=0), axis=1).max(initial=0.0))


def reach_mm(feature_ids, candidates, volume_mm3):
    """How far the named features reach from their centre, mm: the spread of their reachable touches
    (``candidates`` by feature id, fixture frame), or without them the cube root of the part's volume."""
    stored = [candidates[f] for f in feature_ids if candidates and len(candidates.get(f, ()))]
    if stored:
        return spread_mm(np.concatenate(stored))
    return float(volume_mm3) ** (1.0 / 3.0) if volume_mm3 else 0.0


def check_spread(points, feature_ids, candidates, volume_mm3, what="the touches"):
    """Refuse (one-line ValueError) points (n, 3) whose spread a unit slip explains: it is far from the
    features' reach, and within it once converted from metres, inches or micrometres."""
    spread, reach = spread_mm(points), reach_mm(feature_ids, candidates, volume_mm3)
    if not (spread > 0 and reach > 0) or SMALLEST_SHARE <= spread / reach <= LARGEST_SHARE:
        return
    for unit, factor in SLIPS.items():
        if SMALLEST_SHARE <= factor * spread / reach <= LARGEST_SHARE:
            remedy = "convert them to mm" if unit == "um" else f"convert them to mm or pass --units {unit}"
            remedy += "; --units mm if they are mm"
            raise ValueError(f"{what} spread over {spread:.4g} mm but the features they name reach {reach:.4g} mm: "
                             f"they look like {UNIT_NAMES[unit]}, fixturecad reads mm ({remedy})")


def from_units(points, unit):
    """Points (or lengths) given in ``unit`` (a key of :data:`UNITS_MM`), in mm."""
    return np.asarray(points, float) * UNITS_MM[unit]


def ball_radius_estimate(features, touches, poses=(), steps=4):
    """The radius (mm) of a ball tip whose centres ``touches`` (by feature id, (n, 3), mm) would be: every
    touch lies that far outside its surface. The rows are nearly linear in it, so a few Gauss-Newton steps
    over the pose and the radius find it, from each of ``poses`` (4x4) and of the best poses the closed-form
    starts find for common tips; the radius that fits best."""
    from .pose import apply_twist, rt_from_fixture2meas
    from .problem import Problem
    from .solve import solve
    from .touches import build_groups

    def rows(radius, rotation, translation):
        return Problem(build_groups(features, touches, radius)).sensor_rows(rotation, translation)

    starts = [*poses, *(solve(Problem(build_groups(features, touches, tip)), None, complete=False)[0].fixture2meas
                        for tip in COMMON_TIPS_MM)]
    fits = []
    for start in starts:
        rotation, translation = rt_from_fixture2meas(np.asarray(start, float))
        radius = RADIUS_STEP_MM  # a ball, however small: its rows are those of every radius
        for _ in range(steps):
            r, J = rows(radius, rotation, translation)
            d = (rows(radius + RADIUS_STEP_MM, rotation, translation)[0] - r) / RADIUS_STEP_MM
            step = np.linalg.lstsq(np.column_stack([J, d]), -r, rcond=None)[0]
            rotation, translation = apply_twist(rotation, translation, step[:6])
            radius = max(radius + float(step[6]), RADIUS_STEP_MM)
        fits.append((float(np.linalg.norm(rows(radius, rotation, translation)[0])), radius))
    return min(fits)[1]
