"""Every pose the touches admit: a branch and bound over rotations and translations.

A pose *passes* when its cost (the sum of its squared rows) is at most
``T = sigma^2 q``, q the residual test's chi-square quantile. Sensor touches
enter as the point touches that stand in for them (:mod:`.stand_ins`), with
``T`` divided by their factor, or with bounds of their own rows
(:mod:`.sensor_bounds`), added to both bounds below. Write each point
or ball touch's place on the fixture as ``x_i = R^T b_i + y``, ``b_i = p_i - c``
(``c`` the touches' measured centroid, ``y`` its image on the fixture). A
touch's rows measure the distance ``d_i(x_i)`` of ``x_i`` from its element (a
plane, line or point core grown by a radius), and that distance is
1-Lipschitz in ``x_i``. A cell is a box of rotation vectors (centre ``v0``,
half-width ``w``) times a box of images ``y``. Every rotation of the cell is
within ``delta = sqrt(3) w`` of ``R0 = exp(v0)`` (Hartley and Kahl, 2009), so
it moves touch ``i`` by at most ``delta rho_i``, ``rho_i = |b_i|``, and all
touches together by at most ``delta sqrt(lambda)`` in the root of the sum of
squares (``lambda`` the largest eigenvalue of their inertia tensor). Two
lower bounds of the cost follow for any pose of the cell, each proven in
docs/registration.md (:meth:`Tree.cells`):

* zeroth order: *flat* touches (on planes, and on lines and points with no
  radius) have rows linear in ``y``, so their cost at ``R0`` is a quadratic
  whose least value over the ``y`` box is bounded below in closed form, less
  ``delta sqrt(lambda)`` in its root; a *round* touch (a sphere, a cylinder,
  a ball on a point or a line) is at least its least distance over the box of
  places the ``y`` box puts it in, less ``delta rho_i``;
* first order (:meth:`Tree.first_order`): with ``R = R0 exp(omega)`` the rows
  are linear in ``(omega, y)`` give or take a proven remainder, ``y`` is
  eliminated exactly, and the least value over ``|omega| <= delta`` is
  bounded by weak duality, less the remainders' length; or, by weak duality
  on the rows' errors too, :func:`dual_bound`.

On a printed part the zeroth order takes each distance less its deviation
bound ``e_i``, and the first order carries the part's deviation modes as
unknowns (:meth:`Tree.modes`). A cell whose bound exceeds ``T`` holds no pose
that passes and is dropped; so is a cell in which no ``y`` keeps every touch
within reach of its patch's box (:func:`.patches.patch_box`) and within the
slabs that each touch's reach puts ``y`` in, and each sensor's rows or given
contact point (:meth:`Tree.contract`; with no point touch, three of the latter
bound ``y`` by themselves). A cell left is
split (its rotation box in eight while a turn moves the touches more than its
``y`` box is wide, or half as wide where round touches are, else its ``y`` box
in two), or its rotation box narrowed to
the model's ellipsoid (:meth:`Tree.narrowed`), until its first-order model is
close (``LEAF_FRACTION``). The leaves, joined where they touch, are
*regions*: every pose that passes lies in one. A region's pose is refined
from its cheapest leaves, and its *extent* (mm, from each leaf's model
ellipsoid) bounds how far any pose of it that passes puts a touch from where
that pose does; a region is split finer until its pose passes and its extent
is small beside its pose's own valley of poses that pass, or is dropped when
its pose fails by more than its extent can make up (:meth:`Tree.regions`). A
search given a ``stop`` ends at the first pose it meets that passes but is too
weakly determined to judge, or at a settled region that passes too wide to
judge: that pose or region alone makes the answer underdetermined.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import functools
import itertools
from dataclasses import dataclass, field

import numpy as np

from .elements import cross, distance_and_outward, dot, perpendicular_basis
from .least_squares import STEP_TOLERANCE, levenberg_marquardt, step_moves
from .mobility import matrix_rank
from .patches import patch_box
from .pose import point_covariances, rotation_from_vector, skew, vector_from_rotation
from .problem import Problem, subset
from .sensor_bounds import Printed, SensorBounds, bounded
from .stand_ins import deviation_bound_mm, largest_move, stand_ins
from .verdict import CHI2_CONFIDENCE, EXTENT_TOLERANCE_MM, EXTENT_WIDENING_MAX_MM, chi_square_quantile

FIRST_CELLS = 8  # rotation-vector boxes per axis of [-pi, pi]^3 at the first level
LEAF_FRACTION = 0.25  # a leaf's first-order model is off by at most this much of sqrt(T) (and the deviations) ...
LEAF_MM = 0.0125  # ... or this (mm), the larger, at first; a region whose pose does not pass is split finer
NEAR_LEAF = 25.0  # a cell whose remainder is within this many times a leaf's is modelled again about its ellipsoid
CLOSER_ROUNDS = 3  # ... at most this many times, while each round leaves at most this share of its remainder:
CLOSER_GAIN = 0.5
MAX_CELLS = 150000  # cells at one level, or leaves in all, beyond which the search stops, not complete
MAX_LEAVES = 60000
CONTINUUM = f"more than {MAX_CELLS} cells at one level or {MAX_LEAVES} leaves: a continuum of poses"
MAX_LEVELS = 60  # splits of a cell before the search stops, not complete
PARTIAL_CELLS = 50000  # cells kept in all before a search that leaves sensors' rows out stops, not complete
REFINE_STEPS = 4  # batched Gauss-Newton steps from each region's cheapest leaves (near its model's least) ...
REGION_STARTS = 4  # ... this many of them
RESOLVE_ROUNDS = 3  # times an unsettled region is split finer before the search stops ...
SETTLED_MM = 0.05  # ... a region being settled when its pose passes and its extent is at most this (mm) beyond
# twice its pose's own valley (:func:`_valley_mm`)
RANK_ROTATIONS = np.array([[0.0, 0.0, 0.0], [0.9, -0.4, 0.3], [-0.5, 1.1, 0.7]])  # rad
NARROW_ANGLE = 4.0  # rad: a cell whose rotation vectors are shorter than this is narrowed to its model's ellipsoid ...
NARROW_GAIN = 0.5  # ... when that at least halves its rotation box
WEAK_TRY_CELLS = 1000  # a level keeping more cells than this (a valley of poses) tries its best pose on ``stop`` ...
WEAK_TRIES = 2  # ... at most this many times a search, as many wide unsettled regions' poses, as many settled
FIRST_TURN_PLANES = 4  # planes' normals a search starts from at most (two signs each: 2^4 choices)
TUBE_BOXES = 512  # rotation boxes about one plane's measured normal a search starts from at most, each sign
ROUND_TURN_SPREAD = 2.0  # where round touches are, a turn is split once it moves them more than half the y box is wide
CONTRACT_ROUNDS = 1  # rounds of interval propagation over the slabs that hold y (:meth:`Tree.contract`)
SLAB_ACROSS = 0.1  # a box axis whose part across a slanted line core is shorter than this gives that core no slab
SLAB_TRIPLES = 8  # sets of three located sensors' slabs whose box bounds y (:func:`slab_triples`), at most ...
SLAB_DETERMINANT = 0.01  # ... each with normals this far from coplanar (the box's widths grow as 1 / |det|; a wide
# box is still a bound, which the sensors' own slabs narrow)
BIG_MM = 1e9  # an unbounded side of a y box, in the propagation's arithmetic
AXES = np.eye(3)  # the y boxes' axes where no line or cylinder is touched: the fixture's own
AXES.flags.writeable = False
SENSOR_ROWS = ("s_value", "s_jw", "s_m", "s_rem", "s_fine", "s_twist", "s_radius")  # :meth:`Tree.sensor_rows`
CORNERS = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
MEMO_KEPT = 4096  # values a memoised function (:func:`by_value`) keeps before it forgets them all


@dataclass
class Regions:
    """What the search found: a refined pose ``(R, t)`` per region, best first, and each region's extent
    (mm); ``complete`` is False, with the ``reason``, when the search stopped before its leaves; ``cells``:
    the cells kept at each level."""

    poses: list = field(default_factory=list)
    extents_mm: list = field(default_factory=list)
    complete: bool = True
    reason: str = ""
    cells: list = field(default_factory=list)
    left: int = 0
    weak: object = None  # what ``stop`` returned where the search stopped (a pose too weak to judge)
    nearest: tuple = None  # the refined pose of least cost, passing or not: where none passes, the nearest to it


class WeakPose(Exception):
    """The search's ``stop`` called a pose too weakly determined to judge, or the region about it too wide
    (``extent_mm``, mm; None: a pose alone): ``found``, what it returned."""

    def __init__(self, found, extent_mm=None):
        super().__init__()
        self.found, self.extent_mm = found, extent_mm


class Tries:
    """A search's ``stop`` (:meth:`Tree.regions`), tried at most ``left`` times: a call raises
    :class:`WeakPose` when it calls the pose weak."""

    def __init__(self, stop, left):
        self.stop, self.left = stop, left if stop is not None else 0

    def __call__(self, R, t, extent_mm=None):
        self.left -= 1
        found = self.stop(R, t, extent_mm)
        if found is not None:
            raise WeakPose(found, extent_mm)


def threshold_mm2(problem):
    """The residual test's largest cost (mm^2) of a pose at which the rows have rank 6."""
    return problem.sigma**2 * chi_square_quantile(CHI2_CONFIDENCE, max(problem.size - 6, 1))


def search(problem, threshold, stop=None):
    """Every region of poses that may pass ``threshold`` (cost, mm^2; on a printed part,
    ``problem.tolerance``, with the part's deviations) on the point and ball touches and the sensors' stand-ins
    (:mod:`.stand_ins`): :class:`Regions`, ``left`` the sensor touches not searched in full. Not complete when those
    rows cannot fix a pose. ``stop(R, t)``: a pose that passes but too weakly determined to judge, refined from
    (R, t), or None (:meth:`Tree.regions`)."""
    tree, left = stand_in_tree(problem, threshold)
    if not tree.fixes_pose:
        return Regions(complete=False, reason="the point and ball touches and the sensors' stand-ins do not fix a pose",
                       left=left)
    found = tree.regions(partial=left > 0, stop=stop)
    found.left = left
    return found


def stand_in_tree(problem, threshold):
    """The :class:`Tree` over the problem's point and ball touches, its sensors' stand-ins, the threshold
    divided by their factor (:mod:`.stand_ins`), and the sensors with no stand-in that it bounds by their own
    rows (:mod:`.sensor_bounds`); and the number of sensor touches not searched in full."""
    groups, kappa2, left, found, without = stand_ins(problem, threshold)
    sensors = [(g, k) for g, k in without if bounded(g)]
    problem = Problem(groups, problem.sigma, problem.lever, problem.tolerance)
    return Tree(problem, threshold / kappa2, found, sensors, 1.0 / kappa2), left - len(sensors)


def first_cells():
    """The first level's cells: rotation boxes over [-pi, pi]^3 (those that hold a rotation vector within pi),
    each with an unbounded y box: (v, w, ylo, yhi)."""
    w = np.pi / FIRST_CELLS
    axis = -np.pi + w * (2 * np.arange(FIRST_CELLS) + 1)
    v = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    v = v[np.linalg.norm(v, axis=1) - np.sqrt(3.0) * w <= np.pi]
    return v, np.full(len(v), w), np.full((len(v), 3), -np.inf), np.full((len(v), 3), np.inf)


def measured_normals(points, reach, mask):
    """Planes' normals in the measurement frame, each from a set of three touches or more (G, n, 3) (``mask``
    (G, n): the set's), each within ``reach`` (G, n) mm of its plane, whatever the pose: ``(n*, phi)`` (G, 3),
    (G,), every unit n with ``|n.(p_i - p_j)| <= r_i + r_j`` for every pair lying within phi of +n* or -n*; phi
    nan where the touches leave it open.

    First :func:`normal_cones`' bound. Tighter, pair by pair: such an n on n*'s side is ``(n* + u) /
    |n* + u|`` with u across n* and ``|n* + u| = 1 / (n.n*) <= 1 / cos(phi)``, so every pair's ``|(n* +
    u).d| <= (r_i + r_j) / cos(phi)``: u lies in a polygon (the pairs' slabs), within its farthest vertex's
    ``|u| = tan`` of n's angle from n*. (All sets at once: numpy's cost is per call on a few touches.)"""
    n, phi = normal_cones(points, reach, mask)
    i, j = pair_indices(points.shape[1])
    both = mask[:, i] & mask[:, j]
    d = np.where(both[..., None], (points[:, j] - points[:, i]) / (reach[:, i] + reach[:, j])[..., None], 0.0)
    # The slabs' edges a.u = b (both sides of each pair's), their corners where two meet, the corners in every slab;
    # a pair not in the set has no edge (a = 0 meets nothing) and holds every u (0 <= 1 / cos(phi)).
    e1, e2 = perpendicular_basis(n)
    along, across = dot(d, n[:, None]), np.stack([dot(d, e1[:, None]), dot(d, e2[:, None])], axis=-1)
    wall = 1.0 / np.cos(np.where(np.isnan(phi), 0.0, phi))
    a = np.concatenate([across, across], axis=1)
    b = np.concatenate([wall[:, None] - along, -wall[:, None] - along], axis=1)
    k, m = pair_indices(a.shape[1])
    det = a[:, k, 0] * a[:, m, 1] - a[:, k, 1] * a[:, m, 0]
    meet = np.abs(det) > 1e-12
    det = np.where(meet, det, 1.0)
    corners = np.stack([b[:, k] * a[:, m, 1] - b[:, m] * a[:, k, 1], a[:, k, 0] * b[:, m] - a[:, m, 0] * b[:, k]],
                       axis=-1) / det[..., None]
    inside = meet & np.all(np.abs(along[:, None] + corners @ across.transpose(0, 2, 1))
                           <= (1.0 + 1e-7) * wall[:, None, None], axis=2)
    farthest = np.where(inside, np.linalg.norm(corners, axis=2), -np.inf).max(axis=1, initial=-np.inf)
    return n, np.where(farthest >= 0.0, np.minimum(phi, np.arctan(np.maximum(farthest, 0.0))), phi)


def _padded(sets):
    """Sets of touches and their reach ((n_g, 3), (n_g,)) as arrays (G, n, 3), (G, n) and their mask (G, n)."""
    widest = max(len(points) for points, _ in sets)
    mask = np.array([np.arange(widest) < len(points) for points, _ in sets])
    points, reach = np.zeros(mask.shape + (3,)), np.ones(mask.shape)
    for g, (p, r) in enumerate(sets):
        points[g, :len(p)], reach[g, :len(p)] = p, r
    return points, reach, mask


def normal_cones(points, reach, mask):
    """For each set of touches (G, n, 3) (``mask`` (G, n): the set's), each within ``reach`` (G, n) mm of a
    plane, whatever the pose: n* (G, 3) and phi (G,), rad, every unit n with ``|n.(p_i - p_j)| <= r_i + r_j``
    for every pair lying within phi of +n* or -n* (nan where the touches leave it open).

    Summed over the k pairs, ``n^T P n <= k`` with ``P = sum d d^T / (r_i + r_j)^2`` (d = p_j - p_i); with n* the
    eigenvector of P's least eigenvalue, ``n = cos(phi) n* + sin(phi) m`` has ``n^T P n >= sin^2(phi)
    lambda_2``, so ``sin^2(phi) <= k / lambda_2``."""
    i, j = pair_indices(points.shape[1])
    both = mask[:, i] & mask[:, j]
    d = np.where(both[..., None], (points[:, j] - points[:, i]) / (reach[:, i] + reach[:, j])[..., None], 0.0)
    lam, vec = np.linalg.eigh(np.einsum("gki,gkj->gij", d, d))
    k = both.sum(axis=1)
    closed = lam[:, 1] > k
    return vec[:, :, 0], np.where(closed, np.arcsin(np.sqrt(k / np.where(closed, lam[:, 1], np.inf))), np.nan)


