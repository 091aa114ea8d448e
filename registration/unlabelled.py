"""Unlabelled touches: every pose that passes under some assignment of the touches to the features.

A touch without a label is a point (or ball) touch on some surface feature's
patch: a plane, a sphere or a cylinder. The labelled search (:mod:`.search`)
needs each touch's element; a first branch and bound over the same cells
(rotation boxes about ``R0``, boxes of the image ``y`` of the touches'
centroid) finds which features each touch may lie on:

* in a cell, touch i lies within its turn ``delta rho_i`` of the box
  ``a_i + [ylo, yhi]`` (``a_i = R0^T b_i``); for each feature f, the ``y``
  that keep it within that turn of f's patch box, grown as the labelled search
  grows it, form a box, and ``l_if`` is the least distance of f's element
  from the touch's places over that box, less the turn (infinite when the box
  is empty);
* whatever the assignment, touch i's distance is at least ``min_f l_if``, and
  at least ``min_f l_if - e_f`` on a printed part (``e_f`` the deviation
  bound, :func:`.search.deviation_bound`), so the cost of any pose of the
  cell is at least the sum of those minima squared: a cell over T holds no
  pose that passes under any assignment and is dropped;
* f is a *candidate* of touch i in the cell when ``l_if <= sqrt(T) + e_f``: a
  pose of the cell that passes under an assignment gives each touch a
  candidate (its own share of the cost is at most T), so the assignments of
  candidates hold every such pose, and ``y`` lies in each touch's union of its
  candidates' boxes.

A cell whose candidates leave at most ``MAX_ASSIGNMENTS`` assignments goes,
under each, to the labelled search, which finds every pose of the cell that
passes under it; the others are split as the labelled search splits. So every
pose that passes under some assignment is found under that assignment.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import itertools

import numpy as np

from .defaults import DEFAULT_SIGMA_MM, MAX_COORDINATE_MM, SENSOR_LEVER_MM
from .patches import patch_box
from .pose import rotation_from_vector
from .problem import Problem
from .search import (LEAF_FRACTION, MAX_CELLS, MAX_LEVELS, Cells, Tree, across, beyond_pi, contact_offset,
                     deviation_bound, first_cells, least_over_box, patch_growth, split, threshold_mm2, turned_points)
from .solve import Solutions, solve, told_apart
from .touches import point_touches
from .verdict import EXTENT_TOLERANCE_MM, same_pose

MAX_ASSIGNMENTS = 4  # a cell whose candidates leave at most this many assignments is searched under each
MIN_JOINT = 6  # touches with one candidate bounded together (:meth:`Labels.kept`), or searched alone, when at
# least this many
LABEL_TURN_MM = 10.0  # a cell whose turn moves a touch at most this much is branched on a touch's feature
CHUNK = 8192  # cells evaluated at once (memory: cells x candidate pairs x 3)
RELAX = 100.0  # when no pose passes under any assignment, the threshold is raised by this factor ...
RELAX_ROUNDS = 4  # ... at most this many times, to find the assignments the least-cost poses take
FALLBACK_ASSIGNMENTS = 3  # ... and the best this many of them are refined
LOCAL_ROUNDS = 2  # a search that stops: each touch put on its nearest feature this many times from each start


def assigned_problem(groups, features, points, index, assignment, ball_radius_mm, sigma, lever, tolerance, made=None):
    """The labelled problem: the touch groups, and the unlabelled ``points`` on the features ``assignment``
    (a feature id per point; None: the point left out) gives them. ``made``: a dict that keeps the touch groups
    made, by feature and touches (a search makes the same ones under hundreds of assignments)."""
    assignment = np.asarray(assignment, dtype=object)
    made = {} if made is None else made
    extra = []
    for fid in dict.fromkeys(assignment):
        if fid is None:
            continue
        on = assignment == fid
        key = (fid, on.tobytes())
        if key not in made:
            made[key] = point_touches(features[fid], points[on], index[on], ball_radius_mm)
        extra.append(made[key])
    return Problem(list(groups) + extra, sigma, lever, tolerance)


def check_unlabelled(points):
    """The unlabelled touches as an array (n, 3), mm (none: (0, 3)); a ValueError names what is wrong."""
    if points is None:
        return np.zeros((0, 3))
    points = np.asarray(points, dtype=np.float64)
    if points.size == 0:
        return np.zeros((0, 3))
    if points.ndim == 1 and points.size == 3:
        points = points[None]
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"unlabelled touches must have shape (n, 3) in mm, got shape {points.shape}")
    if not np.all(np.isfinite(points)):
        raise ValueError("unlabelled touches must be finite, got NaN or inf")
    if np.abs(points).max() > MAX_COORDINATE_MM:
        raise ValueError(f"unlabelled touches lie beyond {MAX_COORDINATE_MM:g} mm: check the units")
    return points


def _surfaces(features):
    surfaces = [f for f in features.values() if f.surface]  # what an unlabelled touch may lie on
    if not surfaces:
        raise ValueError("an unlabelled touch needs a plane, a sphere or a cylinder to lie on: the fixture has none")
    return surfaces


def _distances(surfaces, points, rotation, translation, ball_radius_mm):
    """Each touch's distance (n, F) mm from each surface at a pose, and whether it lies on the surface's patch
    (within the tolerance the verdict allows)."""
    local = (points - translation) @ rotation
    distance = np.column_stack([f.signed_distance(local) - ball_radius_mm for f in surfaces])
    inside = np.column_stack([np.asarray(f.contains(local, EXTENT_TOLERANCE_MM), bool) for f in surfaces])
    return distance, inside


def nearest_assignment(features, points, initial_pose, ball_radius_mm=0.0):
    """Each touch's feature near a nominal pose (4, 4): the nearest surface whose patch it lies on (the nearest
    of all when it lies on none)."""
    surfaces = _surfaces(features)
    pose = np.asarray(initial_pose, dtype=np.float64)
    distance, inside = _distances(surfaces, points, pose[:3, :3], pose[:3, 3], ball_radius_mm)
    distance = np.abs(distance)
    nearest = np.where(inside.any(axis=1), np.argmin(np.where(inside, distance, np.inf), axis=1),
                       np.argmin(distance, axis=1))
    return tuple(surfaces[k].id for k in nearest)


def assigned(features, solution, points, index, ball_radius_mm=0.0):
    """The unlabelled touches' assignment under a solution: each one's ``touch``, ``feature`` and
    ``residual_mm`` (its signed distance from that feature at the solution's pose)."""
    local = (points - solution.translation) @ solution.rotation
    return [{"touch": int(i), "feature": fid,
             "residual_mm": float(features[fid].signed_distance(p[None])[0] - ball_radius_mm)}
            for i, fid, p in zip(index, solution.assignment, local)]


def solve_unlabelled(groups, features, points, index, ball_radius_mm=0.0, sigma_mm=DEFAULT_SIGMA_MM,
                     lever_mm=SENSOR_LEVER_MM, tolerance=None):
    """Every pose that passes under some assignment of the unlabelled ``points`` (n, 3), mm, measurement
    frame, numbered ``index`` (n,), to the surface features, beside the labelled touch ``groups``: a
    :class:`.solve.Solutions`, best first, each solution with its ``assignment`` (a feature id per unlabelled
    touch) and its labelled ``problem``; ``search`` as :func:`.solve.solve` says it (``complete`` only when
    the first search and the labelled one under every assignment are)."""
    points, index = np.asarray(points, dtype=np.float64).reshape(-1, 3), np.asarray(index)
    surfaces = _surfaces(features)
    made = {}

    def problem_of(assignment):
        return assigned_problem(groups, features, points, index, assignment, ball_radius_mm, sigma_mm, lever_mm,
                                tolerance, made)

    # Every surface gives a point touch one row: the test's threshold is the same under every assignment.
    threshold = threshold_mm2(problem_of([surfaces[0].id] * len(points)))
    trees = {}

    def tree_of(assignment):
        if assignment not in trees:
            problem = problem_of(assignment)
            trees[assignment] = problem, Tree(problem, threshold, labels.centroid)
        return trees[assignment]

    labels = Labels(groups, surfaces, points, ball_radius_mm, tolerance, threshold / sigma_mm**2)
    handed, reason, kept = labels.search(threshold, lambda key: tree_of(key)[1])
    out = Solutions()
    out.cells, out.search, out.reason = kept, "incomplete" if reason else "complete", reason
    found = []
    whole = {}
    for key, cells in handed.items():
        if None not in key:
            whole.setdefault(key, []).append(cells)
            continue
        # Some touches' features left open: the leaves of the search under the others', then every assignment
        # of all the touches that the leaves leave.
        tree = tree_of(key)[1]
        leaves, stopped = tree.leaves(cells[0], cells[1], *Tree.turned(cells[2], cells[3], tree.Q), LEAF_FRACTION,
                                      kept)
        if leaves is None:
            out.search, out.reason = "incomplete", out.reason or stopped
            continue
        for assignment, part in labels.resolve(threshold, leaves.v, leaves.w,
                                               *Tree.turned(leaves.ylo, leaves.yhi, tree.Q.T)).items():
            whole.setdefault(assignment, []).append(part)
    regions = {assignment: tree_of(assignment)[1].regions(tuple(np.concatenate(x) for x in zip(*parts)))
               for assignment, parts in whole.items()}
    for assignment, region in regions.items():
        if region.poses or not region.complete:
            found += _solved(tree_of(assignment)[0], assignment, out, region)
    stopped = bool(reason)
    if not found and not stopped:
        # No pose passes under any assignment: the assignments of the least-cost poses, for what the verdict
        # says of them (inconsistent, and which touches fit no feature).
        relaxed = threshold
        for _ in range(RELAX_ROUNDS):
            relaxed *= RELAX
            handed, why, _ = labels.search(relaxed, lambda key: tree_of(key)[1], FALLBACK_ASSIGNMENTS, joint=False)
            stopped = bool(why)
            for key in handed:
                if None not in key:
                    found += _solved(tree_of(key)[0], key, out)
            if found or stopped:
                break
    if not found and stopped:
        # The first search stopped: poses refined from every first-level rotation (the touches' centroid on the
        # surfaces' middle), each touch on its nearest feature.
        R = rotation_from_vector(first_cells()[0])
        boxes = np.array([patch_box(f) for f in surfaces])
        middle = np.mean(np.where(np.isfinite(boxes), boxes, 0.0).mean(axis=1), axis=0)
        for Rk in R:
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = Rk, labels.centroid - Rk @ middle
            for _ in range(LOCAL_ROUNDS):
                assignment = nearest_assignment(features, points, pose, ball_radius_mm)
                solutions = _solved(problem_of(assignment), assignment, out, initial_pose=pose)
                pose = solutions[0].fixture2meas
            found += solutions
    found.sort(key=lambda s: (not (s.passes and s.admissible), s.cost))
    for s in found:
        # One pose under two assignments (a touch where two patches meet) is one pose: the better one is kept.
        if not any(same_pose((s.rotation, s.translation), (k.rotation, k.translation)) for k in out):
            out.append(s)
    if not out:
        raise ValueError("no assignment of the unlabelled touches to the features comes near a pose")
    return told_apart(out, sigma_mm)


def _solved(problem, assignment, out, found=None, initial_pose=None):
    """The solutions under one assignment (:func:`.solve.solve`), each with its assignment and problem; what
    they say of the search is added to ``out``."""
    solutions = solve(problem, initial_pose, found=found)
    if initial_pose is None and not solutions.complete:
        out.search, out.reason = "incomplete", out.reason or solutions.reason
    if solutions.extent_mm is not None:
        out.extent_mm = max(out.extent_mm or 0.0, solutions.extent_mm)
    for s in solutions:
        s.assignment, s.problem = assignment, problem
    return list(solutions)


class Labels:
    """The first branch and bound of the module doc: each touch's candidate features per cell."""

    def __init__(self, groups, surfaces, points, ball_radius_mm, tolerance, q):
        places, touch, feature, offset = [], [], [], []
        count = 0
        for g in groups:
            if g.points is None:
                continue  # a sensor: not searched (:mod:`.search`)
            places.append(g.points)
            touch += range(count, count + g.count)
            feature += [g.feature] * g.count
            offset += list(contact_offset(g))
            count += g.count
        self.labelled = count
        places.append(points)
        for i in range(count, count + len(points)):
            for f in surfaces:
                touch.append(i)
                feature.append(f)
                offset.append(f.core()[3] + ball_radius_mm)
        places = np.concatenate(places)
        self.centroid = places.mean(axis=0)
        self.b = places - self.centroid
        self.rho = np.linalg.norm(self.b, axis=1)
        self.touch, self.feature, self.surfaces = np.array(touch), feature, surfaces
        self.unlabelled = self.touch >= count
        self.count = len(points)  # unlabelled touches
        self.starts = np.flatnonzero(np.r_[True, np.diff(self.touch) != 0])
        cores = [f.core() for f in feature]
        self.core = np.array([c[0] for c in cores])
        self.anchor = np.array([np.asarray(c[1], float) for c in cores])
        self.direction = np.array([np.zeros(3) if c[2] is None else np.asarray(c[2], float) for c in cores])
        self.offset = np.array(offset, float)
        devs = {f.id: 0.0 if tolerance is None else float(deviation_bound(tolerance, f, q)) for f in feature}
        self.dev = np.array([devs[f.id] for f in feature])
        self.box = np.array([patch_box(f) for f in feature])  # (J, 2, 3)
        self.round = self.core != "plane"

    def search(self, threshold, tree_of, best=None, joint=True):
        """The cells handed to the labelled search, by key, as (v, w, ylo, yhi); the reason when the search
        stopped (else ""); the cells kept per level. A key is a feature id per unlabelled touch, or None where
        the touch's feature is left open; ``tree_of(key)`` is its labelled search (:class:`.search.Tree`, at
        this threshold when ``joint``: it then bounds the touches with one candidate together, :meth:`kept`).
        A cell is handed on under every assignment of its candidates when they are at most
        ``MAX_ASSIGNMENTS`` and each fixes a pose; else under the touches with one candidate, when those fix a
        pose alone (the others' features are found on the leaves: :meth:`resolve`); else it is branched or
        split. ``best``: only the keys of this many of the least-bound cells (the fallback's)."""
        v, w, ylo, yhi = first_cells()
        allowed = None
        F = len(self.surfaces)
        done, kept = [], []
        for _ in range(MAX_LEVELS):
            v, w, ylo, yhi, bound, candidate, allowed = self.kept(threshold, v, w, ylo, yhi, allowed,
                                                                   tree_of if joint else None)
            kept.append(len(v))
            choices = self.choices(candidate)
            count = choices.sum(axis=2)
            keys = self.keys(candidate)
            whole = np.prod(count.astype(float), axis=1) <= MAX_ASSIGNMENTS
            rows, inverse = np.unique(candidate[whole][:, self.unlabelled], axis=0, return_inverse=True)
            fixing = np.array([all(tree_of(a).fixes_pose for a in self.assignments(row)) for row in rows], bool)
            whole[whole] = fixing[inverse.ravel()]
            rows, inverse = np.unique(keys, axis=0, return_inverse=True)
            # (Each surface touch gives one row: fewer than six touches fix no pose.)
            alone = np.array([self.labelled + np.sum(row >= 0) >= MIN_JOINT and tree_of(self.key(row)).fixes_pose
                              for row in rows], bool)[inverse.ravel()] & ~whole
            out = whole | alone
            done.append((v[out], w[out], ylo[out], yhi[out], bound[out],
                         np.where(alone[:, None, None], keys[:, :, None] == np.arange(F), choices)[out]
                         .reshape(-1, self.unlabelled.sum()), alone[out]))
            rest = ~out
            v, w, ylo, yhi, allowed, count, choices = (x[rest] for x in (v, w, ylo, yhi, allowed, count, choices))
            if not len(v):
                return self.handed(done, best), "", kept
            # A cell whose turn is small but whose touches' features are still open: branched on the open touch
            # with the fewest candidates, one cell per candidate (the labelled search takes over once the
            # touches with one feature fix a pose); the others split as the labelled search splits.
            branching = (np.sqrt(3.0) * w * self.rho.max() <= LABEL_TURN_MM) & (count.max(axis=1) > 1)
            touch = np.argmin(np.where(count > 1, count, np.iinfo(int).max), axis=1)
            cell, feature = np.nonzero(choices[np.arange(len(v)), touch] & branching[:, None])
            branch = allowed[cell].copy()
            pairs = self.labelled + F * touch[cell][:, None] + np.arange(F)  # the branched touch's pairs
            branch[np.arange(len(cell))[:, None], pairs] = np.arange(F) == feature[:, None]
            plain = ~branching
            turning = np.sqrt(3.0) * w[plain] * self.rho.max() >= np.linalg.norm(0.5 * (yhi - ylo)[plain], axis=1)
            if len(cell) + 8 * turning.sum() + 2 * (~turning).sum() > MAX_CELLS:
                return {}, f"the touches' features were not told within {MAX_CELLS} cells a level", kept
            parts = split(v[plain], w[plain], ylo[plain], yhi[plain], turning, np.ones(3, bool))
            allowed = np.concatenate([branch, np.repeat(allowed[plain][turning], 8, axis=0),
                                      np.repeat(allowed[plain][~turning], 2, axis=0)])
            v, w, ylo, yhi = (np.concatenate([x[cell], p]) for x, p in zip((v, w, ylo, yhi), parts))
        return {}, f"the touches' features were not told after {MAX_LEVELS} levels", kept

    def kept(self, threshold, v, w, ylo, yhi, allowed=None, tree_of=None):
        """The cells whose bound is at most the threshold: (v, w, ylo, yhi, bound, candidate, allowed);
        ``allowed`` (K, J): the pairs a cell's branch leaves (all by default). With ``tree_of`` (a key's
        labelled search, :class:`.search.Tree`), the touches with one candidate are bounded together by its
        zeroth-order bound (their share of the cost), the others each by its own."""
        allowed = np.ones((len(v), len(self.touch)), bool) if allowed is None else allowed
        if not len(v):
            return v, w, ylo, yhi, np.zeros(0), allowed, allowed
        root = float(np.sqrt(threshold))
        grow = patch_growth(root, self.dev, self.offset)
        low, high = self.box[:, 0] - grow[:, None], self.box[:, 1] + grow[:, None]
        parts = [self.bound(v[k:k + CHUNK], w[k:k + CHUNK], ylo[k:k + CHUNK], yhi[k:k + CHUNK], root, low, high,
                            allowed[k:k + CHUNK]) for k in range(0, len(v), CHUNK)]
        shares, candidate, ylo, yhi = (np.concatenate(p) for p in zip(*parts))
        bound = shares.sum(axis=1)
        keep = (bound <= threshold) & ~beyond_pi(v, w) & np.all(ylo <= yhi, axis=1)
        v, w, ylo, yhi, bound, candidate, allowed, shares = (x[keep] for x in (v, w, ylo, yhi, bound, candidate,
                                                                              allowed, shares))
        if tree_of is not None and len(v):
            count = self.choices(candidate).sum(axis=2)
            keys = self.keys(candidate)
            rows, inverse = np.unique(keys, axis=0, return_inverse=True)
            inverse = inverse.ravel()
            for r, row in enumerate(rows):
                if self.labelled + np.sum(row >= 0) < MIN_JOINT:
                    continue
                m = np.flatnonzero(inverse == r)
                tree = tree_of(self.key(row))
                c = tree.zeroth_bound(Cells(v[m], w[m], *Tree.turned(ylo[m], yhi[m], tree.Q)))
                open_share = np.sum(np.where(count[m] != 1, shares[m, self.labelled:], 0.0), axis=1)
                bound[m] = np.maximum(bound[m], c.zeroth + open_share)
                lo, hi = Tree.turned(c.ylo, c.yhi, tree.Q.T)
                ylo[m], yhi[m] = np.maximum(ylo[m], lo), np.minimum(yhi[m], hi)
            keep = (bound <= threshold) & np.all(ylo <= yhi, axis=1)
            v, w, ylo, yhi, bound, candidate, allowed = (x[keep] for x in (v, w, ylo, yhi, bound, candidate, allowed))
        return v, w, ylo, yhi, bound, candidate, allowed

    def choices(self, candidate):
        """Each cell's candidates of each unlabelled touch (K, n_unlabelled, surfaces), from the pairs' (K, J)."""
        return candidate[:, self.unlabelled].reshape(len(candidate), self.count, len(self.surfaces))

    def keys(self, candidate):
        """Each cell's unlabelled touches' one candidate (an index into the surfaces, -1: none or several)."""
        choices = self.choices(candidate)
        return np.where(choices.sum(axis=2) == 1, np.argmax(choices, axis=2), -1)

    def resolve(self, threshold, v, w, ylo, yhi):
        """Leaves of a search under some touches' features (y boxes on the fixture frame's axes), by every
        assignment of all the touches that their candidates leave (:meth:`search`'s keys)."""
        v, w, ylo, yhi, bound, candidate, _ = self.kept(threshold, v, w, ylo, yhi)
        choices = candidate[:, self.unlabelled]
        return self.handed([(v, w, ylo, yhi, bound, choices, np.zeros(len(v), bool))], None)

    def key(self, row):
        """The key of a row of each unlabelled touch's one candidate (an index into the surfaces, -1: none)."""
        return tuple(None if k < 0 else self.surfaces[k].id for k in row)

    def assignments(self, row):
        """Every assignment (tuples of feature ids) a row of candidates (n_unlabelled x surfaces) leaves."""
        row = np.reshape(row, (-1, len(self.surfaces)))
        return list(itertools.product(*[[self.surfaces[k].id for k in np.flatnonzero(r)] for r in row]))

    def handed(self, done, best):
        """The handed cells by key: each cell under every assignment of its candidates, or under the touches
        with one candidate (``alone``)."""
        v, w, ylo, yhi, bound, choices, alone = (np.concatenate(p) for p in zip(*done))
        if best is not None:
            order = np.argsort(bound)[:best]
            v, w, ylo, yhi, choices, alone = v[order], w[order], ylo[order], yhi[order], choices[order], alone[order]
        rows, inverse = np.unique(np.column_stack([choices, alone]), axis=0, return_inverse=True)
        out = {}
        for k, row in enumerate(rows):
            members = np.flatnonzero(inverse.ravel() == k)
            if row[-1]:
                counts = row[:-1].reshape(-1, len(self.surfaces))
                keys = [self.key(np.where(counts.sum(axis=1) == 1, np.argmax(counts, axis=1), -1))]
            else:
                keys = self.assignments(row[:-1])
            for key in keys:
                out.setdefault(key, []).append(members)
        return {key: tuple(x[np.concatenate(m)] for x in (v, w, ylo, yhi)) for key, m in out.items()}

    def bound(self, v, w, ylo, yhi, root, low, high, allowed):
        """Each cell's lower bound of each touch's share of the cost under any assignment its branch
        ``allowed`` (K, J) leaves (K, n), which features are candidates of which touch (K, J), and its y box
        shrunk to the candidates' boxes."""
        turn = (np.sqrt(3.0) * w)[:, None] * self.rho[None]  # (K, n)
        a = turned_points(self.b, rotation_from_vector(v))[:, self.touch]  # (K, J, 3): R0^T b_i
        reach = turn[:, self.touch, None]
        lo = np.maximum(ylo[:, None], low[None] - a - reach)
        hi = np.minimum(yhi[:, None], high[None] - a + reach)
        open_box = np.all(lo <= hi, axis=2)
        finite = np.all(np.isfinite(lo) & np.isfinite(hi), axis=2)
        centre = a + np.where(finite[..., None], 0.5 * (lo + hi), 0.0)
        half = np.where(finite[..., None], 0.5 * (hi - lo), 0.0)
        near = np.where(finite, self.least(centre, half), 0.0) - turn[:, self.touch]
        candidate = open_box & (near <= root + self.dev) & allowed
        share = np.where(candidate, np.maximum(near - self.dev, 0.0) ** 2, np.inf)
        bound = np.minimum.reduceat(share, self.starts, axis=1)  # each touch's least share of the cost
        # y lies in each touch's union of its candidates' boxes: the labelled touches' own, the unlabelled ones'
        # over their F pairs each (the pairs' last n F).
        lo, hi = np.where(candidate[..., None], lo, np.inf), np.where(candidate[..., None], hi, -np.inf)
        n, F = self.count, len(self.surfaces)
        new_lo = across(np.maximum, np.concatenate([lo[:, :self.labelled], across(np.minimum, np.swapaxes(
            lo[:, self.labelled:].reshape(len(v), n, F, 3), 1, 2))], axis=1))
        new_hi = across(np.minimum, np.concatenate([hi[:, :self.labelled], across(np.maximum, np.swapaxes(
            hi[:, self.labelled:].reshape(len(v), n, F, 3), 1, 2))], axis=1))
        return bound, candidate, np.maximum(ylo, new_lo), np.minimum(yhi, new_hi)

    def least(self, centre, half):
        """The least distance (K, J) of each pair's element from the box of places (centre, half-widths)."""
        rel = centre - self.anchor
        d = self.direction
        # A plane: the signed distance's range over the box.
        signed = np.einsum("kji,ji->kj", rel, d) - self.offset
        out = np.maximum(np.abs(signed) - np.einsum("kji,ji->kj", half, np.abs(d)), 0.0)
        r = self.round  # (the planes' is the signed distance's range)
        out[:, r] = least_over_box(rel[:, r], half[:, r], d[r], self.core[r] == "point", np.zeros(r.sum(), bool),
                                   self.offset[r])
        return out
