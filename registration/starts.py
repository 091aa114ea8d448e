"""Starting poses when no nominal pose is given: closed forms, then sweeps.

Sensors' given contact points, taken as point touches on their features,
by the complete search where they fix a pose; a plane and a cylinder by the
paper's Example Two steps; three or more sphere centres by Kabsch; otherwise
a plane's normal (from three touches, or a plane sensor) or the line through
two sphere centres fixes one direction and a sweep about it, with the
translation solved by batched Gauss-Newton (or from a sphere centre); random
rotations when nothing fixes a direction.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

from dataclasses import dataclass

import numpy as np

from .elements import element, perpendicular_basis
from .fits import combinations, frame_from, kabsch, plane_normal, sphere_centre_candidates
from .pose import random_rotation, rotation_aligning, rotation_from_vector
from .problem import Problem
from .search import search, threshold_mm2
from .touches import point_touches
from .verdict import EXTENT_SIGMAS

SWEEP_STEPS = 24  # angles tried about a measured plane normal when no pose is given
PLANE_CYLINDER_STEPS = 180  # axis directions tried on the cone about the plane normal
NORMAL_SWEEP_RAD = np.radians(2.0)  # plane touches this unsure of the normal (3 sigma) sweep it ...
NORMAL_SWEEP_STEPS = 60  # ... in this many turns about their line
CIRCLE_ITERATIONS = 6  # Gauss-Newton steps fitting a circle of the cylinder's radius to the touches
FALLBACK_STARTS = 96  # rotations tried when no plane gives a direction
UNSWEPT_PER_BLOCK = 6  # fallback starts per candidate centre refined before stopping at a solution


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
            n_meas = plane_normal(g.points)
            if n_meas is not None:
                pairs.append((g.count, g.feature.normal, n_meas))
    pairs.sort(key=lambda item: -item[0])
    return [(a, b) for _, a, b in pairs]


def _anchor(feature):
    for name in ("center", "point"):
        if hasattr(feature, name):
            return np.asarray(getattr(feature, name), float)
    return np.zeros(3)


@dataclass
class Starts:
    """Starting poses (R, t), in ``blocks`` equal blocks (one per candidate sphere centre).

    ``swept``: each block is made of sweeps of ``SWEEP_STEPS`` rotations about
    a measured direction, whose local minima are all refined; ``far``: the
    rotations are random, far from any solution, so a refinement may take many
    slow steps and is never abandoned.
    """

    poses: list
    blocks: int = 1
    swept: bool = False
    far: bool = False


def located_contact_points(problem, centres):
    """Sensors whose contact points are given, on planes, spheres and cylinders: each point lies on its
    feature, so with the point touches they are point touches, and their complete search (:mod:`.search`)
    finds every pose that puts them there; the sensors' own rows then refine each."""
    # (A ball sensor's centre is its contact point only when that is given as ``o``.)
    located = [g for g in problem.groups if g.points is None and g.located and element(g.feature.kind).surface
               and not (g.ctype.sensor == "S" and "o" not in g.sensor.geometry)]
    if not located:
        return None
    groups = [g for g in problem.groups if g.points is not None]
    # On a printed part the points are searched on the drawing, each off it by at most half the zone, which the
    # noise widened by that lets pass (the test's quantile exceeds the touches' count): a start needs no proof,
    # and the part's deviation modes slow the search (the six-boss design: 130 s a call instead of 4).
    zone = 0.0 if problem.tolerance is None else problem.tolerance.zone_mm
    points = Problem(groups + [point_touches(g.feature, g.centre, g.index) for g in located],
                     float(np.hypot(problem.sigma, zone / 2.0)), problem.lever)
    poses = search(points, threshold_mm2(points)).poses
    return Starts(poses, len(poses)) if poses else None


def plane_and_cylinder(problem, centres):
    """Closed form: the paper's Example Two steps (:func:`plane_cylinder_starts`)."""
    poses = plane_cylinder_starts(problem)
    return Starts(poses, len(poses)) if poses else None


def sweep_about_a_plane_normal(problem, centres):
    """A plane's measured normal fixes two rotations: sweep the third, either sign of the normal."""
    for n_fix, n_meas in _plane_directions(problem):
        rotations = []
        for sign in (1.0, -1.0):
            R0 = rotation_aligning(n_fix, sign * n_meas)
            rotations += [rotation_from_vector(2.0 * np.pi * k / SWEEP_STEPS * n_meas) @ R0 for k in range(SWEEP_STEPS)]
        return _translated(problem, rotations, centres, swept=True)
    return None


def kabsch_on_sphere_centres(problem, centres):
    """Closed form: Kabsch on three or more sphere centres, one start per set of candidate centres."""
    if len(centres) < 3:
        return None
    fixed = np.array([f for f, _ in centres])
    poses = [pose for pose in (kabsch(fixed, np.array(c)) for c in combinations([m for _, m in centres]))
             if pose[0] is not None]
    return Starts(poses, len(poses)) if poses else None


