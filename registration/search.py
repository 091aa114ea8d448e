"""Every pose the touches admit: a branch and bound over rotations.

A pose passes the residual test when its cost (the sum of its squared rows)
is at most ``T = sigma^2 q``, q the test's chi-square quantile. Write the
point and ball touches' fixture-frame positions as ``x_i = R^T (p_i - c) + y``:
``c`` their measured centroid, ``y`` its image in the fixture. Every row of a
point or ball touch is a distance of ``x_i`` from its element, so it moves by
at most ``|x_i - x_i'|`` (1-Lipschitz), and turning ``R`` within a cell of
geodesic radius ``delta`` (rad) about ``R0`` moves ``x_i`` by at most
``delta rho_i``, ``rho_i = |p_i - c|``; all touches together, one turn
``E`` of angle ``theta``, by ``sum |(E - I) b_i|^2 <= theta^2 lambda``,
``lambda`` the largest eigenvalue of the touches' inertia tensor about ``c``
(``sum |b|^2 I - b b^T``). So a pose of the cell that passes
has, at ``R0`` and the same ``y``, a cost of at most
``B = (sqrt(T) + delta sqrt(lambda))^2``: a cell whose least cost over ``y`` at
``R0`` exceeds ``B`` holds no pose that passes and is dropped. So is a cell
where no ``y`` brings every touch within ``sqrt(T)`` plus the admissibility
slack (:mod:`.verdict`) plus ``delta rho_i`` of its patch's box
(:func:`.patches.patch_box`): no pose of it is admissible. The cells left
are split in eight until their radius is ``LEAF_RAD`` (or, past
``MAX_CELLS``, ``COARSEST_LEAF_RAD``), and every leaf left is refined.

The least cost over ``y`` is found by Gauss-Newton from the fixture's centre
and from every candidate centre of a touched sphere: exact (linear least
squares) for touches on planes, lines and points; a local minimum on spheres
and cylinders. docs/registration.md states the guarantee that follows.

Rotation cells are boxes of rotation vectors ``v`` (half-width ``w``): the
geodesic angle between ``exp(v)`` and ``exp(v0)`` is at most ``|v - v0|``
(Hartley and Kahl, 2009), so a box's radius is ``sqrt(3) w``.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .elements import distance_and_outward
from .fits import sphere_centre_candidates
from .mobility import matrix_rank
from .patches import patch_box
from .pose import rotation_from_vector
from .problem import Problem
from .verdict import EXTENT_TOLERANCE_MM, EXTENT_WIDENING_MAX_MM, SAME_POSE_CHI2

FIRST_CELLS = 8  # rotation-vector boxes per axis of [-pi, pi]^3 at the first level
LEAF_RAD = 0.045  # cells are split down to this radius (rad), then refined
TRANSLATION_STEPS = 3  # Gauss-Newton steps for the best translation of a cell
MAX_CELLS = 250000  # cells at one level beyond which they are not split again ...
COARSEST_LEAF_RAD = 0.09  # ... but refined as leaves when this small and no more than MAX_LEAVES; else the
MAX_LEAVES = 50000  # search is not completed
REFINE_STEPS = 8  # batched Gauss-Newton steps from every leaf before the leaves are told apart
REFINED_FACTOR = 4.0  # refined leaves kept: cost within this many times the residual test's threshold ...
UNCONVERGED_KEPT = 4  # ... and this many more, the best
TRANSLATION_GRID = 5  # translation starts per axis of the fixture's box, at one rotation
SAME_LEAF_RAD, SAME_LEAF_MM = 0.01, 0.1  # refined leaves this close are one start


def leaf_starts(problem, threshold):
    """Starting poses [(R, t)] from every leaf cell that may hold a pose passing ``threshold``
    (cost, mm^2), best first; ``[]`` when no pose can pass; None when the search does not apply (point
    and ball touches whose rows cannot fix a pose) or is not completed (more than ``MAX_CELLS`` cells wider
    than ``COARSEST_LEAF_RAD``, or more than ``MAX_LEAVES`` of them: a continuum of poses)."""
    search = RotationSearch(problem, threshold)
    if search.problem.size < 6 or matrix_rank(search.problem.evaluate(np.eye(3), np.zeros(3))[1],
                                              search.problem.scale()) < 6:
        return None  # point and ball touches that cannot fix a pose
    leaves = search.leaves()
    if leaves is None:
        return None
    return search.refined(*leaves) if len(leaves[0]) else []


def translation_starts(problem, rotation, translation, threshold):
    """Translations [t] other than ``translation`` at which the touches may pass at one rotation: Gauss-Newton
    from a grid over the touched features' patch boxes, the distinct ends within ``REFINED_FACTOR`` of
    ``threshold``, one per confidence region. A local search's second look: solutions that share a rotation
    (Example One's two, along its edge)."""
    boxes = [patch_box(g.feature) for g in problem.groups]
    low, high = np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        return []
    axes = [np.linspace(a, b, TRANSLATION_GRID) for a, b in zip(low, high)]
    anchors = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    # A fixture point at ``anchor`` is put where the touches' centres are: t = c - R anchor.
    centre = np.concatenate([g.centre for g in problem.groups]).mean(axis=0)
    ts = np.vstack([translation, centre - anchors @ rotation.T])
    Rs = np.broadcast_to(rotation, (len(ts), 3, 3))
    for _ in range(REFINE_STEPS):
        r, J = problem.evaluate_batch(Rs, ts)
        J = J[:, :, 3:]
        A = J.transpose(0, 2, 1) @ J + 1e-9 * np.eye(3)
        ts = ts - (Rs @ np.linalg.solve(A, J.transpose(0, 2, 1) @ r[..., None]))[..., 0]
    r, J = problem.evaluate_batch(Rs, ts)
    cost = np.sum(r**2, axis=1)
    information = J.transpose(0, 2, 1) @ J / problem.sigma**2
    # One end per confidence region, none in the given pose's own: a weak valley holds many ends.
    chosen = [0]
    for k in _distinct(Rs, ts, cost):
        if k and cost[k] <= REFINED_FACTOR * threshold and all(
                _mahalanobis(rotation, ts[j], information[j], Rs[k:k + 1], ts[k:k + 1])[0] >= SAME_POSE_CHI2
                for j in chosen):
            chosen.append(k)
    return [ts[k] for k in chosen[1:]]


class RotationSearch:
    """The branch and bound of the module doc over one problem's point and ball touches."""

    def __init__(self, problem, threshold):
        groups = [g for g in problem.groups if g.points is not None]
        self.problem = Problem(groups, problem.sigma, problem.lever)
        if not groups:
            return
        self.points = np.concatenate([g.points for g in groups])
        self.centroid = self.points.mean(axis=0)
        b = self.points - self.centroid
        self.rho = np.linalg.norm(b, axis=1)
        # How far one radian of turn moves the touches, all together (the module doc's sqrt(lambda)).
        self.swing_mm = float(np.sqrt(np.linalg.eigvalsh(np.sum(self.rho**2) * np.eye(3) - b.T @ b)[-1]))
        self.root = float(np.sqrt(threshold))
        # Each touch's element: its core, and how far off the core the touch lies at contact (a ball's
        # centre by both radii, as its ``rho``; a point probe by the feature's radius; a ball on a point by
        # its own radius). Its rows' squared length is the squared distance (tests/test_search.py).
        self.elements, first = [], 0
        for g in groups:
            core, anchor, direction, radius = g.feature.core()
            ball = np.ravel(g.sensor.geometry.get("r", 0.0)) if g.ctype.sensor == "S" else 0.0
            offset = np.where(g.rho > 0, g.rho, radius + np.broadcast_to(ball, g.rho.shape))
            self.elements.append((core, anchor, direction, offset, slice(first, first + g.count)))
            first += g.count
        # Each touch's patch box, grown by how far an admissible touch may lie off its patch and its surface.
        reach = EXTENT_TOLERANCE_MM + EXTENT_WIDENING_MAX_MM + self.root
        self.low = np.concatenate([np.tile(patch_box(g.feature)[0], (g.count, 1)) for g in groups]) - reach
        self.high = np.concatenate([np.tile(patch_box(g.feature)[1], (g.count, 1)) for g in groups]) + reach
        # Where the centroid's image starts: the mean of the touched elements' anchors, and what each
        # candidate centre of a touched sphere puts there (it fixes the translation given the rotation).
        self.anchor = np.mean([g.feature.core()[1] for g in groups], axis=0)
        self.spheres = sphere_centre_candidates(groups)
        # On planes, lines and points the distances are linear in y: one step reaches the least cost.
        self.translation_steps = TRANSLATION_STEPS if any(g.feature.core()[3] for g in groups) else 1

    def leaves(self):
        """Rotations (K, 3, 3) and translations (K, 3) of the leaf cells left, or None past ``MAX_CELLS``."""
        w = np.pi / FIRST_CELLS
        axis = -np.pi + w * (2 * np.arange(FIRST_CELLS) + 1)
        v = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
        v = v[np.linalg.norm(v, axis=1) - np.sqrt(3.0) * w <= np.pi]
        corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
        while True:
            delta = np.sqrt(3.0) * w
            Rs = rotation_from_vector(v)
            a = (self.points - self.centroid) @ Rs  # R^T (p_i - c)
            fits = self.fits_patches(a, delta)
            v, Rs, a = v[fits], Rs[fits], a[fits]
            ys, cost = self.best_images(a, Rs)
            keep = cost <= (self.root + delta * self.swing_mm) ** 2
            v, Rs, ys = v[keep], Rs[keep], ys[keep]
            if delta <= LEAF_RAD or not len(v) or (
                    8 * len(v) > MAX_CELLS and delta <= COARSEST_LEAF_RAD and len(v) <= MAX_LEAVES):
                # Too many cells to split again, but small enough to refine: the leaves are these.
                return Rs, self.centroid - (Rs @ ys[..., None])[..., 0]
            if 8 * len(v) > MAX_CELLS:
                return None
            w /= 2.0
            v = (v[:, None] + w * corners[None]).reshape(-1, 3)

    def fits_patches(self, a, delta):
        """Whether some ``y`` puts every touch of a rotation cell near its patch box, (K,) bool: the boxes
        each touch allows for ``y`` must meet."""
        slack = (delta * self.rho)[None, :, None]
        low = np.max(self.low[None] - a - slack, axis=1)
        high = np.min(self.high[None] - a + slack, axis=1)
        return np.all(low <= high, axis=1)

    def distances(self, a, ys):
        """Distances (K, n) of the touches ``a + y`` from their elements, and their outward directions."""
        x = a + ys[:, None]
        d, u = np.empty(x.shape[:2]), np.empty(x.shape)
        for core, anchor, direction, offset, part in self.elements:
            d[:, part], u[:, part] = distance_and_outward(core, anchor, direction, offset, x[:, part])
        return d, u

    def best_images(self, a, Rs):
        """The centroid's images ``y`` (K, 3) of least cost found, and that cost (K,), at rotations (K, 3, 3)."""
        starts = [np.broadcast_to(self.anchor, (len(a), 3))]
        for f, ms in self.spheres:
            # The sphere's centre f at m: R f + t = m, y = R^T (c - t) = f + R^T (c - m).
            starts += [f + (self.centroid - m) @ Rs for m in ms]
        best_y = best_cost = None
        for ys in starts:
            for _ in range(self.translation_steps):
                d, u = self.distances(a, ys)
                A = u.transpose(0, 2, 1) @ u + 1e-9 * np.eye(3)
                ys = ys - np.linalg.solve(A, u.transpose(0, 2, 1) @ d[..., None])[..., 0]
            cost = np.sum(self.distances(a, ys)[0] ** 2, axis=1)
            if best_cost is None:
                best_y, best_cost = ys, cost
            else:
                better = cost < best_cost
                best_y[better], best_cost[better] = ys[better], cost[better]
        return best_y, best_cost

    def steps(self, Rs, ts):
        """Gauss-Newton steps (K, 6) of the fixture-frame twist from the problem's rows, and the cost (K,)."""
        r, J = self.problem.evaluate_batch(Rs, ts)
        A = J.transpose(0, 2, 1) @ J
        A = A + 1e-9 * (np.trace(A, axis1=1, axis2=2)[:, None, None] + 1e-12) * np.eye(6)
        return -np.linalg.solve(A, J.transpose(0, 2, 1) @ r[..., None])[..., 0], np.sum(r**2, axis=1)

    def refined(self, Rs, ts):
        """Leaves refined together by Gauss-Newton, then told apart: [(R, t)] one per distinct start, best
        first. A leaf whose refinement ends far above the threshold is dropped, but for the best few."""
        for _ in range(REFINE_STEPS):
            step, cost = self.steps(Rs, ts)
            # Leaves that have met follow one path from here: the best of each place goes on.
            kept = _distinct(Rs, ts, cost)
            Rs, ts, step = Rs[kept], ts[kept], step[kept]
            # The fixture-frame twist: x -> R (exp(omega) x + v) + t.
            ts = ts + (Rs @ step[:, 3:, None])[..., 0]
            Rs = Rs @ rotation_from_vector(step[:, :3])
        r, J = self.problem.evaluate_batch(Rs, ts)
        cost = np.sum(r**2, axis=1)
        kept = _distinct(Rs, ts, cost)
        near = cost[kept] <= REFINED_FACTOR * self.root**2
        near[:UNCONVERGED_KEPT] = True  # the best few of the rest too: a slow refinement is not dropped
        kept = kept[near]
        # One start per confidence region: a weakly determined pose's valley holds many refined leaves.
        information = J.transpose(0, 2, 1) @ J / self.problem.sigma**2
        chosen, alive = [], np.ones(len(kept), bool)
        for i, k in enumerate(kept):
            if alive[i]:
                chosen.append(k)
                alive[i + 1:] &= _mahalanobis(Rs[k], ts[k], information[k], Rs[kept[i + 1:]], ts[kept[i + 1:]]) \
                    >= SAME_POSE_CHI2
        return [(Rs[k], ts[k]) for k in chosen]


def _distinct(Rs, ts, cost):
    """Indices of the least costly pose in each cell of a grid over (rotation matrix entries, translation),
    cheapest first."""
    order = np.argsort(cost)
    keys = np.column_stack([Rs[order].reshape(-1, 9) / SAME_LEAF_RAD, ts[order] / SAME_LEAF_MM])
    first = np.unique(np.round(keys).astype(np.int64), axis=0, return_index=True)[1]
    return order[np.sort(first)]


def _mahalanobis(R, t, information, Rs, ts):
    """Squared Mahalanobis distances (K,) of poses from (R, t) under its information over the fixture-frame
    twist; poses more than a radian away are infinitely far."""
    E = R.T @ Rs  # R exp(omega) = R_k
    cos = np.clip((np.trace(E, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    vee = np.stack([E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]], axis=1)
    omega = vee * np.where(angle < 1e-9, 0.5, angle / (2.0 * np.sin(np.maximum(angle, 1e-9))))[:, None]
    twist = np.hstack([omega, (ts - t) @ R])  # t_k = t + R v
    d = np.einsum("ki,ij,kj->k", twist, information, twist)
    return np.where(angle < 1.0, d, np.inf)