def turn_bound(fixed, measured, reach, sets):
    """The turn R* (Wahba's, weighted) and theta such that every turn R with ``|R f_k - g_k| <= e_k`` for all k
    (fixed (k, 3), measured (k, 3), reach e (k,)) lies within theta of R* (inf where they leave it open).

    ``D = R R*^T`` moves ``w_k = R* f_k`` by at most ``eps_k = e_k + |R* f_k - g_k|``; a turn by theta about n
    moves w by exactly ``2 sin(theta/2) |n x w|``, so ``4 sin^2(theta/2) |n x w_k|^2 / eps_k^2 <= 1`` each, and
    summed over a set of k of them ``4 sin^2(theta/2) n^T M n <= k``, ``M = sum (|w|^2 I - w w^T) / eps^2``:
    ``sin(theta/2) <= sqrt(k / (4 lambda_min(M)))``, the least over the ``sets`` (lists of indices)."""
    U, _, Vt = np.linalg.svd(np.einsum("k,ki,kj->ij", 1.0 / reach**2, measured, fixed))
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    w = fixed @ R.T
    eps = reach + np.linalg.norm(w - measured, axis=1)
    sine = np.inf
    for chosen in sets:
        ws, es = w[chosen], eps[chosen]
        M = np.einsum("p,pij->ij", 1.0 / es**2, np.sum(ws**2, axis=1)[:, None, None] * np.eye(3)
                      - np.einsum("pi,pj->pij", ws, ws))
        least = np.linalg.eigvalsh(M)[0]
        if least > 0.0:
            sine = min(sine, np.sqrt(len(chosen) / (4.0 * least)))
    return R, 2.0 * np.arcsin(sine) if sine < 1.0 else np.inf


def rotation_boxes(R, theta):
    """Rotation boxes (v (k, 3), half-widths (k,)) holding a rotation vector of every turn within theta (rad) of
    R (3, 3) or of each of R (m, 3, 3): R's vector v* within ``(g/2)/sin(g/2) theta``, ``g = |v*| + theta``
    (:meth:`Tree.narrowed`), measured along a path from R whose vector may leave the ball of radius pi; where the
    box reaches past pi, a second box (next to the first) about v*'s other side ``v* - 2 pi v*/|v*|`` holds the
    other side ``p - 2 pi p/|p|`` of such a vector p, within ``w + 2 pi |p/|p| - v*/|v*||``, and ``|p/|p| -
    v*/|v*|| <= 2 w / |v*|``; and within ``sqrt(3) max(1, 2 pi / m - 1) w``, m = ``|v*| - sqrt(3) w`` the
    shortest vector of the box, where that is tighter: the map's Jacobian ``(1 - 2 pi/|p|) I + 2 pi p p^T /
    |p|^3`` has singular values 1 and ``|1 - 2 pi/|p||``, and a matrix's row sums are at most sqrt(3) times
    its largest singular value."""
    v = vector_from_rotation(R).reshape(-1, 3)
    theta = np.broadcast_to(np.asarray(theta, float), len(v))
    length = np.linalg.norm(v, axis=1)
    g = length + theta
    with np.errstate(invalid="ignore", divide="ignore"):  # (a turn by 0 has no second box)
        w = np.where(g > 0.0, theta * (g / 2.0) / np.sin(g / 2.0), theta)
        least = length - np.sqrt(3.0) * w
        stretch = np.where(least > 0.0, np.sqrt(3.0) * np.maximum(1.0, 2.0 * np.pi / least - 1.0), np.inf)
        both = (np.stack([v, v - 2.0 * np.pi * v / length[:, None]], axis=1),
                np.stack([w, w * np.minimum(1.0 + 4.0 * np.pi / length, stretch)], axis=1))
    far = np.linalg.norm(np.abs(v) + w[:, None], axis=1) >= np.pi
    taken = np.column_stack([np.ones(len(v), bool), far])
    return both[0][taken], both[1][taken]


def normal_signs(normal, plane, level, others, heights):
    """The signs s for which a turn can take a plane's fixture normal f to within phi of ``s n*`` (``normal``: (f,
    n*, phi), :func:`measured_normals`) with the plane's touches ``plane`` (n, 3) and every other touch ``others``
    (m, 3) where they may lie: ``level`` (lo, hi), mm, holds ``f.x`` of the plane's touches' centroid in the
    fixture frame, and ``heights`` (m, 2) that of each other touch (its grown patch box's range along f). A turn
    R puts the other touch at ``x = R^T (p - t)``, whose height ``f.x = (R f).(p - c) + f.x_c`` (c the centroid),
    and R f lies within ``2 sin(phi/2)`` of s n*: a sign is kept where every touch's ``s n*.(p - c) + level +- 2
    sin(phi/2) |p - c|`` meets its heights."""
    _, n, phi = normal
    d = others - plane.mean(axis=0)
    along, chord = d @ n, 2.0 * np.sin(phi / 2.0) * np.linalg.norm(d, axis=1)
    return tuple(s for s in (1.0, -1.0) if np.all((s * along + level[1] + chord >= heights[:, 0]) &
                                                  (s * along + level[0] - chord <= heights[:, 1])))


def tube_turns(normal, pairs, most=TUBE_BOXES):
    """Rotation boxes (v (k, 3), half-widths (k,), rad) that hold a rotation vector of every turn that moves a
    plane's fixture normal f to within phi of its measured normal n* with one of its signs (``normal``: (f, n*,
    phi, signs), :func:`measured_normals`, :func:`normal_signs`) and keeps each pair of touches as its element
    keeps them (``pairs``, :func:`tube_pairs`: a fixture direction f_b (m, 3), the touches' difference d (m, 3),
    and bounds on ``|(R f_b).d|`` (m,), mm: at most ``upper`` for two touches on a plane, f_b its normal; at
    least ``lower`` for two on a line or cylinder, f_b its axis).

    For each sign s, write g = s n* and R0 a turn taking f to g. A turn R with ``angle(R f, g) <= phi``
    is ``T^-1 Rot(g, alpha) R0`` with T the least turn taking R f to g: R lies within phi of the circle
    ``Rot(g, alpha) R0``, and within ``phi + Delta`` of its point alpha_k when ``|alpha - alpha_k| <=
    Delta``. ``(R f_b).d`` lies within ``2 sin(phi/2) |d|`` (the chord T moves d by) of ``h(alpha) = (Rot(g,
    alpha) R0 f_b).d = C + A cos(alpha) + B sin(alpha)``, and ``|h'| <= M = hypot(A, B)``: an interval of alpha
    of half-width Delta is dropped where ``|h(alpha_k)| - M Delta`` exceeds a pair's upper bound, or ``|h(alpha_k)|
    + M Delta`` falls short of its lower bound, by more than that chord. The kept intervals are halved while they
    are wider than phi and their number stays within ``most``; each gives :func:`rotation_boxes` of its turn and
    ``phi + Delta``."""
    f, n, phi, signs = normal
    f_b, d, upper, lower = (np.asarray(a, float).reshape(-1, k) for a, k in zip(pairs, (3, 3, 1, 1)))
    chord = 2.0 * np.sin(phi / 2.0) * np.linalg.norm(d, axis=1)
    upper, lower = upper[:, 0] + chord, lower[:, 0] - chord
    rotations, widths = [], []
    for g in (s * n for s in signs):
        R0 = np.column_stack([*perpendicular_basis(g), g]) @ np.column_stack([*perpendicular_basis(f), f]).T
        b = f_b @ R0.T
        along = b @ g
        C, A, B = along * (d @ g), np.sum(d * (b - along[:, None] * g), axis=1), np.sum(d * cross(g, b), axis=1)
        M = np.hypot(A, B)
        # |h| lies in [|C| - M, |C| + M]: a pair within its bounds there drops no interval.
        cuts = (np.abs(C) + M > upper) | (np.abs(C) - M < lower)
        C, A, B, M, high, low = C[cuts], A[cuts], B[cuts], M[cuts], upper[cuts], lower[cuts]
        half = np.pi / FIRST_CELLS
        alpha = -np.pi + half * (2 * np.arange(FIRST_CELLS) + 1)
        while True:
            h = np.abs(C + np.cos(alpha)[:, None] * A + np.sin(alpha)[:, None] * B)
            alpha = alpha[np.all((h - M * half <= high) & (h + M * half >= low), axis=1)]
            if not (half > phi and 0 < 2 * len(alpha) <= most):
                break
            alpha, half = np.concatenate([alpha - half / 2.0, alpha + half / 2.0]), half / 2.0
        rotations.append(rotation_from_vector(alpha[:, None] * g) @ R0)
        widths.append(np.full(len(alpha), half + phi))
    return rotation_boxes(np.concatenate(rotations).reshape(-1, 3, 3), np.concatenate(widths))


def tube_pairs(planes, lines):
    """Every pair of touches on one plane and on one line or cylinder, as :func:`tube_turns` takes them, from each
    plane's (fixture normal, touches (n, 3), reach (n,) mm) and each line's (fixture axis, touches (n, 3), how far
    each may lie from the axis (n,) mm): on a plane ``|(R f).d| <= r_i + r_j`` (each touch within its reach of
    it); on a line ``|(R a).d| >= |d| cos(c)``, c its pair's cone (:func:`pair_cones`, span ``s_i + s_j``)."""
    pairs = []
    for f, points, reach, *_ in planes:
        i, j = pair_indices(len(points))
        pairs += [(f, dk, span, 0.0) for dk, span in zip(points[j] - points[i], reach[i] + reach[j])]
    for a, points, across_mm in lines:
        i, j = pair_indices(len(points))
        d = points[j] - points[i]
        cone, _ = pair_cones(d, across_mm[i] + across_mm[j])
        pairs += [(a, dk, np.inf, least) for dk, least in zip(d, np.linalg.norm(d, axis=1) * np.cos(cone))]
    return tuple(zip(*pairs)) if pairs else ((), (), (), ())


def pair_cones(d, span):
    """Each pair's cone about the axis of a line both touches lie within ``span`` of together (mm, the sum of
    their distances from it), from their difference d (..., 3): d's part across the axis is at most span, so the
    axis lies within ``arcsin(span / |d|)`` of d's line (rad; pi/2 where they lie no farther apart than span, or d
    is 0); and that line's unit vector (0 for d 0)."""
    length = np.linalg.norm(d, axis=-1)
    some = np.where(length > 0.0, length, 1.0)
    return np.where(length > 0.0, np.arcsin(np.clip(span / some, 0.0, 1.0)), np.pi / 2.0), d / some[..., None]


def first_turns(centres, normals, pairs=((), (), (), ()), most=FIRST_TURN_PLANES):
    """Rotation boxes (v (k, 3), half-widths (k,), rad) that hold a rotation vector of every turn that passes, as
    touched spheres' centres and planes' normals fix it whatever the pose, or None where they leave it open wider
    than a first-level cell.

    ``centres``: :class:`Tree`'s (fixture centre, box middle off the centroid, half-widths): a turn that puts
    each centre in its box moves each difference of two centres ``u`` to within ``|h_i + h_j|`` of its boxes'
    middles' difference. ``normals``: (fixture normal, measured normal n*, phi, signs) (:func:`measured_normals`,
    :func:`normal_signs`): the turn moves the fixture normal to within ``2 sin(phi/2)`` of s n*, s one of its
    signs; each choice of signs gives its own turns, and a choice is dropped where no turn can make it: two
    normals' angle is kept by a turn (within ``phi_k + phi_l``), and three normals' triple product (within the
    sum of their chords). The bound (:func:`turn_bound`) over every difference and normal, the centres'
    differences alone (every pair, each base's), and the normals alone; the boxes (:func:`rotation_boxes`) of
    every choice that a turn can make.
    Where that bound is open, the boxes about the tightest normal that ``pairs`` (:func:`tube_pairs`) leave
    (:func:`tube_turns`), unless that normal's own phi is as wide as a first-level cell."""
    normals = sorted(normals, key=lambda n: n[2])[:most]
    joined = list(itertools.combinations(range(len(centres)), 2))
    fixed = [centres[j][0] - centres[i][0] for i, j in joined] + [f for f, *_ in normals]
    reach = [np.linalg.norm(centres[i][2] + centres[j][2]) for i, j in joined] + \
        [2.0 * np.sin(phi / 2.0) for _, _, phi, _ in normals]
    if not fixed:
        return None
    fixed, reach = np.array(fixed, float).reshape(-1, 3), np.array(reach, float)
    planes = np.arange(len(joined), len(fixed))
    sets = [np.arange(len(fixed)), planes, np.arange(len(joined))] + [
        [k for k, (i, j) in enumerate(joined) if base in (i, j)] for base in range(len(centres))]
    sets = [chosen for chosen in sets if len(chosen) >= 2]
    f, e = fixed[planes], reach[planes]
    differences = np.array([centres[j][1] - centres[i][1] for i, j in joined], float).reshape(-1, 3)
    boxes = []
    for signs in itertools.product(*[signs for *_, signs in normals]):
        g = np.array([s * n for s, (_, n, _, _) in zip(signs, normals)], float).reshape(-1, 3)
        angle_kept = all(abs(np.arccos(np.clip(f[k] @ f[m], -1, 1)) - np.arccos(np.clip(g[k] @ g[m], -1, 1)))
                         <= normals[k][2] + normals[m][2] for k, m in itertools.combinations(range(len(f)), 2))
        triple_kept = all(abs(np.linalg.det(f[list(c)]) - np.linalg.det(g[list(c)])) <= e[list(c)].sum()
                          for c in itertools.combinations(range(len(f)), 3))
        if not (angle_kept and triple_kept):
            continue  # no turn makes these signs
        R, theta = turn_bound(fixed, np.concatenate([differences, g]), reach, sets)
        if not theta < np.pi / FIRST_CELLS:
            return tube_turns(normals[0], pairs) if normals and normals[0][2] < np.pi / FIRST_CELLS else None
        boxes.append(rotation_boxes(R, theta))
    if not boxes:
        return None
    return np.concatenate([v for v, _ in boxes]), np.concatenate([w for _, w in boxes])


def beyond_pi(v, w):
    """Whether each rotation box lies wholly beyond pi, where every rotation has a rotation vector: it holds
    none that needs looking at."""
    return np.linalg.norm(np.maximum(np.abs(v) - w[:, None], 0.0), axis=1) > np.pi


