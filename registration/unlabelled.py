"""Unlabelled touches: every pose that passes under some assignment of the touches to the features.

A touch without a label is a point (or ball) touch on some surface feature's patch: a plane, a sphere or a
cylinder (the sensing features, or with ``--anywhere`` every face of the part, features.json's ``faces``). The assignments the touches' own shape admits, whatever the pose (:mod:`.assignments`), or where
those are too many the poses admit (:mod:`.face_search`), hold every assignment under which a pose passes (or
one of its orbit under the surfaces' symmetries); the labelled search (:mod:`.search`) finds every pose that
passes under each. So every pose that passes under some assignment is found under that assignment, with the labelled
search's guarantee.

This module imports numpy only and nothing of fixturecad: it is inlined into the generated standalone
``register.py``.
"""

import dataclasses

import numpy as np

from .assignments import admitted
from .defaults import DEFAULT_SIGMA_MM, MAX_COORDINATE_MM, SENSOR_LEVER_MM
from .face_search import face_search
from .patches import patch_box
from .pose import rotation_from_vector
from .problem import Problem
from .search import first_cells, stand_in_tree, threshold_mm2
from .solve import Solutions, solve, told_apart
from .symmetry import core_onto, symmetries
from .touches import point_touches
from .verdict import EXTENT_TOLERANCE_MM, distinct

LOCAL_ROUNDS = 2  # a search that stops: each touch put on its nearest feature this many times from each start
MAX_SEARCHED = 4000  # assignments searched at most, each by the labelled search (3-20 ms): past that it stops


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


def surface_features(features):
    """The features an unlabelled touch may lie on: the planes, spheres and cylinders."""
    surfaces = [f for f in features.values() if f.surface]
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


def nearest_assignment(surfaces, points, initial_pose, ball_radius_mm=0.0):
    """Each touch's feature near a nominal pose (4, 4): the nearest of the ``surfaces`` whose patch it lies on
    (the nearest of all when it lies on none)."""
    pose = np.asarray(initial_pose, dtype=np.float64)
    distance, inside = _distances(surfaces, points, pose[:3, :3], pose[:3, 3], ball_radius_mm)
    distance = np.abs(distance)
    nearest = np.where(inside.any(axis=1), np.argmin(np.where(inside, distance, np.inf), axis=1),
                       np.argmin(distance, axis=1))
    return tuple(surfaces[k].id for k in nearest)


def faces_holding(faces, features):
    """For each face (``--anywhere``) that one or more of the ``features`` lie on (the same surface: their cores
    one, :func:`.symmetry.core_onto`), their ids: a touch put on the face is named by them too."""
    holds = {f.id: [g.id for g in features.values() if g.kind == f.kind and core_onto(g, f)] for f in faces.values()}
    return {fid: ids for fid, ids in holds.items() if ids}


def assigned(features, solution, points, index, ball_radius_mm=0.0, holds=None):
    """The unlabelled touches' assignment under a solution: each one's ``touch``, ``feature``, ``residual_mm``
    (its signed distance from that feature at the solution's pose) and, where the feature is a face that
    features lie on (``holds``, :func:`faces_holding`), ``holds``: their ids."""
    local = (points - solution.translation) @ solution.rotation
    holds = holds or {}
    return [{"touch": int(i), "feature": fid,
             "residual_mm": float(features[fid].signed_distance(p[None])[0] - ball_radius_mm),
             **({"holds": holds[fid]} if fid in holds else {})}
            for i, fid, p in zip(index, solution.assignment, local)]