def sweep_about_two_sphere_centres(problem, centres):
    """The line through two sphere centres fixes two rotations: sweep about it."""
    if len(centres) < 2:
        return None
    (f1, m1), (f2, m2) = centres[:2]
    rotations = []
    for c1 in m1:
        for c2 in m2:
            axis = (c2 - c1) / max(np.linalg.norm(c2 - c1), 1e-12)
            R0 = rotation_aligning(f2 - f1, axis)
            rotations += [rotation_from_vector(2.0 * np.pi * k / SWEEP_STEPS * axis) @ R0 for k in range(SWEEP_STEPS)]
    return _translated(problem, rotations, centres, swept=True)


def random_rotations(problem, centres):
    """Nothing fixes a direction: seeded random rotations."""
    rng = np.random.default_rng(0)
    return _translated(problem, [random_rotation(rng) for _ in range(FALLBACK_STARTS)], centres, far=True)


# The start strategies, first that applies wins: one entry per kind of fixture.
STRATEGIES = (located_contact_points, plane_and_cylinder, sweep_about_a_plane_normal, kabsch_on_sphere_centres,
              sweep_about_two_sphere_centres, random_rotations)


def initial_poses(problem) -> Starts:
    """Starting poses without a nominal pose: the first strategy of ``STRATEGIES`` that applies."""
    centres = sphere_centre_candidates([g for g in problem.groups if g.points is not None])
    return next(starts for starts in (strategy(problem, centres) for strategy in STRATEGIES) if starts is not None)


def _translated(problem, rotations, centres, swept=False, far=False):
    """Rotations with their translations: from each candidate centre of a sphere, else from the mean touch."""
    if centres:
        f, ms = centres[0]
        return Starts([(R, m - R @ f) for m in ms for R in rotations], len(ms), swept, far)
    # Every touch's place in the measurement frame, its centre (a point touch's point, a sensor's placement
    # centre, on or near its contact), against its feature's anchor.
    placed = [g for g in problem.groups if g.centre is not None]
    if placed:
        measured = np.concatenate([g.centre for g in placed]).mean(axis=0)
        anchors = np.concatenate([np.tile(_anchor(g.feature), (g.count, 1)) for g in placed]).mean(axis=0)
    else:
        measured = anchors = np.zeros(3)
    return Starts([(R, measured - R @ anchors) for R in rotations], 1, swept, far)


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
    n_meas = plane_normal(plane.points)
    n_fix, a_fix = plane.feature.normal, cylinder.feature.axis
    cos_a = float(n_fix @ a_fix)
    if n_meas is None or abs(cos_a) > 0.999 or abs(cos_a) < 1e-3:
        return []
    sin_a = np.sqrt(1.0 - cos_a**2)
    radius, pts = cylinder.feature.radius, cylinder.points
    theta = np.linspace(0.0, 2.0 * np.pi, steps, endpoint=False)
    # The fixture's origin of the frame: where its axis meets its plane.
    origin_fix = cylinder.feature.point + ((plane.feature.point - cylinder.feature.point) @ n_fix / cos_a) * a_fix
    frame_fix = frame_from(n_fix, a_fix)
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
                R = frame_from(n, s) @ frame_fix.T
                on_axis = centres[k, c, 0] * u1[k] + centres[k, c, 1] * u2[k]
                along = n @ (plane.points.mean(axis=0) - on_axis) / (n @ s)
                starts.append((R, on_axis + along * s - R @ origin_fix))
    return starts


def best_starts(problem, starts: Starts):
    """Solve each start's translation (batched Gauss-Newton) and order the starts.

    Returns (poses, first): the ``first`` ones are those to refine in any
    case: in sweeps, every start whose cost is no higher than its two
    neighbours; otherwise the best few of each block. The rest follow by cost.
    """
    if not starts.poses:
        return [], 0
    Rs = np.array([R for R, _ in starts.poses])
    ts = np.array([t for _, t in starts.poses], dtype=float)
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
    if starts.swept:
        sweep = cost.reshape(-1, SWEEP_STEPS)
        minima = (sweep <= np.roll(sweep, 1, axis=1)) & (sweep <= np.roll(sweep, -1, axis=1))
        chosen = [k for k in order if minima.reshape(-1)[k]]
    else:
        size = len(starts.poses) // starts.blocks
        block = np.arange(len(starts.poses)) // size
        chosen = [k for k in order if np.sum(block[order[: list(order).index(k)]] == block[k]) < UNSWEPT_PER_BLOCK]
    picked = set(chosen)
    ordered = chosen + [k for k in order if k not in picked]
    return [(Rs[k], ts[k]) for k in ordered], len(chosen)