class Tree:
    """The branch and bound of the module doc over one problem's point and ball touches (y the image of
    their centroid, or where there is none of the bounded sensors' placement centres); the last groups, one
    touch each, may be sensors' stand-ins (:class:`.stand_ins.StandIn`). ``sensors``: (group, k) of sensor
    touches bounded by their own rows (:mod:`.sensor_bounds`), their bound times ``weight``."""

    def __init__(self, problem, threshold, stand_ins=(), sensors=(), weight=1.0):
        self.problem = problem.point_touches()
        groups = self.problem.groups
        # Every row the search bounds, sensors' included: what fixes the pose, and what regions' poses are refined on.
        singles = [subset(g, np.array([k])) for g, k in sensors]
        self.full = Problem(groups + singles, problem.sigma, problem.lever) if singles else self.problem
        self.sensors = None
        # The test, deviations and all, with the bounded sensors unless their cost is weighed apart; with stand-ins
        # off their sensors' features on a printed part only what must pass is known of it (their features have
        # no modes of their own).
        self.sensors_apart = bool(sensors) and weight != 1.0
        printed_stand_ins = problem.tolerance is not None and not all(one.own for one in stand_ins)
        self.judge = None if printed_stand_ins else self.full if problem.tolerance is None and not self.sensors_apart \
            else Problem(groups + ([] if self.sensors_apart else singles), problem.sigma, problem.lever, problem.tolerance)
        self.root = float(np.sqrt(threshold))
        if not groups and not sensors:
            return
        # y is the image of the touches' centroid (of the sensors' placement centres where no point is touched).
        self.points = np.concatenate([g.points for g in groups]) if groups else np.zeros((0, 3))
        self.centroid = (self.points if groups else np.array([g.centre[k] for g, k in sensors])).mean(axis=0)
        b = self.points - self.centroid
        self.rho = np.linalg.norm(b, axis=1)
        self.modes(groups, problem.tolerance, threshold / problem.sigma**2, stand_ins, [g for g, _ in sensors])
        if sensors:
            self.sensors = SensorBounds(sensors, problem.lever, self.centroid, weight, self.printed,
                                        EXTENT_TOLERANCE_MM + EXTENT_WIDENING_MAX_MM)
        # The points a region's extent follows: the touches, and where bounded sensors are placed.
        self.markers = self.points if self.sensors is None else np.vstack([self.points, self.sensors.markers])
        self.marker_rho = np.linalg.norm(self.markers - self.centroid, axis=1)
        # Each touch's element: its core, anchor, direction and how far off the core the touch lies at contact
        # (a ball's centre by both radii, its ``rho``; a point probe by the feature's radius).
        core, anchor, direction, offset, boxes = [], [], [], [], []
        for g in groups:
            c, a, d, _ = g.feature.core()
            core += [c] * g.count
            anchor += [np.asarray(a, float)] * g.count
            direction += [np.zeros(3) if d is None else np.asarray(d, float)] * g.count
            offset += list(contact_offset(g))
            boxes += [patch_box(g.feature)] * g.count
        self.core = np.array(core, dtype=str)
        self.anchor, self.direction = np.array(anchor).reshape(-1, 3), np.array(direction).reshape(-1, 3)
        self.offset = np.array(offset, float)
        self.flat = (self.core == "plane") | (self.offset == 0.0)
        self.round = ~self.flat
        # Each touch's patch box, grown by how far a touch that passes may lie off its patch: the patch's
        # tolerance and widening, its distance off the surface, a ball's radius.
        self.patch_low = np.array([box[0] for box in boxes]).reshape(-1, 3)
        self.patch_high = np.array([box[1] for box in boxes]).reshape(-1, 3)
        grow = patch_growth(self.root, self.dev, self.offset)
        self.low, self.high = self.patch_low - grow[:, None], self.patch_high + grow[:, None]
        self.mode_moves(threshold / problem.sigma**2)
        # Flat touches' rows one by one: unit vectors m_j spanning each touch's row space (a plane's normal,
        # the two directions across a line, three across a point), and the anchor moved out by a ball's radius.
        self.flat_anchor = self.anchor + np.where(self.core == "plane", self.offset, 0.0)[:, None] * self.direction
        self.owner = owner = np.repeat(np.arange(len(groups)), [g.count for g in groups]).astype(int)  # touch's group
        flat = np.flatnonzero(self.flat)
        spans = [row_span(self.core[i] == "plane", self.direction[i]) for i in flat]
        self.row_touch = np.repeat(flat, [len(m) for m in spans]).astype(int)
        self.row_first = np.cumsum([0] + [len(m) for m in spans[:-1]]).astype(int)  # each flat touch's first row
        self.row_unit = np.concatenate(spans) if spans else np.zeros((0, 3))
        self.H_flat_least, self.H_flat_pinv = least_and_pinv(self.row_unit.T @ self.row_unit)
        self.flat_swing = largest_swing(b[self.flat])
        self.flat_dev = float(np.linalg.norm(self.dev[self.flat]))
        # Flat touches on one feature, two or more: their rows' least over y is the same wherever y is, so its
        # swing is their own turn about their own centroid, not the touches' centroid (:meth:`zeroth_bound`).
        owner_row = owner[self.row_touch]
        self.flat_groups = []
        for k in np.unique(owner_row):
            rows = np.flatnonzero(owner_row == k)
            touches = np.unique(self.row_touch[rows])
            if len(touches) < 2:
                continue
            self.flat_groups.append((rows, across_rows(self.row_unit[rows]),
                                     largest_swing(b[touches] - b[touches].mean(axis=0)),
                                     float(np.linalg.norm(self.dev[touches]))))
        # Round touches on one core in pairs: the difference of their squared distances from it is linear in y
        # (the circles' radical axis), a slab for y however far the box is from the core (:meth:`contract`).
        # Each touch is paired with the one farthest from it across the core (the narrowest slab), at most n pairs.
        projector = np.eye(3) - np.where((self.core == "line")[:, None, None],
                                         np.einsum("ni,nj->nij", self.direction, self.direction), 0.0)
        self.pairs = np.zeros((0, 2), int)
        rounds = np.flatnonzero(self.round)
        if len(rounds):
            across_core = np.linalg.norm(np.einsum("mij,mnj->mni", projector[rounds],
                                                   b[None, rounds] - b[rounds, None]), axis=2)
            mates = (owner[rounds, None] == owner[None, rounds]) & ~np.eye(len(rounds), dtype=bool)
            paired = mates.any(axis=1)
            i, j = rounds[paired], rounds[np.argmax(np.where(mates, across_core, -1.0), axis=1)[paired]]
            n = len(b)
            code = np.unique(np.minimum(i, j) * n + np.maximum(i, j))  # (numpy's unique of rows is slow)
            self.pairs = np.column_stack([code // n, code % n])
        # Each paired touch's projector across its core, once a touch however many pairs it is in.
        self.paired, pair_index = np.unique(self.pairs, return_inverse=True) if len(self.pairs) else (np.zeros(0, int),) * 2
        self.pair_index = pair_index.reshape(-1, 2)
        self.paired_projector = projector[self.paired]
        self.paired_across = bool(np.any(self.core[self.paired] == "line"))
        # A sphere's centre touched four times or more lies where its touches put it in the measurement frame,
        # whatever the pose: each touch within its contact offset, give or take sqrt(T) and its deviation bound
        # (no turn), of it; on a printed sphere, the printed centre within sqrt(T) of a common radius
        # (:meth:`printed_centre`). That box bounds y with one turn, the centre's (:meth:`zeroth_bound`).
        self.centres = []
        for k in range(len(groups)):
            idx = np.flatnonzero((owner == k) & self.round & (self.core == "point"))
            if len(idx) >= 4 and np.all(self.anchor[idx] == self.anchor[idx[0]]):
                shells = self.printed_centre(idx) if self.L is not None and self.radius_own[idx].all() else None
                if shells is None:
                    lo, hi = shell_box(self.points[idx], self.offset[idx], self.root + self.dev[idx])
                else:
                    radius, width, move = shells
                    lo, hi = shell_box(self.points[idx], np.stack([self.offset[idx], radius]),
                                       np.stack([self.root + self.dev[idx], width]))
                    lo, hi = np.maximum(lo[0], lo[1] - move), np.minimum(hi[0], hi[1] + move)
                rel, half = 0.5 * (lo + hi) - self.centroid, 0.5 * (hi - lo)
                # (the box's middle off the centroid, its half-widths, and how far a unit turn moves its points)
                self.centres.append((self.anchor[idx[0]], rel, half, np.linalg.norm(rel) + np.linalg.norm(half)))
        # The y boxes' axes: the first touched cylinder's (or line's) axis last, so that the box's first two
        # axes hold its touches' distances exactly and its last needs no split for them.
        lines = np.flatnonzero(self.round & (self.core == "line"))
        self.Q = AXES
        if len(lines):
            e1, e2 = perpendicular_basis(self.direction[lines[0]])
            self.Q = np.column_stack([e1, e2, self.direction[lines[0]]])
        self.aligned = self.round & (self.core == "line")
        if len(lines):
            self.aligned &= np.all(np.isclose(self.direction, self.Q[:, 2]) | np.isclose(self.direction, -self.Q[:, 2]),
                                   axis=1)
        # The round touches whose distance holds some of the box's axes (every axis for a point core, the first two
        # for a line core along the last; none for a line core across them), and those axes.
        self.fixing = np.flatnonzero(self.round & ((self.core == "point") | self.aligned))
        self.fixing_axes = np.where((self.core[self.fixing] == "point")[:, None], True, [True, True, False])
        # A round touch on a line core across the box's axes lies within its reach of a cylinder about the core, and so
        # between two planes along the core across each of the box's axes (:meth:`contract`): each such plane's unit
        # normal, the box's axis with its part along the core taken out.
        slanted = np.flatnonzero(self.round & (self.core == "line") & ~self.aligned)
        across_axes = self.Q[None] - np.einsum("ni,nj,jk->nik", self.direction[slanted], self.direction[slanted], self.Q)
        length = np.linalg.norm(across_axes, axis=1)  # (n, 3): each axis' part across the core
        touch, axis = np.nonzero(length > SLAB_ACROSS)
        self.slab_touch = slanted[touch]
        self.slab_normal = (across_axes[touch, :, axis] / length[touch, axis][:, None]).reshape(-1, 3)
        # The y box's axes a round touch's distance depends on: all three, or across an aligned axis; a bounded
        # sensor's bound depends on all three (it holds the box's half-diagonal), and on them even beside flat
        # touches only, whose bound takes the least over the box itself.
        self.relevant = np.ones(3, bool)
        if self.round.any() and self.aligned[self.round].all() and self.sensors is None:
            self.relevant[2] = False
        # Each touch's patch box, its middle, widths and half-widths on the box's axes (an unbounded patch's box has
        # no middle: 0 there, widths 0 and infinite half-widths).
        self.bounded = bounded = np.all(np.isfinite(self.low) & np.isfinite(self.high), axis=1)
        low, high = np.where(bounded[:, None], self.low, 0.0), np.where(bounded[:, None], self.high, 0.0)
        self.patch_middle, self.patch_width = 0.5 * (low + high), high - low
        self.patch_half = np.where(bounded[:, None], 0.5 * self.patch_width @ np.abs(self.Q), np.inf)
        # The located sensors' slabs across their axes (:meth:`.sensor_bounds.SensorBounds.located`), on the box's
        # axes, and three of them at a time that bound y on their own (:func:`slab_triples`).
        self.axial_normals = np.array([d for _, _, d, *_ in self.sensors.axial]).reshape(-1, 3) @ self.Q \
            if self.sensors is not None else np.zeros((0, 3))
        self.triples = slab_triples(self.axial_normals)
        # The turn's weight against the y box in the split rule (:meth:`leaves`): ROUND_TURN_SPREAD where round
        # touches are; where no point is touched, how much farther than their slabs a turn moves the box they bound
        # (their box's half-diagonal over its slabs' half-width, the least over the triples); else 1.
        self.turn_spread = ROUND_TURN_SPREAD if self.round.any() else 1.0 if len(self.points) or not self.triples else \
            min(np.linalg.norm(np.abs(inverse) @ np.ones(3)) for _, inverse in self.triples)

    @functools.cached_property
    def planes(self):
        """Each plane touched twice or more: (fixture normal, its touches in the measurement frame, their reach
        in mm, their indices)."""
        return [(self.direction[idx[0]], self.points[idx], self.root + self.dev[idx], idx)
                for idx in self._touched("plane") if np.allclose(self.offset[idx], self.offset[idx[0]])]

    @functools.cached_property
    def lines(self):
        """Each line or cylinder touched twice or more: (fixture axis, its touches in the measurement frame, how
        far each may lie from the axis in mm: its contact offset and reach)."""
        return [(self.direction[idx[0]], self.points[idx], self.offset[idx] + self.root + self.dev[idx])
                for idx in self._touched("line")]

    def _touched(self, core):
        """The touches' indices of each group touched twice or more on an element with this core."""
        for k in range(len(self.problem.groups)):
            idx = np.flatnonzero(self.owner == k)
            if len(idx) >= 2 and np.all(self.core[idx] == core):
                yield idx

    @functools.cached_property
    def normals(self):
        """Each plane touched three times or more, its normal in the measurement frame where its touches put it,
        whatever the pose, up to its sign, and the signs the other touches leave: (fixture normal, measured
        normal, phi, signs) (:func:`measured_normals`, :func:`normal_signs`); and each plane sensor lying on a
        plane, the sensor's normal, either sign."""
        out = []
        planes = [plane for plane in self.planes if len(plane[3]) >= 3]
        # A printed plane's modes move it as a whole: its touches lie within sqrt(T) of a plane whose normal is
        # within its largest turn of the drawn one's (:meth:`modes`); both bounds for all planes in one call.
        tight = [self.L is not None and self.radius_own[idx].all() for *_, idx in planes]
        sets = [(points, reach) for _, points, reach, _ in planes]
        sets += [(points, np.full(len(idx), self.root)) for (_, points, _, idx), t in zip(planes, tight) if t]
        measured, phis = measured_normals(*_padded(sets)) if sets else (None, None)
        shifted = iter(range(len(planes), len(sets)))
        for g, ((f, points, reach, idx), t) in enumerate(zip(planes, tight)):
            normal, phi = measured[g], phis[g]
            if t:
                h = next(shifted)
                if not np.isnan(phis[h]) and (np.isnan(phi) or phis[h] + self.tilt[idx[0]] < phi):
                    normal, phi = measured[h], phis[h] + self.tilt[idx[0]]
            if np.isnan(phi):
                continue
            normal = f, normal, float(phi)
            others = np.setdiff1d(np.arange(len(self.points)), idx)
            # Each other touch's grown patch box along f (an unbounded one's: everywhere).
            middle = self.patch_middle[others] @ f
            half = np.where(self.bounded[others], 0.5 * self.patch_width[others] @ np.abs(f), np.inf)
            heights = np.column_stack([middle - half, middle + half])
            level = f @ self.flat_anchor[idx[0]] + np.array([-1.0, 1.0]) * reach.mean()
            out.append((*normal, normal_signs(normal, points, level, self.points[others], heights)))
        if self.sensors is not None:
            # Its turn rows alone keep R f within phi of the sensor's normal: L (sin(phi) - tilt) <= sqrt(T)
            # (:mod:`.sensor_bounds`, the rows that only turn).
            most = np.sqrt(self.root**2 / self.sensors.weight) / np.sqrt(self.sensors.lever2)
            for (ctype, s, fx, *_), printed in zip(self.sensors.touches, self.sensors.printed):
                if ctype.is_locus and ctype.sensor == ctype.fixture == "PL" and most + printed.tilt < 1.0:
                    out.append((np.asarray(fx["n"], float), np.asarray(s["n"], float),
                                float(np.arcsin(most + printed.tilt)), (1.0, -1.0)))
        return out

    def first_cells(self):
        """The first level's cells: the rotation boxes that touched spheres' centres and planes' normals, and
        pairs of touches on planes and lines, leave (:func:`first_turns`), else every rotation
        (:func:`first_cells`; a lone box in its eight parts); y unbounded."""
        turn = first_turns(self.centres, self.normals, tube_pairs(self.planes, self.lines))
        if turn is None:
            return first_cells()
        v, w = turn
        ylo, yhi = np.full((len(v), 3), -np.inf), np.full((len(v), 3), np.inf)
        if len(v) == 1 and self.round.any():
            # A lone box holds every turn that may pass: where round touches are, their bend over it keeps it far
            # from a leaf and its model's ellipsoid too wide to narrow it, so its eight parts are bounded at once
            # (one level's bounds cost about the same for one cell as for eight).
            v, w, ylo, yhi = split(v, w, ylo, yhi, np.ones(1, bool), self.relevant)
        return v, w, ylo, yhi

    @functools.cached_property
    def fixes_pose(self):
        """Whether the rows can fix a pose: their largest rank at a few rotations (it drops at special ones), the
        touches' centroid on the touched patches' centre; with no point touch, only where the located sensors'
        slabs bound y. (The bounds hold either way: :mod:`.unlabelled` searches assignments whose rows leave
        motions free, for where no region is left.)"""
        groups = self.full.groups
        if not groups or not (self.problem.groups or self.triples):
            return False
        with np.errstate(invalid="ignore"):  # an unbounded patch's box has no middle: 0 there
            middle = np.mean([np.mean(patch_box(g.feature), axis=0) for g in groups], axis=0)
        middle = np.where(np.isfinite(middle), middle, 0.0)
        # The rows before a printed part's whitening, an invertible map (C^-1/2's eigenvalues lie in (0, 1] and
        # far above the rank's threshold): the same rank, without the modes' cost.
        return any(matrix_rank(self.full.sensor_rows(R, self.centroid - R @ middle)[1], self.full.scale()) == 6
                   for R in rotation_from_vector(RANK_ROTATIONS))

    def modes(self, groups, tolerance, q, stand_ins, sensors):
        """A printed part's deviation modes, as the first-order model carries them: ``L`` (k, k') with
        ``L L^T`` the touched features' mode covariance S; each touch's modes' twists (n, k, 6) and radius
        flags (n, k); each touch's deviation bound ``dev`` (mm, :func:`deviation_bound`) and ``tilt`` = the
        largest turn (rad) of its feature that a pose that passes allows, ``sqrt(q lambda_max)`` of its turn's
        covariance. A sensor's stand-in takes its sensor's feature's modes, its deviation bound from
        :func:`.stand_ins.deviation_bound_mm`, and a radius mode moves its element by ``radius_move`` (fixture
        frame) or the turned ``radius_sensor`` (measurement frame), its size within ``radius_dev`` (mm). Each
        bounded sensor touch (its group in ``sensors``) gets its feature's modes' twists and radius flags, times
        L (``sensor_twists`` (s, 6, k'), ``sensor_radius`` (s, k')), and its :class:`.sensor_bounds.Printed`
        (``printed``)."""
        n = sum(g.count for g in groups)
        self.dev, self.tilt, self.L, self.printed = np.zeros(n), np.zeros(n), None, None
        if tolerance is None:
            return
        links = [None] * (len(groups) - len(stand_ins)) + [None if one.own else one for one in stand_ins]
        sources = [g.feature if link is None else link.source for g, link in zip(groups, links)]
        fids = list(dict.fromkeys([f.id for f in sources] + [g.feature.id for g in sensors]))
        # The touched features' modes among the tolerance's (the columns of L's rows).
        self.mode_index = index = np.concatenate([np.arange(tolerance.slices[f].start, tolerance.slices[f].stop)
                                                  for f in fids])
        S = tolerance.covariance[np.ix_(index, index)]
        h, E = np.linalg.eigh(S)
        keep = h > 1e-12 * max(h[-1], 1e-300)
        self.L = E[:, keep] * np.sqrt(h[keep])
        self.mode_twists = np.zeros((n, len(index), 6))
        self.mode_radius = np.zeros((n, len(index)), bool)
        self.radius_own = np.ones(n, bool)
        self.radius_move, self.radius_sensor, self.radius_dev = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)
        sizes = [tolerance.slices[f].stop - tolerance.slices[f].start for f in fids]
        start = dict(zip(fids, np.cumsum([0] + sizes[:-1])))
        first = 0
        for g, source, link in zip(groups, sources, links):
            f, m = source.id, tolerance.modes[source.id]
            columns = slice(start[f], start[f] + len(m.names))
            rows = slice(first, first + g.count)
            self.mode_twists[rows, columns] = m.twists
            self.mode_radius[rows, columns] = m.radius
            s = tolerance.covariance[tolerance.slices[f], tolerance.slices[f]]
            if link is None:
                self.dev[rows] = deviation_bound(tolerance, source, q)
            else:
                self.dev[rows] = deviation_bound_mm(tolerance, source, link.places, q)
                self.radius_own[rows] = False
                self.radius_move[rows], self.radius_sensor[rows] = link.move, link.sensor_move
                radius = m.radius.astype(float)
                self.radius_dev[rows] = np.sqrt(q * max(radius @ s @ radius, 0.0)) * np.linalg.norm(link.sensor_move)
            self.tilt[rows] = _largest_turn(tolerance, f, q)
            first += g.count
        twists, radius = np.zeros((len(sensors), len(index), 6)), np.zeros((len(sensors), len(index)))
        self.printed = []
        for k, g in enumerate(sensors):
            f, m = g.feature.id, tolerance.modes[g.feature.id]
            columns = slice(start[f], start[f] + len(m.names))
            twists[k, columns] = m.twists
            radius[k, columns] = m.radius
            self.printed.append(Printed(_largest_turn(tolerance, f, q),
                                        deviation_bound_mm(tolerance, g.feature, m.centre[None], q), m.centre))
        # Through L at once: what a cell's rows need (the modes u, not the features' own).
        self.sensor_twists, self.sensor_radius = np.einsum("sci,cj->sij", twists, self.L), radius @ self.L

    def printed_centre(self, idx):
        """The shells a printed sphere's centre lies in, touched by ``idx`` (four or more touches on it, point or
        ball, its own radius): (radius (n,), width (n,), move), None where they leave it open.

        A pose that passes has modes ``z = L u``, ``|u|^2 <= q``, with each row ``r_i - n_i.dc - dr`` within
        sqrt(T): the modes move the centre by dc (at most ``centre_move``) and the radius by dr (at most
        ``radius_grow``, :meth:`mode_moves`). So each touch lies from the printed centre c + dc within ``R' +-
        w`` of a radius ``R' = R + dr`` common to the touches, ``w = sqrt(T) + |dc|^2 / (2 (a - |dc|))`` (``|s -
        dc| - (|s| - n.dc)`` lies in ``[0, |dc|^2 / (2 (|s| - |dc|))]``, ``a`` the least ``|s|``): the radical
        slabs of a common radius are ``4 R' w`` wide, wherever dr puts R'. The printed centre's box
        (:func:`shell_box` with the largest R') grown by the largest ``|dc|`` (``move``) holds the centre's."""
        move, grow = self.centre_move[idx[0]], self.radius_grow[idx[0]]
        least = np.min(self.offset[idx] - self.root - self.dev[idx]) - move
        if least <= 0.0:
            return None
        return self.offset[idx] + grow, np.full(len(idx), self.root + move**2 / (2.0 * least)), move

    def mode_moves(self, q):
        """What the modes of a pose that passes (``z = L u``, ``|u|^2 <= q``) move, per touch (mm):
        ``centre_move``, the largest move ``|omega x c + v|`` of its feature's anchor c; ``radius_grow``, of its
        radius; ``turn_dev``, the largest ``|omega x x + v|`` at any place x of its grown patch box (at most
        ``centre_move`` plus the largest turn times the box's farthest corner from c, or the same about the box's
        middle), the part of its row's change with the modes that turns with its outward direction (a radius
        mode's, -1 on a touch of its own feature, does not; a stand-in keeps its deviation bound there)."""
        n = len(self.points)
        self.centre_move, self.radius_grow, self.turn_dev = np.zeros(n), np.zeros(n), self.dev.copy()
        if self.L is None:
            return
        twists = self.mode_twists * ~self.mode_radius[..., None]
        self.radius_grow = np.sqrt(q) * np.linalg.norm(self.mode_radius @ self.L, axis=1)
        # About the anchor, or about the box's middle p (``omega x x + v = omega x (x - p) + (omega x p + v)``), the
        # nearer for a long boss anchored at one end.
        corners = np.where(CORNERS[None] > 0.0, self.high[:, None], self.low[:, None])  # (n, 8, 3)
        far = np.max(np.linalg.norm(corners - self.anchor[:, None], axis=2), axis=1)
        half = np.linalg.norm(0.5 * (self.high - self.low), axis=1)
        bounded = np.isfinite(far) & np.isfinite(half)
        far, half = np.where(bounded, far, 0.0), np.where(bounded, half, 0.0)
        middle = np.where(bounded[:, None], 0.5 * (self.low + self.high), 0.0)
        # The largest move of the anchor, of the turn and of the middle, in one call.
        arms = np.stack([cross(twists[..., :3], self.anchor[:, None]) + twists[..., 3:], twists[..., :3],
                         cross(twists[..., :3], middle[:, None]) + twists[..., 3:]])  # (3, n, k, 3)
        self.centre_move, turn, moved = np.sqrt(q) * largest_move(arms, self.L @ self.L.T)
        bound = np.minimum(self.centre_move + turn * far, moved + turn * half)
        # An unbounded patch gives no lever: where its feature turns, the touch keeps its deviation bound.
        own = self.round & self.radius_own & (bounded | (turn == 0.0))
        self.turn_dev[own] = bound[own]

    def deviation_rows(self, unit, touch, x, R):
        """How each row (unit directions (K, R, 3) of touches ``touch`` (R,) at fixture places x (K, n, 3), the
        cells' rotations R (K, 3, 3)) moves with the modes' coordinates u (``z = L u``): (K, R, k'). A mode moves
        its feature's surface by ``omega x p + v`` (a row by minus that along it), a radius mode along the outward
        direction (a stand-in's element by its ``radius_move``, or its sensor's turned by R)."""
        # The modes' twists taken to u's coordinates (R, 6, k'), a radius mode's apart (it moves a row along it).
        twists = np.einsum("rmi,ml->ril", np.where(self.mode_radius[touch][..., None], 0.0, self.mode_twists[touch]),
                           self.L)
        # u . (omega x p + v) = (p x u) . omega + u . v, a row by minus that: a product per touch over the cells.
        arm = np.concatenate([cross(x[:, touch], unit), unit], axis=2).transpose(1, 0, 2)  # (R, K, 6)
        change = -(arm @ twists).transpose(1, 0, 2)
        move = self.radius_move[touch][None] + np.einsum("kji,rj->kri", R, self.radius_sensor[touch])
        radius = np.where(self.radius_own[touch][None], -1.0, -np.einsum("kri,kri->kr", unit, move))
        return change + radius[..., None] * (self.mode_radius[touch] @ self.L)[None]

    # --- the bounds ----------------------------------------------------------------------------------------

    def round_rows(self, c, kappa):
        """The round touches' rows to first order over the cells: ``value + (u x a).omega + u.y`` (value (K, m),
        u (K, m, 3)), each off its true distance by at most ``off`` (K, m) mm; ``usable`` (K, m): whether the
        touch's move D over the cell (its turn, ``kappa`` (K, m) the turn's remainder, and the y box) keeps it off
        its core (else its row is 0: no model); ``turn`` (K, m): how far its direction from the core turns (rad;
        inf where not usable). The distance ``|s|`` is convex in the touch's place: above its tangent at s_0, by
        at most the bend (:func:`_bend`); the model takes half the bend, and is off by the other half either way,
        and by kappa."""
        centre = self.box_centre(c.ylo, c.yhi)
        s0, u, half = self.round_offsets(c, centre)
        d0 = s0 - self.offset[self.round]
        move = c.delta[:, None] * self.rho[self.round] + half + kappa
        core_gap = s0 - move  # the least |s| over the move
        usable = core_gap > 0.0
        gap = np.where(usable, core_gap, 1.0)
        bend = np.where(usable, 0.5 * _bend(move, np.where(usable, s0, 1.0)), 0.0)
        value = np.where(usable, d0 + bend - np.einsum("kri,ki->kr", u, centre), 0.0)
        return value, np.where(usable[..., None], u, 0.0), np.where(usable, kappa + bend, 0.0), usable, \
            np.where(usable, move / gap, np.inf)

    def round_offsets(self, c, centre):
        """Each round touch's offset from its core at R0 with y the box's centre (fixture frame): its length
        ``|s_0|`` and direction u (K, r, 3), and how far the y box moves it across the core (K, r): the box's
        half-diagonal, across the box's last axis for a cylinder along it."""
        d0, u = self.distances(c.a, centre)
        half = 0.5 * (c.yhi - c.ylo)
        half = np.where(self.aligned[None, self.round], np.linalg.norm(half[:, :2], axis=1)[:, None],
                        np.linalg.norm(half, axis=1)[:, None])
        return d0[:, self.round] + self.offset[self.round], u[:, self.round], half

    def cells(self, v, w, ylo, yhi):
        """Each cell's rotation, touches at ``R0``, y box shrunk to the patches, lower bound of the cost, and its
        first-order model (:meth:`first_order`): a :class:`Cells`."""
        return self.first_bound(self.zeroth_bound(Cells(v, w, ylo, yhi)))

    def zeroth_bound(self, c):
        """The cells' y boxes shrunk to the patches and the slabs, and ``zeroth``, their zeroth-order bound (on a
        cell the patches and the flat touches already put over T, that bound: the slabs are not drawn)."""
        v, w = c.v, c.w
        c.delta = np.sqrt(3.0) * w
        c.R = rotation_from_vector(v)
        c.a = turned_points(self.points - self.centroid, c.R)  # R0^T b_i
        turn = c.delta[:, None] * self.rho[None]
        # How far off its element a touch that passes may lie at R0: sqrt(T), its deviation bound and its turn.
        reach = self.root + self.dev[None] + turn
        # The flat rows at R0 and y = 0: the row at y is value + m.y.
        value = np.einsum("ri,kri->kr", self.row_unit, c.a[:, self.row_touch] - self.flat_anchor[self.row_touch])
        # y keeps every touch within reach of its patch's box: each box about y's own axes (none for an unbounded
        # patch).
        middle = on_axes(self.patch_middle[None] - c.a, self.Q)
        half = self.patch_half[None] + turn[..., None]
        lo, hi = middle - half, middle + half
        # ... and every round touch within its reach of its element: its core within that of its radius, on the
        # axes its distance depends on (``fixing``; a line core across the box's axes: the touch may lie anywhere
        # along it).
        if len(self.fixing):
            f = self.fixing
            core_reach = (self.offset[f][None] + reach[:, f])[..., None]
            core = on_axes(self.anchor[f][None] - c.a[:, f], self.Q)
            if self.fixing_axes.all():
                lo[:, f], hi[:, f] = np.maximum(lo[:, f], core - core_reach), np.minimum(hi[:, f], core + core_reach)
            else:
                lo[:, f] = np.where(self.fixing_axes, np.maximum(lo[:, f], core - core_reach), lo[:, f])
                hi[:, f] = np.where(self.fixing_axes, np.minimum(hi[:, f], core + core_reach), hi[:, f])
        turned = np.abs(c.R @ self.Q) if self.centres else None
        for anchor, rel, half, lever in self.centres:
            spread = half @ turned + (c.delta * lever)[:, None]
            middle = (anchor - rel @ c.R) @ self.Q
            c.ylo, c.yhi = np.maximum(c.ylo, middle - spread), np.minimum(c.yhi, middle + spread)
        if len(self.points):
            c.ylo = np.maximum(c.ylo, across(np.maximum, lo))
            c.yhi = np.minimum(c.yhi, across(np.minimum, hi))
        flat = None
        if self.flat.any():
            # q(y) = sum (value + m.y)^2 >= q_min + h |y - y*|^2 outside the box's reach of y*.
            y_star = -(value @ self.row_unit) @ self.H_flat_pinv.T
            q_min = np.sum((value + y_star @ self.row_unit.T) ** 2, axis=1)
            y_hat = y_star @ self.Q
            grouped = sum(np.maximum(np.linalg.norm(value[:, rows] @ off, axis=1) - c.delta * swing - dev, 0.0) ** 2
                          for rows, off, swing, dev in self.flat_groups) if self.flat_groups else np.zeros(len(v))

            def flat(k, ylo, yhi):
                """The flat touches' bound of cells k with these y boxes."""
                gap = np.maximum(ylo - y_hat[k], 0.0) + np.maximum(y_hat[k] - yhi, 0.0)
                root = np.sqrt(q_min[k] + self.H_flat_least * np.sum(gap**2, axis=1)) - c.delta[k] * self.flat_swing
                return np.maximum(np.maximum(root - self.flat_dev, 0.0) ** 2, grouped[k])
        # The bound so far (an empty box: none passes; the flat touches' over the box before the slabs shrink it,
        # which only raises it): the slabs and the rest only for the cells it keeps, which are all it can keep.
        empty = np.any(c.ylo > c.yhi, axis=1)
        c.zeroth = np.where(empty, np.inf, 0.0 if flat is None else flat(slice(None), c.ylo, c.yhi))
        live = np.flatnonzero(c.zeroth <= self.root**2)
        kept = c.take(live)
        room = self.contract(kept, reach[live], value[live])
        c.ylo[live], c.yhi[live] = kept.ylo, kept.yhi
        # A cell the slabs leave no y holds no pose that passes: the rest only for the others.
        c.zeroth[live[~room]] = np.inf
        live, kept = live[room], kept.take(room)
        # Zeroth order: each touch within its turn of where it is at R0.
        bound = np.zeros(len(live)) if flat is None else flat(live, kept.ylo, kept.yhi)
        if self.round.any():
            near = self.round_least(kept.a, kept.ylo, kept.yhi)
            bound = bound + np.sum(np.maximum(near - turn[live][:, self.round] - self.dev[self.round], 0.0) ** 2, axis=1)
        if self.sensors is not None:
            # The sensors bounded by their own rows: a cost apart from the touches', and their first-order rows.
            bound = bound + self.sensor_rows(kept)
            for name in SENSOR_ROWS:
                x = getattr(kept, name)
                setattr(c, name, np.zeros((len(v),) + x.shape[1:], x.dtype))
                getattr(c, name)[live] = x
        c.zeroth[live] = bound
        return c

    def sensor_rows(self, c):
        """The bounded sensors' cost bound over the cells (K,); their first-order rows (``SENSOR_ROWS``) filled in
        (:meth:`.sensor_bounds.SensorBounds.cells`)."""
        sensed, *rows = self.sensors.cells(c.R, c.delta, self.box_centre(c.ylo, c.yhi),
                                           np.linalg.norm(0.5 * (c.yhi - c.ylo), axis=1), self.root)
        for name, x in zip(SENSOR_ROWS, rows):
            setattr(c, name, x)
        return sensed

    def first_bound(self, c):
        """The cells' first-order model and bound ``first``, ``bound`` the larger of the two, and the y boxes
        shrunk to the model's ellipsoid."""
        self.first_order(c)
        # The zeroth-order bound holds the cost with each distance less its deviation bound, the first-order one
        # the test's own cost; a pose over T in the first is over it in the second (docs/registration.md).
        c.first = np.maximum(np.maximum(np.sqrt(c.least) - c.remainder, 0.0) ** 2, c.dual)
        c.bound = np.maximum(c.zeroth, c.first)
        # The y of a pose that may pass lies in the model's ellipsoid: the box shrinks to its shadow on the box's
        # axes (the remainders hold over the box it had).
        c.W, c.theta, c.slack, c.held = W, theta, slack, held = self.ellipsoid(c)
        centre = theta[:, 3:6] @ self.Q
        half = np.sqrt(slack[:, None] * np.sum(self.Q * (W[:, 3:6, 3:6] @ self.Q), axis=1))
        c.ylo = np.where(held[:, None], np.maximum(c.ylo, centre - half), c.ylo)
        c.yhi = np.where(held[:, None], np.minimum(c.yhi, centre + half), c.yhi)
        c.bound = np.where(np.any(c.ylo > c.yhi, axis=1), np.inf, c.bound)
        return c

    def contract(self, c, reach, value):
        """Shrink the cells' y boxes to the slabs every pose that passes keeps y in: each touch's distance is at
        most ``s_i = sqrt(T) + e_i + delta rho_i`` at ``R0`` (each touch's share of the cost is at most ``T``,
        its turn moves it at most ``delta rho_i``); a flat row ``value + m.y`` lies in ``[-s_i, s_i]``, and two
        round touches on one core, at ``D_i in [r_i - s_i, r_i + s_i]`` from it, have ``D_i^2 - D_j^2 =
        |P u_i|^2 - |P u_j|^2 + 2 P (u_i - u_j) . y`` (``u = a - anchor``, ``P`` the projector across the
        core). The bounded sensors add theirs (:meth:`.sensor_bounds.SensorBounds.slabs`, ``located``: a located
        contact point's across its feature's axis, three of which narrow the box to the parallelepiped they hold,
        :func:`boxed`). Each slab ``l <= g.y <= u`` narrows each axis of the box to what the other axes leave
        (interval propagation, in rounds over all slabs at once). ``reach`` (K, n): the ``s_i``; ``value`` (K,
        rows): the flat rows at ``y = 0``. Returns whether each cell leaves y any room (K,); the others' boxes are
        left as they are."""
        # The flat rows' and the slabs' directions are every cell's: one array of them, not one a cell.
        g = [self.row_unit @ self.Q]
        low, high = [-value - reach[:, self.row_touch]], [-value + reach[:, self.row_touch]]
        if len(self.slab_touch):
            i = self.slab_touch
            along = np.einsum("si,ksi->ks", self.slab_normal, c.a[:, i] - self.anchor[i])
            radius = self.offset[i][None] + reach[:, i]
            g.append(self.slab_normal @ self.Q)
            low.append(-radius - along)
            high.append(radius - along)
        if len(self.axial_normals):
            a, b = self.sensors.located(c.R, c.delta)
            for rows, inverse in self.triples:
                c.ylo, c.yhi = boxed(inverse, a[:, rows], b[:, rows], c.ylo, c.yhi)
            g.append(self.axial_normals)
            low.append(a)
            high.append(b)
        slabs = [(np.concatenate(g), np.concatenate(low, axis=1), np.concatenate(high, axis=1))]
        if self.round.any():
            slabs.append(self.round_slabs(c, reach[:, self.round]))
        if len(self.pairs):
            i, j = self.pairs.T
            k, m = self.pair_index.T
            Pu = c.a[:, self.paired] - self.anchor[self.paired]
            if self.paired_across:  # (on a point core the projector is the identity)
                Pu = np.einsum("pij,kpj->kpi", self.paired_projector, Pu)
            square = np.sum(Pu**2, axis=2)
            near = np.maximum(self.offset[None] - reach, 0.0) ** 2
            far = (self.offset[None] + reach) ** 2
            constant = square[:, k] - square[:, m]
            slabs.append((on_axes(2.0 * (Pu[:, k] - Pu[:, m]), self.Q), near[:, i] - far[:, j] - constant,
                          far[:, i] - near[:, j] - constant))
        # A cell one slab misses over its box as it is holds no y (most cells, early on, where sensors' slabs hold
        # y): the sensors' slabs, the dearest, are drawn for the others alone, and those they leave are narrowed.
        slabs = [slab for slab in slabs if slab[1].size]
        room = ~np.any(c.ylo > c.yhi, axis=1) & ~missed(slabs, c.ylo, c.yhi)
        live = np.flatnonzero(room)
        slabs = [(g if g.ndim == 2 else g[live], low[live], high[live]) for g, low, high in slabs]
        lo, hi = c.ylo[live], c.yhi[live]
        if self.sensors is not None:
            planes = self.sensors.slabs(c.R[live], c.delta[live], self.box_centre(lo, hi),
                                        np.linalg.norm(0.5 * (hi - lo), axis=1), self.root)
            if planes is not None:
                planes = (on_axes(planes[0], self.Q), planes[1], planes[2])
                hit = ~missed([planes], lo, hi)
                room[live] = hit
                live, lo, hi = live[hit], lo[hit], hi[hit]
                slabs = [(g if g.ndim == 2 else g[hit], low[hit], high[hit]) for g, low, high in slabs + [planes]]
        if slabs:
            c.ylo[live], c.yhi[live] = propagated(slabs, lo, hi, CONTRACT_ROUNDS)
        room[live] = ~np.any(c.ylo[live] > c.yhi[live], axis=1)
        return room

    def round_slabs(self, c, reach):
        """Slabs ``low <= g.y <= high`` (g (K, r, 3) on the box's axes; low, high (K, r)) that hold every y of the
        cells' boxes that puts each round touch within its ``reach`` (K, r) of its element at R0: its offset from
        the core, ``s_0 + P e`` about the box's centre (e = y - y_c), has its length within reach of the radius;
        that length lies above the tangent ``|s_0| + u.e`` (convex) and below it plus the bend of ``|P e|``
        (:meth:`round_rows`): a slab along the outward direction u (none where the touch lies on its core)."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            centre = self.box_centre(c.ylo, c.yhi)
            s0, u, half = self.round_offsets(c, centre)
            bend = _bend(half, s0)
            along = np.einsum("kri,ki->kr", u, centre) + self.offset[self.round] - s0
            return on_axes(u, self.Q), np.where(s0 > 0.0, along - reach - bend, -np.inf), \
                np.where(s0 > 0.0, along + reach, np.inf)

    def closer(self, c):
        """Held cells modelled again about their model's ellipsoid, which holds every pose of theirs that may pass
        (:meth:`ellipsoid`): over the y boxes it shrank, and about the turn ``R0 exp(omega*)`` of its centre, within
        ``r`` (:meth:`turn_reach`; ``exp`` moves a turn no farther than its rotation vector moves) and within
        ``delta + |omega*|`` as the cell is. The bounds and the model hold for the poses that may pass, not the
        whole cell: a cell whose bound exceeds T holds none, one whose model is then close is a leaf (its
        rotation box, which only joins leaves into regions, is the cell's), and any other is to be split as it
        was."""
        star = c.theta[:, :3]
        c.delta = np.minimum(self.turn_reach(c), c.delta + np.linalg.norm(star, axis=1))
        c.R = c.R @ rotation_from_vector(star)
        c.a = turned_points(self.points - self.centroid, c.R)
        if self.sensors is not None:
            self.sensor_rows(c)
        return self.first_bound(c)

    def turn_reach(self, c):
        """How far (K,) rad from ``R0 exp(omega*)`` the turn of any pose of the cells that may pass lies: the
        shadow of the model's ellipsoid on omega, ``sqrt(slack lambda_max(W_ww))`` (held cells only; inf on the
        others). W's omega block is the inverse of the y-reduced form A (block inversion; where the model holds every
        motion, the y block's pseudo-inverse is its inverse), whose least eigenvalue ``alpha`` the model has."""
        with np.errstate(divide="ignore"):
            return np.where(c.held, np.sqrt(c.slack / c.alpha[:, 0]), np.inf)

    def narrowed(self, c):
        """Which cells' rotation boxes narrow to their model's ellipsoid, and the narrower boxes (v, w).

        A pose of the cell that passes has its turn ``omega`` in the ellipsoid's shadow, within ``r =
        sqrt(slack lambda_max(W_ww))`` of ``omega*``, and ``|omega| <= delta``. Follow the rotation vector of
        ``R0 exp(omega)`` from ``v0`` as omega moves: its length moves no faster than omega (along its axis
        the inverse right Jacobian is 1), so it stays within ``a = |v0| + delta < 2 pi``, and the vector moves at
        most ``(a/2) / sin(a/2)`` times as fast as omega (that Jacobian's norm). So it lies within that times
        ``min(r, 2 delta)`` of the vector of ``R0 exp(omega*)`` nearest ``v0``: the box of that half-width about
        it holds every pose of the cell that passes (with the y box the cell has)."""
        star = c.theta[:, :3]
        angle = np.linalg.norm(c.v, axis=1) + c.delta
        reach = self.turn_reach(c)
        half = np.minimum(angle, NARROW_ANGLE) / 2.0
        w = half / np.sin(half) * np.minimum(reach, 2.0 * c.delta)
        narrow = c.held & (np.linalg.norm(star, axis=1) <= c.delta) & (angle <= NARROW_ANGLE) & (w <= NARROW_GAIN * c.w)
        v = vector_from_rotation(c.R[narrow] @ rotation_from_vector(star[narrow]))
        # The same rotation's other vector, past a half turn, where the cell's own vector lies beyond pi.
        length = np.linalg.norm(v, axis=1, keepdims=True)
        other = v - 2.0 * np.pi * v / np.maximum(length, 1e-300)
        far = np.linalg.norm(other - c.v[narrow], axis=1) < np.linalg.norm(v - c.v[narrow], axis=1)
        return narrow, np.where(far[:, None], other, v), w[narrow]

    def first_order(self, c):
        """The touches' rows to first order in the cell's turn ``omega`` (``R = R0 exp(omega)``, ``|omega| <=
        delta``) and image y: ``value + Jw.omega + m.y``, off the true rows by a vector no longer than
        ``remainder`` (mm). A turn puts touch i at ``exp(-omega) a_i = a_i + a_i x omega + e_i``, ``|e_i| <=
        (delta^2/2 + delta^3/6) rho_i``; a round touch's distance ``|s| - r`` (``s`` its offset from the core)
        lies above its tangent by at most the bend (:meth:`round_rows`). Fills ``least``: a lower bound of the
        model's least cost over ``|omega| <= delta`` and any y (weak duality: ``Q0 - b^T (A + lambda I)^-1 b -
        lambda delta^2`` for any lambda >= 0, y eliminated exactly), ``dual``: a lower bound of the cost
        (:func:`dual_bound`, at the model's rows where that lambda puts its least), and what :meth:`leaf_poses`
        needs."""
        K = len(c.v)
        kappa = (c.delta**2 / 2.0 + c.delta**3 / 6.0)[:, None] * self.rho[None]
        unit = np.broadcast_to(self.row_unit, (K,) + self.row_unit.shape)
        a_rows = c.a[:, self.row_touch]
        value = np.einsum("kri,kri->kr", unit, a_rows - self.flat_anchor[self.row_touch])
        # Each row's own remainder (K, rows); a flat touch's turn remainder kappa moves its rows together, a vector
        # of length at most kappa across them.
        row_off = [np.zeros(value.shape)]
        if self.round.any():
            round_value, u, off, usable, turn = self.round_rows(c, kappa[:, self.round])
            unit = np.concatenate([unit, u], axis=1)
            a_rows = np.concatenate([a_rows, c.a[:, self.round]], axis=1)
            value = np.concatenate([value, round_value], axis=1)
            row_off.append(off)
        # A round touch whose move may reach its core has no tangent model: the cell is no leaf.
        c.modelled = np.all(usable, axis=1) if self.round.any() else np.ones(K, bool)
        Jw = cross(unit, a_rows)  # row j's change with omega: m . (a x omega) = (m x a) . omega
        touch_rows = unit.shape[1]
        if self.sensors is not None:
            unit, Jw = np.concatenate([unit, c.s_m], axis=1), np.concatenate([Jw, c.s_jw], axis=1)
            value = np.concatenate([value, c.s_value], axis=1)
            row_off.append(c.s_rem)
            c.modelled = c.modelled & c.s_fine
        row_off = np.concatenate(row_off, axis=1)
        # The rows' columns (value, then omega's and y's) and their products: all the bound and the ellipsoid need.
        columns = np.concatenate([value[..., None], Jw, unit], axis=2)
        gram = columns.transpose(0, 2, 1) @ columns
        if self.L is not None:
            # The part's deviations z = L u as unknowns beside y, each u held by sigma u (the test is min over z
            # of |r - J_d z|^2 + sigma^2 z^T S^-1 z): the rows' change with u taken at the y box's
            # centre, off by at most the touch's move times its feature's largest turn (and, on a round
            # feature, by its direction's turn times its deviation bound).
            touch = np.concatenate([self.row_touch, np.flatnonzero(self.round)])
            centre = self.box_centre(c.ylo, c.yhi)
            spread = np.linalg.norm(0.5 * (c.yhi - c.ylo), axis=1)[:, None]
            move_all = c.delta[:, None] * self.rho[None] + kappa + spread
            off_dev = move_all[:, touch] * self.tilt[touch]
            if self.round.any():
                rounds = slice(len(self.row_touch), None)
                off_dev[:, rounds] += turn * self.turn_dev[self.round]
            # A stand-in's radius mode along its sensor's normal turns with the cell: off by delta times its size.
            off_dev += c.delta[:, None] * self.radius_dev[touch]
            row_off[:, :touch_rows] += off_dev
            Jz = self.deviation_rows(unit[:, :touch_rows], touch, c.a + centre[:, None], c.R)
            if self.sensors is not None:
                # A sensor's row moves with its feature's modes as the row's twist and radius say (its remainder
                # in the sensor's own).
                rows = self.sensors.row_touch
                change = (c.s_twist.transpose(1, 0, 2) @ self.sensor_twists[rows]).transpose(1, 0, 2) \
                    + c.s_radius[..., None] * self.sensor_radius[rows][None]
                Jz = np.concatenate([Jz, change], axis=1)
            # u eliminated exactly: min over u of |v - Jz u|^2 + sigma^2 |u|^2 (:func:`_modes_eliminated`), the
            # model's least and its ellipsoid's shadow on (omega, y) as with u among the unknowns.
            eliminated, U, JzU = _modes_eliminated(Jz, self.problem.sigma, columns)
            gram = gram - eliminated
        # The rows' error is a flat touch's turn vector plus each row's own: its length at most the root of the
        # squares of each flat touch's kappa plus its rows' own (their root) and of every other row's own.
        flat_kappa = kappa[:, self.flat]
        c.remainder = np.sqrt(np.sum((flat_kappa + self.flat_sizes(row_off)) ** 2, axis=1)
                              + np.sum(row_off[:, len(self.row_touch):] ** 2, axis=1))
        c.gram = gram
        h, E = np.linalg.eigh(gram[:, 4:, 4:])
        c.H_pinv = (E * np.where(h > 1e-9 * h[:, -1:], 1.0 / np.maximum(h, 1e-300), 0.0)[:, None]) @ E.transpose(0, 2, 1)
        A, c.b, c.Q0 = _reduced(gram, c.H_pinv)
        c.alpha, c.V = np.linalg.eigh(A)
        c.alpha = np.maximum(c.alpha, 0.0)
        beta = np.einsum("kij,ki->kj", c.V, c.b)
        beta2 = beta**2
        # Newton on the secular equation 1/|p(lambda)| = 1/delta from lambda = 0 (monotone from below), until it
        # stops moving.
        lam = np.zeros(K)
        for _ in range(8):
            shifted = np.maximum(c.alpha + lam[:, None], 1e-90)
            p2 = np.sum(beta2 / shifted**2, axis=1)
            phi = 1.0 / np.sqrt(np.maximum(p2, 1e-300)) - 1.0 / c.delta
            slope = np.sum(beta2 / shifted**3, axis=1) / np.maximum(p2, 1e-150) ** 1.5
            with np.errstate(over="ignore", invalid="ignore"):
                step = phi / np.maximum(slope, 1e-300)
            # Any lambda >= 0 gives a bound: a step that does not come out finite is not taken.
            new = np.maximum(lam - np.where(np.isfinite(step), step, 0.0), 0.0)
            settled = np.all(np.abs(new - lam) <= 1e-12 * new)
            lam = new
            if settled:
                break
        shifted = c.alpha + lam[:, None]
        # An axis with no curvature adds nothing without a pull along it, and leaves no bound with one.
        terms = np.where(beta2 > 0.0, beta2 / np.where(shifted > 0.0, shifted, 1.0), 0.0)
        terms = np.where((shifted <= 0.0) & (beta2 > 1e-30), np.inf, terms)
        c.least = np.maximum(c.Q0 - np.sum(terms, axis=1) - lam * c.delta**2, 0.0)
        # The model's rows at its least with that lambda: omega* = -(A + lambda I)^-1 b, y* eliminated, the modes' u*.
        omega = -np.einsum("kij,kj->ki", c.V,
                           np.where(shifted > 0.0, beta / np.where(shifted > 0.0, shifted, 1.0), 0.0))
        y = -np.einsum("kij,kj->ki", c.H_pinv, gram[:, 4:, 0] + np.einsum("kij,ki->kj", gram[:, 1:4, 4:], omega))
        x = np.concatenate([np.ones((K, 1)), omega, y], axis=1)
        rows = np.einsum("krj,kj->kr", columns, x)
        modes = np.zeros(K)
        if self.L is not None:
            rows, modes = _modes_left(U, JzU, self.problem.sigma, rows, x)
        c.dual = dual_bound(columns, rows, modes, c.delta, box_middle(c.ylo, c.yhi), 0.5 * (c.yhi - c.ylo), self.Q,
                            row_off, flat_kappa, self.flat_sizes(rows))

    def flat_sizes(self, x):
        """Each flat touch's length (K, f) of its rows' part of x (K, rows)."""
        if not len(self.row_touch):
            return np.zeros((len(x), 0))
        return np.sqrt(np.add.reduceat(x[:, :len(self.row_touch)] ** 2, self.row_first, axis=1))

    def box_centre(self, ylo, yhi):
        """The centres (K, 3) of y boxes (box axes), fixture frame (0 along an unbounded axis)."""
        return box_middle(ylo, yhi) @ self.Q.T

    def round_least(self, a, ylo, yhi):
        """The least distance (K, r) of each round touch from its element over the box of ``x_i`` that the
        ``y`` box puts it in: exact on a point core and on a line core along the box's last axis, within the
        box's half-diagonal on another line core."""
        centre, half = box_middle(ylo, yhi), 0.5 * (yhi - ylo)  # an unbounded axis: any centre, infinite half-width
        rel = on_axes(a[:, self.round] - self.anchor[self.round], self.Q) + centre[:, None]  # on the box's axes
        return least_over_box(rel, half[:, None], self.direction[self.round] @ self.Q,
                              self.core[self.round] == "point", self.aligned[self.round], self.offset[self.round])

    def distances(self, a, ys):
        """Distances (K, n) of the touches ``a + y`` from their elements, and their outward directions."""
        x = a + ys[:, None]
        d, u = np.empty(x.shape[:2]), np.empty(x.shape)
        for kind in ("point", "line", "plane"):
            part = self.core == kind
            if part.any():
                d[:, part], u[:, part] = distance_and_outward(kind, self.anchor[part], self.direction[part],
                                                              self.offset[part], x[:, part])
        return d, u

    def relaxed_cost(self, Rs, ts):
        """The touches' cost (K,) at poses, each distance less its deviation bound: what must pass."""
        a = np.einsum("kji,nj->kni", Rs, self.points - self.centroid)
        ys = np.einsum("kji,kj->ki", Rs, self.centroid - ts)
        return np.sum(np.maximum(np.abs(self.distances(a, ys)[0]) - self.dev, 0.0) ** 2, axis=1)

    # --- the search ----------------------------------------------------------------------------------------

    def leaves(self, v, w, ylo, yhi, fraction, kept, budget=None, tries=None):
        """The leaf cells (:class:`Cells`) grown from the given cells: split until their model's remainder is at
        most ``fraction sqrt(T)``; the cells kept per level are added to ``kept``. None when the search stops
        (past ``MAX_CELLS`` or ``MAX_LEVELS``, or more than ``budget`` cells kept in all), with the reason.
        ``tries`` (:class:`Tries`): on the best cell of a level that keeps more than ``WEAK_TRY_CELLS``."""
        done = []
        for _ in range(MAX_LEVELS):
            # The cheap zeroth-order bound first; the first-order model only for the cells it keeps.
            c = self.zeroth_bound(Cells(v, w, ylo, yhi))
            c = self.first_bound(c.take((c.zeroth <= self.root**2) & ~beyond_pi(c.v, c.w)))
            c = c.take(c.bound <= self.root**2)
            kept.append(len(c.v))
            if tries is not None and tries.left > 0 and len(c.v) > WEAK_TRY_CELLS:
                # The cell whose model's least pose fits best, its touches on their patches.
                R, y = self.leaf_poses(c)[:2]
                x = np.einsum("kji,nj->kni", R, self.points - self.centroid) + y[:, None]
                off = np.maximum(self.patch_low - x, 0.0) + np.maximum(x - self.patch_high, 0.0)
                k = np.argmin(np.sum(self.distances(x, np.zeros_like(y))[0] ** 2 + np.sum(off**2, axis=2), axis=1))
                tries(R[k], self.centroid - R[k] @ y[k])
            if budget is not None and sum(kept) > budget:
                return None, f"more than {budget} cells with sensors' rows left out: the rest leave the pose weak"
            limit = fraction * max(self.root, LEAF_MM / LEAF_FRACTION)
            leaf = c.modelled & (c.remainder <= limit)
            near = np.flatnonzero(~leaf & c.modelled & c.held & (c.remainder <= NEAR_LEAF * limit))
            if len(near):
                # A cell a little short of a leaf, modelled again about its ellipsoid (:meth:`closer`), again while
                # that narrows it: dropped, a leaf a level sooner, or split as it was.
                stay, leaves, closer = np.ones(len(c.v), bool), [], c.take(near)
                for _ in range(CLOSER_ROUNDS):
                    before = closer.remainder
                    closer = self.closer(closer)
                    passes = closer.bound <= self.root**2
                    now = passes & closer.modelled & (closer.remainder <= limit)
                    stay[near[~passes | now]] = False
                    leaves.append(closer.take(now))
                    again = passes & ~now & closer.modelled & closer.held & (closer.remainder <= CLOSER_GAIN * before)
                    closer, near = closer.take(again), near[again]
                    if not len(near):
                        break
                c = Cells.joined([c.take(stay)] + leaves)
                leaf = c.modelled & (c.remainder <= limit)
            if self.sensors is not None:
                # Where the model (the touches' and the sensors' rows) leaves a motion free, a leaf's poses are its
                # whole cell, which must then be as narrow as a settled region.
                whole = np.linalg.norm(0.5 * (c.yhi - c.ylo), axis=1) + c.delta * self.marker_rho.max()
                leaf &= c.held | (whole <= 0.5 * SETTLED_MM)
            done.append(c.take(leaf))
            c = c.take(~leaf)
            if not len(c.v):
                return Cells.joined(done), ""
            # A turn that moves the touches, or the bounded sensors' placement centres, more than the round touches'
            # y box is wide is split first (a sensor far from the touches pins the turn down).
            turn = c.delta * self.marker_rho.max() * self.turn_spread
            shift = np.linalg.norm(0.5 * (c.yhi - c.ylo)[:, self.relevant], axis=1) \
                if self.round.any() or self.sensors is not None else np.zeros(len(c.v))
            if self.centres:
                # The y box that touched spheres' centres bound is about as wide as the turn moves them, on each
                # axis: a split of y cannot narrow that part, a split of the turn does.
                shift = shift - np.sqrt(3.0) * c.delta * min(lever for *_, lever in self.centres)
            # A y box still unbounded (unbounded patches) has no middle to split at: its turn is split.
            turning = (turn >= shift) | ~np.isfinite(shift)
            if 8 * turning.sum() + 2 * (~turning).sum() > MAX_CELLS or sum(len(d.v) for d in done) > MAX_LEAVES:
                return None, CONTINUUM
            # A cell whose model pins its turn down is narrowed to it at once, the rest split.
            narrow, v_narrow, w_narrow = self.narrowed(c)
            v, w, ylo, yhi = split(c.v[~narrow], c.w[~narrow], c.ylo[~narrow], c.yhi[~narrow], turning[~narrow],
                                   self.relevant)
            v, w = np.concatenate([v, v_narrow]), np.concatenate([w, w_narrow])
            ylo, yhi = np.concatenate([ylo, c.ylo[narrow]]), np.concatenate([yhi, c.yhi[narrow]])
        return None, f"cells still wider than a leaf after {MAX_LEVELS} levels"

    def regions(self, partial=False, stop=None):
        """:class:`Regions` over every rotation and image. ``partial``: sensors' rows are left out, which may narrow what the rows
        searched leave wide: a region whose pose passes is settled however wide (splitting it finer would not
        narrow it), and the search stops past ``PARTIAL_CELLS`` cells (the rows searched leave the pose weak).

        ``stop(R, t, extent_mm)``: what it finds from (R, t) when a pose refined from it passes but the touches
        determine it too weakly to judge, or (given the ``extent_mm`` of a settled region about it) when that
        region of poses that may pass is too wide to judge, else None. Such a pose makes the answer
        underdetermined whatever else passes, so where a valley of poses keeps many cells its best pose is tried,
        and so is a region that passes wider than a patch's widening, unsettled or settled (``WEAK_TRIES`` times
        each at most); the search stops at the first weak one (``weak``, not complete)."""
        kept = []
        try:
            return self._regions(partial, *(Tries(stop, WEAK_TRIES) for _ in range(3)), kept)
        except WeakPose as weak:
            reason = "stopped at a pose that passes but that the touches leave free or determine too weakly to judge" \
                if weak.extent_mm is None else (f"stopped at a region of poses that may pass {weak.extent_mm:.2f} mm "
                                                "wide, wider than a patch's widening")
            return Regions(complete=False, cells=kept, weak=weak.found, reason=reason)

    def _regions(self, partial, level_tries, region_tries, wide_tries, kept):
        """:meth:`regions`' search, its stop tried on valleys' cells and on wide regions' poses, unsettled and
        settled."""
        start = self.first_cells()
        budget = PARTIAL_CELLS if partial else None
        leaves, reason = self.leaves(*start, LEAF_FRACTION, kept, budget, level_tries)
        if leaves is None:
            return Regions(complete=False, reason=reason, cells=kept)
        fraction, nearest, tried = LEAF_FRACTION, None, set()
        for _ in range(RESOLVE_ROUNDS + 1):
            found = self.found(leaves)
            if found and (nearest is None or found[0].cost < nearest.cost):
                nearest = found[0]
            # A region is settled when its pose passes and every pose of it that may pass lies near that one
            # (or its leaves are as fine as they get); else it may hold another pose: its leaves split finer.
            fine = fraction * max(self.root, LEAF_MM / LEAF_FRACTION) <= LEAF_FRACTION * self.root
            # A region whose pose fails by more than its extent can make up holds no pose that passes: the root of
            # the cost moves by at most sqrt(n) times the largest move of a touch.
            found = [r for r in found if np.sqrt(r.cost) - np.sqrt(len(self.rho)) * r.extent_mm <= self.root]
            unsettled = [k for k, region in enumerate(found)
                         if not region.passes or (region.extent_mm > SETTLED_MM + 2.0 * region.valley_mm and not fine
                                                  and not partial)]
            if not unsettled:
                return Regions([r.pose for r in found], [r.extent_mm for r in found], cells=kept,
                               nearest=nearest and nearest.pose)
            # Regions that pass but reach farther than a patch's widening, each pose once, the widest first.
            # Unsettled, one may be a weak pose's valley; settled, as it stays, it makes the answer underdetermined
            # (:func:`.solve.judged_all`: no pose of it can be judged), tried with its extent.
            wide = [k for k, region in enumerate(found) if region.passes and region.extent_mm > EXTENT_WIDENING_MAX_MM
                    and (k in unsettled or not partial) and region.pose[1].tobytes() not in tried]
            for k in sorted(wide, key=lambda k: -found[k].extent_mm):
                tries = region_tries if k in unsettled else wide_tries
                if tries.left > 0:
                    tried.add(found[k].pose[1].tobytes())
                    tries(*found[k].pose, None if k in unsettled else found[k].extent_mm)
            fraction /= 4.0
            members = np.concatenate([found[k].members for k in unsettled])
            settled = leaves.take(~np.isin(np.arange(len(leaves.v)), members))
            finer, reason = self.leaves(leaves.v[members], leaves.w[members], leaves.ylo[members],
                                        leaves.yhi[members], fraction, kept, budget, level_tries)
            if finer is None:
                break
            leaves = Cells.joined([settled, finer])
            if len(leaves.v) > MAX_LEAVES:  # each level's cap, over the rounds' leaves together
                reason = CONTINUUM
                break
        else:
            reason = "a region may hold a pose that passes far from the one found in it"
        return Regions([r.pose for r in found], [r.extent_mm for r in found], complete=False, reason=reason,
                       cells=kept, nearest=nearest and nearest.pose)

    def found(self, leaves):
        """The regions of joined leaves (:class:`Region`), best first."""
        if not len(leaves.v):
            return []
        start_R, start_y, centre, reach = self.leaf_poses(leaves)
        labels = _joined(leaves.v, leaves.w, leaves.ylo, leaves.yhi)
        a = np.einsum("kji,nj->kni", start_R, self.points - self.centroid)
        cost = np.sum(self.distances(a, start_y)[0] ** 2, axis=1)
        groups = []
        for label in np.unique(labels):
            members = np.flatnonzero(labels == label)
            groups.append((members[np.argsort(cost[members])[:REGION_STARTS]], members))
        picks = np.concatenate([best for best, _ in groups])
        Rs, ts = self.refined(start_R[picks], self.centroid - np.einsum("kij,kj->ki", start_R[picks], start_y[picks]))
        relaxed = self.relaxed_cost(Rs, ts)
        # The bounded sensors' cost (their rows after the touches'), weighted as their bounds are.
        sensed = 0.0
        if self.sensors_apart and self.printed is not None:  # a printed part: the bound at the pose, deviations less
            sensed = self.sensors.cells(Rs, np.zeros(len(Rs)), np.einsum("kji,kj->ki", Rs, self.centroid - ts),
                                        np.zeros(len(Rs)), self.root)[0]
        elif self.sensors_apart:
            sensed = self.sensors.weight * np.sum(self.full.evaluate_batch(Rs, ts)[0][:, self.problem.size:] ** 2,
                                                  axis=1)
        sensed = np.broadcast_to(sensed, relaxed.shape)
        out, first = [], 0
        for best, members in groups:
            k = first + int(np.argmin(relaxed[first:first + len(best)]))
            first += len(best)
            R, t, cost = Rs[k], ts[k], float(relaxed[k])
            valley = 0.0
            if self.judge is not None:
                r, J = self.judge.evaluate(R, t)
                if self.L is not None and r @ r > self.root**2:  # refined on the test itself, deviations included
                    R, t, r, J = levenberg_marquardt(self.judge, R, t, max_iterations=REFINE_STEPS)
                cost = float(r @ r)
                valley = _valley_mm(J, self.root**2 - cost, self.markers)
            cost += float(sensed[k])
            # How far any pose of the region that may pass puts a touch (or a sensor) from where the refined pose does.
            x_ref = (self.markers - t) @ R
            extent = float(np.max(np.linalg.norm(centre[members] - x_ref[None], axis=2) + reach[members]))
            out.append(Region((R, t), cost <= self.root**2, extent, members, float(relaxed[k]), valley))
        out.sort(key=lambda region: region.cost)
        return out

    def ellipsoid(self, c):
        """The first-order model's 6-D ellipsoid of (omega, y) that may pass, ``Q(theta) <= (sqrt(T) +
        remainder + deviations)^2``: its inverse matrix W (K, 6, 6), centre theta* (K, 6), the room left
        above the model's least value (K,, mm^2), and whether the model holds every motion (K,)."""
        G, g = c.gram[:, 1:, 1:], c.gram[:, 1:, 0]
        eig = np.linalg.eigvalsh(G)
        held = eig[:, 0] > 1e-9 * np.maximum(eig[:, -1], 1e-300)
        inverse = np.where(c.alpha > 1e-12 * np.maximum(c.alpha[:, -1:], 1e-300), 1.0 / np.maximum(c.alpha, 1e-300), 0.0)
        # W = G^-1 by blocks (where the model holds every motion, the y block's pseudo-inverse H is its inverse, and
        # A, the y-reduced form, the omega block's Schur complement): W_ww = A^-1, W_wy = -A^-1 G_wy H, W_yy = H -
        # H G_yw W_wy; the identity on the other cells.
        Ww = (c.V * inverse[:, None]) @ c.V.transpose(0, 2, 1)
        Wwy = -Ww @ G[:, :3, 3:] @ c.H_pinv
        Wyy = c.H_pinv - c.H_pinv @ G[:, 3:, :3] @ Wwy
        W = np.where(held[:, None, None], np.concatenate([np.concatenate([Ww, Wwy], axis=2),
                                                          np.concatenate([Wwy.transpose(0, 2, 1), Wyy], axis=2)],
                                                         axis=1), np.eye(6))
        theta = -np.einsum("kij,kj->ki", W, g)
        beta = np.einsum("kij,ki->kj", c.V, c.b)
        q_min = c.Q0 - np.sum(inverse * beta**2, axis=1)
        slack = np.maximum((self.root + c.remainder) ** 2 - q_min, 0.0)
        return W, theta, slack, held

    def leaf_poses(self, c):
        """Each leaf's start (R, y), and where its poses that may pass put the touches: within ``reach`` (K, n)
        mm of ``centre`` (K, n, 3). From the first-order model's 6-D ellipsoid ``Q(theta) <= (sqrt(T) +
        remainder + deviations)^2`` about its least ``theta*`` (its image under touch i's map ``[a_i x, I]``,
        plus twice the turn's remainder), or, where the model leaves a motion free, from the cell itself."""
        W, theta, slack, held = c.W, c.theta, c.slack, c.held  # (:meth:`first_bound`'s)
        # The start: theta* with its turn brought into the cell.
        norm = np.linalg.norm(theta[:, :3], axis=1)
        omega = np.where(held[:, None], theta[:, :3] * np.minimum(1.0, c.delta / np.maximum(norm, 1e-300))[:, None], 0.0)
        start_R = c.R @ rotation_from_vector(omega)
        box = self.box_centre(c.ylo, c.yhi)
        start_y = np.where(held[:, None], theta[:, 3:6], box)
        a = c.a if self.sensors is None else turned_points(self.markers - self.centroid, c.R)
        kappa = (c.delta**2 / 2.0 + c.delta**3 / 6.0)[:, None] * self.marker_rho[None]
        # Touch i at a_i + a_i x omega + y + e_i, |e_i| <= kappa_i: over the ellipsoid, within
        # sqrt(slack lambda_max(B_i W B_i^T)) + kappa_i of its image at theta*, B_i = [a_i x, I].
        B = np.concatenate([skew(a), np.broadcast_to(np.eye(3), a.shape + (3,))], axis=3)  # (K, n, 3, 6)
        spread = np.sqrt(slack[:, None] * np.linalg.eigvalsh(B @ W[:, None, :6, :6] @ B.transpose(0, 1, 3, 2))[..., -1])
        image = a + cross(a, theta[:, None, :3]) + theta[:, None, 3:6]
        # Where the model leaves a motion free: the cell, every turn within delta and every y in its box.
        whole = np.linalg.norm(0.5 * (c.yhi - c.ylo), axis=1)[:, None] + c.delta[:, None] * self.marker_rho[None]
        centre = np.where(held[:, None, None], image, a + box[:, None])
        reach = np.where(held[:, None], spread + kappa, whole)
        return start_R, start_y, centre, reach

    def refined(self, Rs, ts):
        """Poses refined together by Gauss-Newton on the touches' rows and the bounded sensors', or on the test:
        (Rs, ts); it stops after steps that all moved the touches too little for the test to see (the next would move
        them less)."""
        # Where points and balls alone are touched, on the test itself (on a printed part, deviations and all): the
        # final refinement (:func:`.solve.solve`) starts where this ends, and ends within a step. (A sensor's rows
        # there take a central difference for their radius: dearer than the steps saved.)
        problem = self.full if self.sensors is not None or self.judge is None else self.judge
        length = problem.scale()
        for _ in range(REFINE_STEPS):
            r, J = problem.evaluate_batch(Rs, ts)
            A = J.transpose(0, 2, 1) @ J
            A = A + 1e-9 * (np.trace(A, axis1=1, axis2=2)[:, None, None] + 1e-12) * np.eye(6)
            step = -np.linalg.solve(A, J.transpose(0, 2, 1) @ r[..., None])[..., 0]
            # The fixture-frame twist: x -> R (exp(omega) x + v) + t.
            ts = ts + (Rs @ step[:, 3:, None])[..., 0]
            Rs = Rs @ rotation_from_vector(step[:, :3])
            if np.all(step_moves(step, length) < STEP_TOLERANCE * self.problem.sigma):
                break
        return Rs, ts


def _largest_turn(tolerance, fid, q):
    """The largest turn (rad) of a printed feature that a pose that passes allows: ``sqrt(q lambda_max)`` of its
    turn's covariance."""
    s = tolerance.covariance[tolerance.slices[fid], tolerance.slices[fid]]
    return float(np.sqrt(q) * largest_move(tolerance.modes[fid].twists[:, :3], s))


def contact_offset(group):
    """How far off its element's core each touch of a point or ball group lies at contact (n,), mm: a ball's
    centre by both radii (the group's ``rho``), a point probe by the feature's radius."""
    ball = np.ravel(group.sensor.geometry.get("r", 0.0)) if group.ctype.sensor == "S" else 0.0
    radius = group.feature.core()[3]
    return np.where(group.rho > 0, group.rho, radius + np.broadcast_to(ball, group.rho.shape))


def patch_growth(root, dev, offset):
    """How far (mm) a touch that passes may lie off its patch's box: the patch's tolerance and widening, the root
    of the threshold, its deviation bound, its distance off the surface (a ball's radius)."""
    return EXTENT_TOLERANCE_MM + EXTENT_WIDENING_MAX_MM + root + dev + offset


def by_value(function):
    """``function`` of a few small arrays, memoised on their values: the labelled search under each assignment
    (:mod:`.unlabelled`) builds the same spans, inverses and swings up to hundreds of times a call. What it
    returns is shared: read only."""
    kept = {}

    @functools.wraps(function)
    def memoised(*arrays):
        key = tuple((a.shape, a.dtype.str, a.tobytes()) for a in map(np.asarray, arrays))
        if key not in kept:
            if len(kept) >= MEMO_KEPT:
                kept.clear()
            kept[key] = function(*arrays)
        return kept[key]

    return memoised


def _read_only(array):
    array.setflags(write=False)
    return array


@functools.lru_cache(maxsize=64)
def pair_indices(n):
    """Every pair ``i < j`` of n things, ``np.triu_indices(n, 1)``, built once a size (numpy builds an n by n mask
    each call; the last 64 sizes kept). Read only."""
    return tuple(_read_only(index) for index in np.triu_indices(n, 1))


@by_value
def row_span(plane, direction):
    """Unit vectors (k, 3) spanning a flat touch's rows: a plane's normal, the two directions across a line,
    three across a point (its ``direction`` 0)."""
    M = np.outer(direction, direction) if plane else np.eye(3) - np.outer(direction, direction)
    return _read_only(np.array([m for m in np.linalg.eigh(M)[1].T if m @ M @ m > 0.5]).reshape(-1, 3))


@by_value
def least_and_pinv(H):
    """The least eigenvalue (0 at least) and the pseudo-inverse of a symmetric matrix."""
    return float(max(np.linalg.eigvalsh(H)[0], 0.0)), _read_only(np.linalg.pinv(H, rcond=1e-9))


@by_value
def across_rows(M):
    """The projector off the column space of rows ``M`` (r, 3): ``I - M (M^T M)^+ M^T``."""
    return _read_only(np.eye(len(M)) - M @ np.linalg.pinv(M.T @ M, rcond=1e-9) @ M.T)


@by_value
def largest_swing(u):
    """A turn by ``delta`` moves the offsets ``u`` (n, 3) mm by at most ``delta`` times this (the root of the sum
    of their moves' squares): the root of their inertia tensor's largest eigenvalue."""
    inertia = np.sum(u**2) * np.eye(3) - u.T @ u
    return float(np.sqrt(max(np.linalg.eigvalsh(inertia)[-1], 0.0)))


def shell_box(points, radius, width):
    """Boxes (lo, hi) holding every centre within ``radius +- width`` of each of the points (n, 3), for each row
    of radius and width (n,) or (m, n): the shells' boxes, narrowed by the radical slabs of every pair (|p_i -
    C|^2 - |p_j - C|^2 is linear in C): the box of the slabs' least-squares solve, then interval propagation (two
    rounds: more narrow it by little). Each (3,), or (m, 3) for m rows."""
    rows = np.ndim(radius) == 2 or np.ndim(width) == 2
    radius, width = np.atleast_2d(radius), np.atleast_2d(width)
    origin = points.mean(axis=0)
    p = points - origin
    near, far = np.maximum(radius - width, 0.0) ** 2, (radius + width) ** 2
    lo, hi = np.max(p - (radius + width)[..., None], axis=1), np.min(p + (radius + width)[..., None], axis=1)
    i, j = pair_indices(len(p))
    g = 2.0 * (p[i] - p[j])
    constant = np.sum(p[i] ** 2, axis=1) - np.sum(p[j] ** 2, axis=1)
    low, high = constant - (far[:, i] - near[:, j]), constant - (near[:, i] - far[:, j])  # g.C lies between
    u, s, vt = np.linalg.svd(g, full_matrices=False)
    if np.count_nonzero(s > s.max(initial=0.0) * max(g.shape) * np.finfo(float).eps) == 3:  # numpy's matrix_rank
        # Any A with A g = I gives C = A (g C): the least-squares one's box (g's pseudo-inverse).
        lo, hi = boxed(vt.T @ ((1.0 / s)[:, None] * u.T), low, high, lo, hi)
    lo, hi = propagated([(g, low, high)], lo, hi, 2)
    return (lo + origin, hi + origin) if rows else (lo[0] + origin, hi[0] + origin)


def slab_triples(normals, most=SLAB_TRIPLES):
    """Of slabs with these unit normals (s, 3), at most ``most`` sets of three that bound a box by themselves, the
    best conditioned first: (indices (3,), the inverse (3, 3) of their normals' matrix), each with ``|det| >=
    SLAB_DETERMINANT``."""
    sets = list(itertools.combinations(range(len(normals)), 3))
    det = np.array([abs(np.linalg.det(normals[list(k)])) for k in sets])
    order = [k for k in np.argsort(-det, kind="stable")[:most] if det[k] >= SLAB_DETERMINANT] if sets else []
    return [(np.array(sets[k]), np.linalg.inv(normals[list(sets[k])])) for k in order]


def boxed(inverse, low, high, lo, hi):
    """Boxes (K, 3) narrowed to the box that slabs ``low <= N y <= high`` (low, high (K, s)) hold, ``inverse`` any
    A (3, s) with ``A N = I`` (three slabs' N^-1, or more slabs' pseudo-inverse): y = A z, z in the box of the
    slabs' bounds."""
    centre = 0.5 * (low + high) @ inverse.T
    half = 0.5 * (high - low) @ np.abs(inverse).T
    return np.maximum(lo, centre - half), np.minimum(hi, centre + half)


def propagated(slabs, lo, hi, rounds):
    """Boxes (K, 3) narrowed to slabs ``low <= g.y <= high``: ``slabs`` a list of (g, low, high), g (S, 3) the
    same for every box or (K, S, 3) each its own, low and high (K, S); each slab narrows each axis to what the
    box's other axes leave it, ``rounds`` times over all slabs at once (g within 1e-12 of 0 taken as 0). A shared
    g is neither copied per box nor split by sign per box."""
    slabs = [(_held_axes(g), low, high) for g, low, high in slabs]
    for _ in range(rounds):
        y_lo, y_hi = np.maximum(lo, -BIG_MM), np.minimum(hi, BIG_MM)
        narrowed = [_narrowed(g, low, high, y_lo, y_hi) for g, low, high in slabs]
        lo = np.maximum(lo, across(np.maximum, np.stack([a for a, _ in narrowed], axis=1)))
        hi = np.minimum(hi, across(np.minimum, np.stack([b for _, b in narrowed], axis=1)))
    return lo, hi


def _held_axes(g):
    """Slab directions g with parts within 1e-12 of 0 taken as 0: axes the slabs do not hold."""
    return np.where(np.abs(g) <= 1e-12, 0.0, g)


def _spanned(g, y_lo, y_hi):
    """The range ``[bottom, top]`` (K, S) of each slab's g.y over each box (g as in :func:`propagated`), and g's
    positive and negative parts."""
    gp, gn = np.maximum(g, 0.0), np.minimum(g, 0.0)
    if g.ndim == 2:
        return y_lo @ gp.T + y_hi @ gn.T, y_hi @ gp.T + y_lo @ gn.T, gp, gn
    return (np.einsum("ki,ksi->ks", y_lo, gp) + np.einsum("ki,ksi->ks", y_hi, gn),
            np.einsum("ki,ksi->ks", y_hi, gp) + np.einsum("ki,ksi->ks", y_lo, gn), gp, gn)


def missed(slabs, lo, hi):
    """Whether some slab of ``slabs`` (as in :func:`propagated`) misses each box (K,): it holds no y."""
    y_lo, y_hi = np.maximum(lo, -BIG_MM), np.minimum(hi, BIG_MM)
    out = np.zeros(len(lo), bool)
    for g, low, high in slabs:
        bottom, top = _spanned(_held_axes(g), y_lo, y_hi)[:2]
        out |= np.any((top < low) | (bottom > high), axis=1)
    return out


def _narrowed(g, low, high, y_lo, y_hi):
    """One round of :func:`propagated` over one list's slabs: each axis's interval (lo, hi) (K, 3) that they leave
    it. g.y's range over the box is ``[bottom, top]``; axis k's own part of it taken out, ``g_k y_k`` lies in
    ``[low - (top - own), high - (bottom - own)]``, divided by g_k (its ends swapped where g_k < 0; an axis a slab
    does not hold is left as it is)."""
    bottom, top, gp, gn = _spanned(g, y_lo, y_hi)  # (K, S)
    # Every axis at once (K, S, 3).
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (low[..., None] - top[..., None] + gp * y_hi[:, None] + gn * y_lo[:, None]) / g
        b = (high[..., None] - bottom[..., None] + gp * y_lo[:, None] + gn * y_hi[:, None]) / g
    lo = np.max(np.where(g > 0.0, a, np.where(g < 0.0, b, -np.inf)), axis=1, initial=-np.inf)
    hi = np.min(np.where(g > 0.0, b, np.where(g < 0.0, a, np.inf)), axis=1, initial=np.inf)
    return lo, hi


def turned_points(points, R):
    """``points @ R`` (K, n, 3): points (n, 3) by rotations (K, 3, 3), as one product (numpy's stack of small
    products is several times slower)."""
    return np.tensordot(points, R, axes=([1], [1])).transpose(1, 0, 2)


def on_axes(x, Q):
    """``x @ Q``: x (..., 3) by one matrix Q (3, 3), as one product (none for the fixture's own axes)."""
    return x if Q is AXES else (x.reshape(-1, 3) @ Q).reshape(x.shape)


def across(op, x):
    """``op`` (np.maximum or np.minimum) reduced over axis 1 of x (K, n, ...), a touch at a time (numpy reduces
    across a middle axis slowly)."""
    out = x[:, 0].copy()
    for k in range(1, x.shape[1]):
        op(out, x[:, k], out=out)
    return out


def box_middle(lo, hi):
    """The middles of boxes ``lo``-``hi`` (..., 3) mm, 0 along an unbounded axis."""
    middle = 0.5 * (lo + hi)
    return np.where(np.isfinite(middle), middle, 0.0)


def least_over_box(rel, half, direction, point, aligned, radius):
    """The least distance (...) of a sphere or cylinder surface (a point or line core grown by ``radius``) from
    boxes of places ``rel +- half`` (offsets from the core's anchor, ``(..., 3)``): exact on a point core and on
    a line core along the boxes' last axis (``aligned``), within the box's half-diagonal on another line core."""
    # A point core (or an aligned line core, across it): the nearest and farthest points of the box.
    across = np.where(np.asarray(aligned)[:, None], [1.0, 1.0, 0.0], 1.0)
    near = np.linalg.norm(across * np.maximum(np.abs(rel) - half, 0.0), axis=-1)
    far = np.linalg.norm(across * (np.abs(rel) + half), axis=-1)
    exact = point | aligned
    if not np.all(exact):
        # Another line core: the distance at the box's centre, give or take its half-diagonal.
        perp = np.linalg.norm(rel - np.einsum("...i,...i->...", rel, direction)[..., None] * direction, axis=-1)
        diagonal = np.linalg.norm(half, axis=-1)
        near = np.where(exact, near, np.maximum(perp - diagonal, 0.0))
        far = np.where(exact, far, perp + diagonal)
    return np.maximum(np.maximum(near - radius, radius - far), 0.0)


def deviation_bound(tolerance, feature, q):
    """A touch's deviation bound ``e = sqrt(q D)`` (mm) on a printed feature, ``D`` the largest variance of the
    feature's deviation across its rows over its patch (:meth:`.deviations.FixtureTolerance.largest_variance`)."""
    return np.sqrt(q * tolerance.largest_variance(feature))


@dataclass
class Region:
    """Joined leaves: the pose refined from the best of them, whether it passes (each distance less its deviation
    bound), how far any pose of the region that may pass puts a touch from where it does (mm), the leaves'
    indices and the pose's cost (mm^2)."""

    pose: tuple
    passes: bool
    extent_mm: float
    members: np.ndarray
    cost: float
    valley_mm: float = 0.0  # how far the poses that pass about the pose reach, to first order (:func:`_valley_mm`)


def _valley_mm(J, room, markers):
    """How far (mm) the twists ``theta`` with ``|J theta|^2 <= room`` (mm^2; the test's rows J (m, 6) at a pose
    that passes, to first order: the poses that pass about it) move the points ``markers`` (n, 3), measurement
    frame, a twist moving p by ``omega x p + v``; 0 where J leaves a motion free."""
    F = J.T @ J
    if room <= 0.0 or np.linalg.cond(F) >= 1e14:
        return 0.0
    spread = np.linalg.eigvalsh(point_covariances(markers, np.linalg.inv(F)))[:, -1]
    return float(np.sqrt(room * max(spread.max(), 0.0)))


class Cells:
    """A batch of cells: rotation-vector box centres ``v`` (K, 3), half-widths ``w`` (K,), y boxes, and what
    :meth:`Tree.cells` fills in."""

    def __init__(self, v, w, ylo, yhi):
        self.v, self.w, self.ylo, self.yhi = v, w, ylo, yhi

    def take(self, keep):
        """The cells ``keep`` (a mask or indices) picks."""
        index = np.flatnonzero(keep) if keep.dtype == bool else keep  # indices take faster than a mask masks
        out = Cells.__new__(Cells)
        for name, value in vars(self).items():
            setattr(out, name, value.take(index, axis=0))
        return out

    @staticmethod
    def joined(parts):
        out = Cells.__new__(Cells)
        for name in vars(parts[0]):
            setattr(out, name, np.concatenate([getattr(p, name) for p in parts]))
        return out


def split(v, w, ylo, yhi, turning, relevant):
    """Rotation boxes of ``turning`` cells in eight, the others' y boxes in two across their widest ``relevant``
    axis."""
    half = 0.5 * w[turning]
    vs = (v[turning][:, None] + half[:, None, None] * CORNERS[None]).reshape(-1, 3)
    parts = [(vs, np.repeat(half, 8), np.repeat(ylo[turning], 8, axis=0), np.repeat(yhi[turning], 8, axis=0))]
    lo, hi = ylo[~turning], yhi[~turning]
    rows = np.arange(len(lo))
    axis = np.argmax(np.where(relevant, hi - lo, -1.0), axis=1)
    middle = 0.5 * (lo + hi)[rows, axis]
    lo2, hi1 = lo.copy(), hi.copy()
    hi1[rows, axis] = middle
    lo2[rows, axis] = middle
    parts.append((np.repeat(v[~turning], 2, axis=0), np.repeat(w[~turning], 2),
                  np.stack([lo, lo2], 1).reshape(-1, 3), np.stack([hi1, hi], 1).reshape(-1, 3)))
    return [np.concatenate(p) for p in zip(*parts)]


def _modes_least(Jz, sigma, v):
    """The modes u (K, k, c) at the least over u of ``|v - Jz u|^2 + sigma^2 |u|^2``, for each of v's columns (K, r,
    c) (Jz (K, r, k)): ``u = C^-1 Jz^T v``, ``C = sigma^2 I + Jz^T Jz``. The smaller of two equal systems (C positive
    definite, its least eigenvalue sigma^2): k by k, a part's few modes under many rows, or r by r, ``C^-1 Jz^T =
    Jz^T (sigma^2 I + Jz Jz^T)^-1`` (push-through), a few sensors' rows on many features' modes."""
    r, k = Jz.shape[1:]
    Jt = Jz.transpose(0, 2, 1)
    if r < k:
        return Jt @ np.linalg.solve(sigma**2 * np.eye(r) + Jz @ Jt, v)
    return np.linalg.solve(Jt @ Jz + sigma**2 * np.eye(k), Jt @ v)


def _modes_eliminated(Jz, sigma, columns):
    """What eliminating the modes u takes off the Gram matrix of the rows' ``columns`` (K, r, c): ``B^T C^-1 B``
    (K, c, c), ``B = Jz^T columns`` (:func:`_modes_least`), so that a combination v of the columns costs ``|v|^2 -
    v^T Jz C^-1 Jz^T v = min over u of |v - Jz u|^2 + sigma^2 |u|^2``; and ``U = C^-1 B`` (K, k, c) and ``Jz U``
    (K, r, c): the least u of ``v = columns x`` is ``U x`` (:func:`_modes_left`)."""
    U = _modes_least(Jz, sigma, columns)
    JzU = Jz @ U
    return columns.transpose(0, 2, 1) @ JzU, U, JzU


def _bend(move, s0):
    """The most (mm) that a distance ``|s|`` from a core lies above its tangent at ``s_0`` over a move of ``move``
    (mm) across the core, ``|s_0|`` = ``s0``: ``move^2 / (2 |s_0|)`` up to ``2 |s_0|``, reached where ``u.D =
    -|D|^2 / (2 |s_0|)`` (there ``|s_0 + D| = |s_0|``), then ``2 (move - |s_0|)`` (D against ``s_0``)."""
    return np.where(move <= 2.0 * s0, move**2 / (2.0 * s0), 2.0 * (move - s0))


def _modes_left(U, JzU, sigma, v, x):
    """Rows ``v = columns x`` (K, r) less the modes' part at the least over u of ``|v - Jz u|^2 + sigma^2 |u|^2``,
    and that least's ``sigma^2 |u|^2`` (K,): u is ``U x`` (``U``, ``JzU``: :func:`_modes_eliminated`'s; the least
    is linear in v, so no system is solved again)."""
    u = np.einsum("kjc,kc->kj", U, x)
    return v - np.einsum("krc,kc->kr", JzU, x), sigma**2 * np.sum(u**2, axis=1)


def dual_bound(columns, rows, modes, delta, middle, half, Q, row_off, kappa, kappa_size):
    """A lower bound (K,) of the cost over cells (turns ``|omega| <= delta`` (K,), y boxes of ``middle`` and
    ``half`` (K, 3) on the axes Q) whose rows lie within ``row_off`` (K, n) each of the model ``columns . (1,
    omega, y)`` (columns (K, n, 7); less ``Jz u`` on a printed part, u costing ``sigma^2 |u|^2``), and the flat
    touches' rows also within a vector of length ``kappa`` (K, f) each: weak duality, multipliers ``2 s r``, r
    the model's ``rows`` (K, n) at some point, ``modes`` its u's ``sigma^2 |u|^2`` (K,), ``kappa_size`` (K, f)
    each flat touch's length of r (docs/registration.md). A row is at least its distance from its error
    interval, whose square is at least ``l x - l^2 / 4 - off |l|`` for any l (a touch's rows: ``l.x - |l|^2 /
    4 - kappa |l|``), and ``-Jz^T l . u + sigma^2 |u|^2 >= -|Jz^T l|^2 / (4 sigma^2)``; over the cell that is
    ``2 s G1 - s^2 G2``, ``G1 = r.value - delta |Jw^T r| + min over the box of (m^T r).y - off.|r| - kappa.|r|``,
    ``G2 = |r|^2 + |Jz^T r|^2 / sigma^2`` (the latter ``modes`` where u is least for r), whose most over ``s >=
    0`` is ``G1^2 / G2``."""
    pull = np.einsum("krj,kr->kj", columns, rows)  # (r.value, Jw^T r, m^T r)
    g = pull[:, 4:] @ Q
    with np.errstate(divide="ignore", invalid="ignore"):
        y_least = np.sum(g * middle - np.where(g == 0.0, 0.0, np.abs(g) * half), axis=1)
        # (a row at 0 has multiplier 0: nothing, however large its remainder)
        spread = np.sum(np.where(rows == 0.0, 0.0, row_off * np.abs(rows)), axis=1) + np.sum(kappa * kappa_size, axis=1)
        G1 = pull[:, 0] - delta * np.linalg.norm(pull[:, 1:4], axis=1) + y_least - spread
        G2 = np.sum(rows**2, axis=1) + modes
        return np.where((G1 > 0.0) & (G2 > 0.0), G1**2 / G2, 0.0)


def _reduced(gram, H_pinv):
    """The least cost over y of linear rows ``value + Jw . omega + m . y``: ``Q0 + 2 b.omega + omega^T A omega``,
    as (A (K, 3, 3), b (K, 3), Q0 (K,)), from the rows' Gram matrix (K, 7, 7) of their columns (value, Jw, m).
    ``H_pinv``: the pseudo-inverse of its y block ``sum m m^T`` (the y columns' products lie in its range, so it
    eliminates y exactly)."""
    Gww, Gwy, gw, gy = gram[:, 1:4, 1:4], gram[:, 1:4, 4:], gram[:, 1:4, 0], gram[:, 4:, 0]
    GH = Gwy @ H_pinv
    A = Gww - GH @ Gwy.transpose(0, 2, 1)
    b = gw - np.einsum("kij,kj->ki", GH, gy)
    Q0 = gram[:, 0, 0] - np.sum(gy * (H_pinv @ gy[..., None])[..., 0], axis=1)
    return A, b, Q0


def _joined(v, w, ylo, yhi):
    """Labels (K,) of the connected groups of leaves whose rotation boxes and y boxes touch or overlap."""
    K = len(v)
    # Candidates: leaves whose intervals on one axis of the six overlap, found in the order of their lower ends
    # (a block of pairs at a time), on the axis that leaves fewest.
    low = np.concatenate([v - w[:, None], ylo], axis=1)
    high = np.concatenate([v + w[:, None], yhi], axis=1)
    best = None
    for axis in range(6):
        order = np.argsort(low[:, axis], kind="stable")
        count = np.searchsorted(low[order, axis], high[order, axis] + 1e-9, side="right") - np.arange(K)
        if best is None or count.sum() < best[1].sum():
            best = order, count
    order, count = best
    v, w, ylo, yhi = v[order], w[order], ylo[order], yhi[order]
    ends = np.cumsum(count)
    pairs = []
    for lo in range(0, K, 256):
        rows = np.arange(lo, min(lo + 256, K))
        i = np.repeat(rows, count[rows])
        j = i + np.arange(len(i)) - np.repeat(ends[rows] - count[rows] - (ends[lo] - count[lo]), count[rows])
        near = np.all(np.abs(v[i] - v[j]) <= (w[i] + w[j])[:, None] + 1e-9, axis=1)
        near &= np.all((ylo[i] <= yhi[j] + 1e-9) & (ylo[j] <= yhi[i] + 1e-9), axis=1)
        pairs.append((i[near], j[near]))
    i = np.concatenate([p[0] for p in pairs])
    j = np.concatenate([p[1] for p in pairs])
    labels = np.arange(K)
    while True:
        lower = labels.copy()
        np.minimum.at(lower, i, labels[j])
        np.minimum.at(lower, j, labels[i])
        lower = lower[lower]  # jump to the label's own label
        if np.array_equal(lower, labels):
            break
        labels = lower
    out = np.empty(K, int)
    out[order] = labels
    return out


def mahalanobis(R, t, information, Rs, ts):
    """Squared Mahalanobis distances (K,) of poses (Rs, ts) from (R, t) under its information (6, 6) over the
    spatial twist (rotation vector, translation) that takes (R, t) to each; poses more than a radian away are
    infinitely far."""
    E = Rs @ R.T  # R_k = exp(omega) R
    omega = vector_from_rotation(E)
    twist = np.hstack([omega, ts - E @ t])  # t_k = exp(omega) t + v
    d = np.einsum("ki,ij,kj->k", twist, information, twist)
    return np.where(np.linalg.norm(omega, axis=1) < 1.0, d, np.inf)