def solve_unlabelled(groups, features, surfaces, points, index, ball_radius_mm=0.0, sigma_mm=DEFAULT_SIGMA_MM,
                     lever_mm=SENSOR_LEVER_MM, tolerance=None):
    """Every pose that passes under some assignment of the unlabelled ``points`` (n, 3), mm, measurement
    frame, numbered ``index`` (n,), to the ``surfaces`` (features, all of them in ``features`` by id), beside
    the labelled touch ``groups``: a :class:`.solve.Solutions`, best first, each solution with its
    ``assignment`` (a feature id per unlabelled touch) and its labelled ``problem``; ``search`` as
    :func:`.solve.solve` says it (``complete`` only when the assignments were told, no more than
    ``MAX_SEARCHED``, and the labelled search under each is complete); ``cells``: the assignments kept per
    touch, or where the poses told them the cells of poses kept per level."""
    points, index = np.asarray(points, dtype=np.float64).reshape(-1, 3), np.asarray(index)
    made = {}

    def problem_of(assignment):
        return assigned_problem(groups, features, points, index, assignment, ball_radius_mm, sigma_mm, lever_mm,
                                tolerance, made)

    def turned(assignment, regions):
        """The orbit of an assignment A under the symmetries (a group: :func:`.symmetry.symmetries`), A itself
        left out: each S (x -> R x + t) turns A into pi(A), whose touches lie on pi(A) at P S^-1 (x -> R_P R^T
        (x - t) + t_P) as on A at P."""
        out, taken = [], {assignment}
        for R, t, to in group:
            image = tuple(None if f is None else to[f] for f in assignment)
            if image not in taken:
                taken.add(image)
                poses = [(Rp @ R.T, tp - Rp @ R.T @ t) for Rp, tp in regions.poses]
                out.append((image, problem_of(image), dataclasses.replace(regions, poses=poses)))
        return out

    def searched(keep, leaves=None):
        """Each assignment of the touches ``keep`` (a mask; the others left out, None in it) whose search leaves a
        region, with its problem and regions: the ``leaves`` given (assignments of those touches), else every one
        admitted; the reason the assignments were not told (else ""); the assignments kept per touch; at the
        refined pose nearest to passing of any search, each touch's distance (mm) from its feature, and the
        assignment (None where no search refined a pose)."""
        q = threshold / sigma_mm**2
        reason, kept = "", []
        if leaves is None:
            leaves, reason, kept = admitted(groups, surfaces, points[keep], ball_radius_mm, tolerance, q,
                                            float(np.sqrt(threshold)), [to for *_, to in group])
        if reason or len(leaves) > MAX_SEARCHED:
            # Shape alone leaves too many: the poses tell them (one of each orbit, turned below).
            leaves, reason, kept = face_search(surfaces, points[keep], ball_radius_mm, tolerance, q, threshold, group)
        if len(leaves) > MAX_SEARCHED:
            leaves, reason = [], f"the touches fit {len(leaves)} assignments, more than the {MAX_SEARCHED} searched"
        trees = []
        for leaf in leaves:
            assignment = np.full(len(points), None, dtype=object)
            assignment[keep] = leaf
            assignment = tuple(assignment)
            problem = problem_of(assignment)
            trees.append((assignment, problem, *stand_in_tree(problem, threshold)))
        found, loose, nearest = [], False, (np.inf, None)
        # The assignments that fix a pose first: one that does not and leaves a region makes the search incomplete,
        # and the others that do not (a continuum each, slow to search) can then change nothing that is proven.
        for assignment, problem, tree, left in sorted(trees, key=lambda item: not item[2].fixes_pose):
            if loose and not tree.fixes_pose:
                break
            regions = tree.regions(partial=left > 0)
            if regions.nearest is not None:
                r, _ = problem.evaluate(*regions.nearest)
                if r @ r < nearest[0]:
                    off = np.zeros(len(points))
                    off[keep] = np.abs(r[[np.flatnonzero(problem.row_touch == i)[0] for i in index[keep]]])
                    nearest = (r @ r, (off, assignment))
            if not tree.fixes_pose and (regions.poses or not regions.complete):
                regions.complete, loose = False, True
                regions.reason = "the touches fit an assignment of them that does not fix a pose"
            if regions.poses or not regions.complete:
                found.append((assignment, problem, regions))
                found += turned(assignment, regions)
        return found, reason, kept, nearest[1]

    # The surfaces' symmetries turn one assignment's poses into another's: only where nothing else (labelled
    # touches, sensors, a printed part's deviations, each tied to its own feature) tells the surfaces apart.
    group = symmetries(surfaces) if not groups and tolerance is None else []

    # Every surface gives a point touch one row: the test's threshold is the same under every assignment.
    threshold = threshold_mm2(problem_of([surfaces[0].id] * len(points)))
    out = Solutions()
    everyone = np.ones(len(points), bool)
    leaves, reason, out.cells, near = searched(everyone)
    out.search, out.reason = ("incomplete", reason) if reason else ("complete", "")
    found = [s for assignment, problem, regions in leaves for s in _solved(problem, assignment, out, regions)]
    # No pose passes under any assignment: each touch left out in turn (one that fits no feature); the first that
    # leaves a region gives its poses, refined with the touch on its nearest feature there, for what the verdict
    # says of them (inconsistent, and which touches fit no feature). Where a search refined a pose nearest to
    # passing, the touches farthest off their features there first, each under that pose's assignment (the rest
    # keep their features); then, or else, under every assignment the rest admit.
    order = np.argsort(-near[0]) if near is not None else range(len(points))
    tries = [(i, [tuple(np.array(near[1], dtype=object)[np.arange(len(points)) != i])]) for i in order] \
        if near is not None else []
    for i, only in tries + [(i, None) for i in order] if not (found or reason) else ():
        rest = everyone.copy()
        rest[i] = False
        for assignment, problem, regions in searched(rest, only)[0]:
            for R, t in regions.poses:
                pose = np.eye(4)
                pose[:3, :3], pose[:3, 3] = R, t
                full = assignment[:i] + nearest_assignment(surfaces, points[i:i + 1], pose, ball_radius_mm) \
                    + assignment[i + 1:]
                found += _solved(problem_of(full), full, out, initial_pose=pose)
        if found:
            break
    if not found:
        # The assignments were not told, or no touch left out leaves a pose: poses refined from every
        # first-level rotation (the touches' centroid on the surfaces' middle), each touch on its nearest feature.
        R = rotation_from_vector(first_cells()[0])
        boxes = np.array([patch_box(f) for f in surfaces])
        middle = np.mean(np.where(np.isfinite(boxes), boxes, 0.0).mean(axis=1), axis=0)
        centroid = np.concatenate([g.points for g in groups if g.points is not None] + [points]).mean(axis=0)
        for Rk in R:
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = Rk, centroid - Rk @ middle
            for _ in range(LOCAL_ROUNDS):
                assignment = nearest_assignment(surfaces, points, pose, ball_radius_mm)
                solutions = _solved(problem_of(assignment), assignment, out, initial_pose=pose)
                pose = solutions[0].fixture2meas
            found += solutions
    found.sort(key=lambda s: (not (s.passes and s.admissible), s.cost))
    # One pose under two assignments (a touch where two patches meet) is one pose: the better one is kept.
    out.extend(distinct(found))
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
