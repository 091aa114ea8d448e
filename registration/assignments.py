"""Which features unlabelled touches may lie on, from the touches' own shape: every assignment under which a
pose may pass, whatever the pose.

A rigid motion keeps the touches' distances. At a pose that passes under an assignment each touch lies within
its reach ``r = sqrt(T) + e`` (``e`` the printed part's deviation bound, :func:`.search.deviation_bound`) of its
feature, its contact offset ``R`` off the feature's core (a ball's radius, a sphere's or a cylinder's), and
within the feature's patch box grown as the labelled search grows it (:func:`.search.patch_growth`). So:

* two touches on features f and g lie as far apart as two points of their grown boxes can: between the boxes'
  least and greatest distances; two on one sphere at most its diameter ``2 (R + r)``;
* four touches on one plane lie in a slab ``2 r`` wide: their tetrahedron's least width (its faces' heights
  and its opposite edges' distances, where a polytope's least width lies) is at most ``2 r``;
* four on one sphere or point, centre c: ``|p_k - c|^2 - |p_0 - c|^2 = |d_k|^2 - 2 d_k.(c - p_0)`` (``d_k =
  p_k - p_0``) lies within ``+-((R + r)^2 - max(R - r, 0)^2)``, three slabs whose parallelepiped holds c, and
  ``|p_0 - c|`` lies within ``R +- r`` for a c in it;
* four on one cylinder or line: two touches farther apart than ``2 (R + r)`` keep its axis within
  ``arcsin(2 (R + r) / |d|)`` of their difference's line (the part of d across the axis is at most ``2 (R +
  r)``), and any two such cones of the quad's six pairs meet;
* five or more on one cylinder or line fit one axis (:func:`fit_an_axis`), tested on the tree's leaves; where
  three or more lie on a plane beside them, the axis keeps its angle to the plane's normal, which those touches
  bound (:func:`.search.normal_cones`).

An interpretation tree (Grimson and Lozano-Perez 1987) takes the touches in turn, the labelled ones first:
each assignment of the touches so far that passes every test among them is extended by each feature the next
touch may take. Every test is a necessary condition, so the tree's leaves hold every assignment under which a
pose passes; the labelled search (:mod:`.search`) decides each, with its own guarantee.

This module imports numpy only and nothing of fixturecad: it is inlined into the generated standalone
``register.py``.
"""

import itertools

import numpy as np

from .elements import perpendicular_basis
from .patches import patch_box
from .search import contact_offset, deviation_bound, normal_cones, pair_cones, pair_indices, patch_growth

MAX_ROWS = 20_000  # assignments of the touches so far kept at most: past that the poses tell them (:mod:`.face_search`)
AXIS_TOUCHES = 5  # a cylinder's or line's touches, this many or more, searched for an axis they fit
AXIS_CELLS = 4  # the axis search's first cells: this many a side on each of three cube faces ...
AXIS_LEVELS = 8  # ... split this many times at most (a cell then 0.0014 rad across) ...
AXIS_KEPT = 2000  # ... while a set keeps at most this many cells (it is taken to fit past either)
AXIS_PAIRS = 36  # the narrowest cones about the set's pairs' lines that bound the axis search's cells (all of nine touches')
CHUNK = 4096  # rows tested at once against the quads, cells of the axis search at once
SLACK = 1e-9  # relative: rounding kept on the tests' side


def admitted(groups, surfaces, points, ball_radius_mm, tolerance, q, root, group=()):
    """Every assignment of the unlabelled ``points`` (n, 3), mm, to the ``surfaces`` that the touches' shape
    admits beside the labelled point and ball touches of ``groups``, as tuples of feature ids; the reason when
    the tree stopped (else ""); the assignments kept per touch. ``q``: the test's threshold over sigma^2 (for
    the deviation bounds); ``root``: its square root in mm. ``group``: the surfaces' symmetries, each a map
    {id: image id} (:mod:`.symmetry`): of each orbit of assignments only the least is kept (a pose passes under
    one of an orbit where it passes under all, turned; see :func:`least_of_orbits`)."""
    places, slots = [], []
    for g in groups:
        if g.points is None:
            continue  # a sensor: not among the touches the tree takes
        places.append(g.points)
        for offset in contact_offset(g):
            slots.append([(g.feature, float(offset))])
    places.append(points)
    slots += [[(f, float(f.core()[3] + ball_radius_mm)) for f in surfaces]] * len(points)
    # The distinct (feature, offset) pairs: the tests' elements.
    elements = list(dict.fromkeys((f.id, offset) for options in slots for f, offset in options))
    features = {f.id: f for options in slots for f, _ in options}
    options = [np.array([elements.index((f.id, offset)) for f, offset in o]) for o in slots]
    places = np.concatenate(places)
    tables = Tables([features[fid] for fid, _ in elements], np.array([o for _, o in elements]), places,
                    tolerance, q, root)
    labelled = len(places) - len(points)
    index = {element: k for k, element in enumerate(elements)}
    turns = [np.array([index[(to[fid], offset)] for fid, offset in elements]) for to in group]
    rows, kept = np.zeros((1, 0), int), []
    for choices in options:
        rows = least_of_orbits(tables.extend(rows, choices), turns)
        kept.append(len(rows))
        if len(rows) > MAX_ROWS:
            return [], f"the touches' features were not told within {MAX_ROWS} assignments", kept
    rows = tables.on_axes(tables.at_angles(rows))
    return [tuple(elements[k][0] for k in row[labelled:]) for row in rows], "", kept


def least_of_orbits(rows, turns):
    """The rows (assignments of the first touches, element indices) that no symmetry (``turns``: each an
    element's image index) turns into a row that comes first, lexicographically. A symmetry turns a whole
    assignment that passes into one that passes, and the least of an orbit has the least prefixes of its orbit
    too (a prefix that comes later than an image's would put the whole after that image), so every orbit keeps
    its least assignment through the tree."""
    keep = np.ones(len(rows), bool)
    at = np.arange(len(rows))
    for turn in turns:
        image = turn[rows]
        first = np.argmax(image != rows, axis=1)  # where they first differ (0 where they do not)
        keep &= ~(image[at, first] < rows[at, first])
    return rows[keep]


def grown_boxes(features, offsets, tolerance, q, root):
    """Each feature's deviation bound (S,), mm (0 on an exact part), and its patch box grown as far as a touch
    that passes may lie off it (:func:`.search.patch_growth`): low and high (S, 3)."""
    dev = np.array([0.0 if tolerance is None else float(deviation_bound(tolerance, f, q)) for f in features])
    grow = patch_growth(root, dev, offsets)
    boxes = np.array([patch_box(f) for f in features])
    return dev, boxes[:, 0] - grow[:, None], boxes[:, 1] + grow[:, None]


class Tables:
    """The tests of the module doc, computed once for every pair and quad of touches on each element."""

    def __init__(self, features, offsets, places, tolerance, q, root):
        self.places = places
        n, S = len(places), len(features)
        self.core = [f.core()[0] for f in features]
        self.direction = [f.core()[2] for f in features]
        dev, low, high = grown_boxes(features, offsets, tolerance, q, root)
        self.reach, self.offsets = root + dev, offsets
        least, most = box_distances(low, high)
        sphere = np.array([c == "point" for c in self.core]) & (offsets > 0.0)
        most[np.diag_indices(S)] = np.where(sphere, np.minimum(np.diag(most), 2.0 * (offsets + self.reach)),
                                            np.diag(most))
        distance = np.linalg.norm(places[:, None] - places[None], axis=2)
        # pair[i, j, s, t]: touch i on element s and touch j on t may lie this far apart.
        self.pair = ((distance[:, :, None, None] >= least * (1.0 - SLACK) - SLACK)
                     & (distance[:, :, None, None] <= most * (1.0 + SLACK) + SLACK))
        # bad[s][i, j, k, l]: four touches that cannot lie on element s together (None: no test on it).
        quads = np.array(list(itertools.combinations(range(n), 4))).reshape(-1, 4)
        self.bad = []
        for s in range(S):
            test = QUAD_TESTS.get(self.core[s])
            if test is None or not len(quads):
                self.bad.append(None)
                continue
            table = np.zeros((n, n, n, n), np.float32)
            fails = ~test(places[quads], offsets[s], self.reach[s])
            for order in itertools.permutations(range(4)):
                table[tuple(quads[:, order].T)] = fails
            self.bad.append(table)

    def extend(self, rows, choices):
        """The rows (assignments of the first d touches, element indices) extended by each of the next touch's
        ``choices`` that passes the tests with the touches before it."""
        d = rows.shape[1]
        new = np.repeat(rows, len(choices), axis=0)
        k = np.tile(choices, len(rows))
        ok = np.all(self.pair[d, np.arange(d), k[:, None], new], axis=1)
        for s in np.unique(k):
            if self.bad[s] is None or d < 3:
                continue
            bad = self.bad[s][d, :d, :d, :d].reshape(d * d, d)
            for start in range(0, len(new), CHUNK):
                part = slice(start, start + CHUNK)
                mine = (k[part] == s) & ok[part]
                if not mine.any():
                    continue
                group = (new[part][mine] == s).astype(np.float32)  # (m, d): the touches on s before this one
                together = (group[:, :, None] * group[:, None, :]).reshape(len(group), d * d)
                conflicts = np.einsum("mj,mj->m", together @ bad, group)
                idx = np.flatnonzero(mine) + start
                ok[idx[conflicts > 0]] = False
        return np.column_stack([new, k])[ok]

    def at_angles(self, rows):
        """The rows in which each two planes that three or more touches lie on may keep their normals' angle (of
        lines): the normals the touches bound (:func:`.search.normal_cones`) lie that angle apart, give or take
        their cones' widths."""
        planes = np.flatnonzero(np.array(self.core) == "plane")
        if len(planes) < 2 or not len(rows):
            return rows
        normal, width = self.normals(planes, np.concatenate([rows == e for e in planes], axis=1))
        keep = np.ones(len(rows), bool)
        for a, b in itertools.combinations(range(len(planes)), 2):
            fixed = line_angle(self.direction[planes[a]], self.direction[planes[b]])
            measured = line_angle(normal[:, a], normal[:, b])
            keep &= np.abs(measured - fixed) <= width[:, a] + width[:, b] + SLACK
        return rows[keep]

    def normals(self, planes, on):
        """For each set of touches ``on`` (G, P n) on the ``planes`` (P element indices), each plane's normal
        n* and the width phi of the cone about it that holds the plane's normal wherever its touches lie within
        their reach (:func:`.search.normal_cones`; inf where fewer than three touches bound it): (G, P, 3), (G,
        P), rad."""
        G, n = len(on), len(self.places)
        on = on.reshape(G, len(planes), n)
        normal, width = np.zeros((G, len(planes), 3)), np.full((G, len(planes)), np.inf)
        for k, e in enumerate(planes):
            some = np.flatnonzero(on[:, k].sum(axis=1) >= 3)
            normal[some, k], phi = normal_cones(np.broadcast_to(self.places, (len(some), n, 3)),
                                                np.full((len(some), n), self.reach[e]), on[some, k])
            width[some, k] = np.where(np.isnan(phi), np.inf, phi)
        return normal, width

    def on_axes(self, rows):
        """The rows whose touches on each cylinder or line, ``AXIS_TOUCHES`` or more, may fit one axis at its angle
        to each plane three or more touches lie on (:func:`fit_an_axis`)."""
        keep = np.ones(len(rows), bool)
        n = rows.shape[1]
        planes = np.flatnonzero(np.array(self.core) == "plane")
        for s in np.flatnonzero(np.array(self.core) == "line"):
            on = rows == s
            big = on.sum(axis=1) >= AXIS_TOUCHES
            if not big.any():
                continue
            # A set: the touches on the line, then those on each plane that three or more lie on.
            tied = [on] + [(rows == e) & ((rows == e).sum(axis=1) >= 3)[:, None] for e in planes]
            sets, inverse = np.unique(np.concatenate(tied, axis=1)[big], axis=0, return_inverse=True)
            counts = sets.astype(int)
            holds = counts @ counts.T == counts.sum(axis=1)  # holds[a, b]: set a holds set b
            np.fill_diagonal(holds, False)
            fits, tested = np.ones(len(sets), bool), np.zeros(len(sets), bool)
            # A set holding one that fits no axis fits none: each set searched once those it holds are.
            while True:
                fits &= ~(holds & ~fits).any(axis=1)
                tested |= ~fits
                now = np.flatnonzero(~tested & ~(holds & ~tested).any(axis=1))
                if not len(now):
                    break
                fits[now] = fit_an_axis([self.places[sets[g, :n]] for g in now], self.offsets[s], self.reach[s],
                                        self.bands(s, planes, sets[now, n:]))
                tested[now] = True
            keep[np.flatnonzero(big)[~fits[inverse.ravel()]]] = False
        return rows[keep]

    def bands(self, s, planes, on):
        """The bands the axis of line element s lies in, for each set of touches ``on`` (G, P n) on the
        ``planes`` (P element indices): each plane's normal and its cone's width (:meth:`normals`) and the axis's
        angle to the plane's normal (rad, of lines, fixture frame): (G, P, 3), (G, P), (G, P)."""
        normal, width = self.normals(planes, on)
        angle = line_angle(np.array([self.direction[e] for e in planes]).reshape(-1, 3), self.direction[s])
        return normal, width, np.broadcast_to(angle, width.shape)


def fit_an_axis(sets, radius, reach, bands=None):
    """Whether each set of touches (list of (m, 3)) may lie within ``reach`` of one cylinder of ``radius``
    (mm; 0: a line): False only where a branch and bound over the axis's direction leaves none. ``bands``:
    directions n (G, B, 3) for the G sets, their widths phi (G, B) and angles (G, B), rad: the axis's angle to a
    line within phi of n is that angle (:meth:`Tables.bands`).

    Directions, up to sign, are the points of three faces of the cube about the origin (|x|, |y| or |z| the
    largest, 1); a square cell of half-width h holds directions within ``beta = sqrt(2) h`` of its middle's a0
    (a segment s long at least 1 from the origin subtends at most s). Say the touches fit the axis through c, the
    point nearest their centroid m, along a within theta <= beta of a0: m lies within ``R + r`` of it (the
    distance from a line is convex). A touch ``p - c = s a + u`` (u across a, ``|u| = d``) lies across a0 at
    ``|s P0 a + P0 u|``, with ``|P0 a| = sin(theta)`` and ``d cos(theta) <= |P0 u| <= d``; and ``|s| = |(p -
    m).a| <= |(p - m).a0| + beta |p - m|``. So its distance from the axis along a0 through c lies in ``[lo, hi]
    = R +- (r + beta |s| + R beta^2 / 2)``. Across a0, with m at the origin, c' lies within ``R + r`` of it and ``|q_i - c'|^2 - |q_0 - c'|^2``, linear in c', within ``[lo_i^2 -
    hi_0^2, hi_i^2 - lo_0^2]``: two such slabs (touch 0 the farthest from m, touch 1 the farthest from it,
    touch 2 the farthest off their line) hold c' in a parallelogram, and every touch's distance from a point of
    it must meet its ``[lo, hi]``; and a0 must lie within ``beta`` of each of the set's narrowest cones about
    its pairs' lines (as the quads' test), and its angle to each band's n within ``beta + phi`` of the band's
    (the angle of lines obeys the triangle inequality). A cell that fails is dropped, the others split in four
    (the first cells are tested by the cones and bands alone)."""
    sizes = np.array([len(p) for p in sets])
    flat = np.concatenate(sets)
    mask = np.arange(sizes.max()) < sizes[:, None]
    points = np.zeros(mask.shape + (3,))
    points[mask] = flat - np.repeat(np.add.reduceat(flat, np.cumsum(sizes) - sizes) / sizes[:, None], sizes, axis=0)
    far = np.where(mask, np.linalg.norm(points, axis=2), 0.0)  # |p - m|
    # Each set's narrowest cones about its pairs' lines (the quads' test): the axis lies within each.
    i, j = pair_indices(mask.shape[1])
    cone, lines = pair_cones(np.where((mask[:, i] & mask[:, j])[..., None], points[:, j] - points[:, i], 0.0),
                             _span(radius, reach))
    narrow = np.argsort(cone, axis=1)[:, :AXIS_PAIRS]
    cone = np.take_along_axis(cone, narrow, axis=1)
    lines = np.take_along_axis(lines, narrow[..., None], axis=1)
    normal, width, angle = (np.zeros((len(sets), 0, 3)), np.zeros((len(sets), 0)), np.zeros((len(sets), 0))) \
        if bands is None else bands
    # The first cells, the same directions for every set: one product tests them all by the cones and bands
    # alone (beta 0.35 rad: the parallelograms rule out 0.3 % of them on the inclined plane).
    side = (2 * np.arange(AXIS_CELLS) + 1) / AXIS_CELLS - 1.0
    face, u, v = (x.ravel() for x in np.meshgrid(np.arange(3), side, side, indexing="ij"))
    h = 1.0 / AXIS_CELLS
    beta = np.sqrt(2.0) * h
    first = _directions(face, u, v).T
    keep = np.all(np.abs(lines @ first) >= _least(cone, beta)[..., None], axis=1)
    if width.shape[1]:
        keep &= np.all(np.abs(line_angle(normal[..., None, :], first.T) - angle[..., None])
                       <= (width + beta + SLACK)[..., None], axis=1)
    g, cell = np.nonzero(keep)
    face, u, v = face[cell], u[cell], v[cell]
    fits = np.zeros(len(sets), bool)
    for _ in range(AXIS_LEVELS):
        fits |= np.bincount(g, minlength=len(sets)) > AXIS_KEPT
        g, face, u, v = (x[~fits[g]] for x in (g, face, u, v))
        if not len(g):
            return fits
        h /= 2.0
        beta = np.sqrt(2.0) * h
        du, dv = np.array([-h, h, -h, h]), np.array([-h, -h, h, h])
        g, face = np.repeat(g, 4), np.repeat(face, 4)
        u, v = (np.repeat(u, 4) + np.tile(du, len(u))), (np.repeat(v, 4) + np.tile(dv, len(v)))
        least = _least(cone, beta)
        keep = np.zeros(len(g), bool)
        # In chunks: a level's cells at once took blocks of fresh memory, whose page faults cost more than the
        # tests (the inclined plane's layout 67: 7,700 faults, its first search 90-170 ms against 60).
        for start in range(0, len(g), CHUNK):
            k = np.arange(start, min(start + CHUNK, len(g)))
            gk, a0 = g[k], _directions(face[k], u[k], v[k])
            near = np.all(np.abs(lines[gk] @ a0[:, :, None])[..., 0] >= least[gk], axis=1)
            if width.shape[1]:
                near &= np.all(np.abs(line_angle(normal[gk], a0[:, None]) - angle[gk]) <= width[gk] + beta + SLACK,
                               axis=1)
            k, gk, a0 = k[near], gk[near], a0[near]
            keep[k] = _axis_cells(points[gk], mask[gk], far[gk], a0, beta, radius, reach)
        g, face, u, v = g[keep], face[keep], u[keep], v[keep]
    return fits | (np.bincount(g, minlength=len(sets)) > 0)


def _directions(face, u, v):
    """The unit directions (K, 3) through (u, v) on the cube's faces ``face`` (0, 1, 2: x, y or z is 1)."""
    corner = np.stack([np.ones_like(u), u, v], axis=1)
    a0 = np.take_along_axis(corner, (np.arange(3)[None] - face[:, None]) % 3, axis=1)
    return a0 / np.linalg.norm(a0, axis=1, keepdims=True)


def _least(cone, beta):
    """The least ``|a0.line|`` (...) of a direction a0 within ``beta`` (rad) of a cone of width ``cone`` about a
    line (0 where they span a right angle)."""
    wide = cone + beta + SLACK
    return np.where(wide < np.pi / 2.0, np.cos(np.minimum(wide, np.pi / 2.0)), 0.0)


def _axis_cells(points, mask, far, a0, beta, radius, reach):
    """The cells (K) of :func:`fit_an_axis` that may hold an axis: touches (K, M, 3) about their centroid,
    ``mask`` the real ones, their distances from it (K, M), each cell's middle direction a0 (K, 3), and the
    cells' radius beta (rad). Two parallelograms hold c', each from three touches: those farthest apart across
    a0, and those farthest apart for how wide their ranges are (the touches nearest the centroid along a0, whose
    ranges a tilt widens least); a cell either one rules out fails."""
    q = points @ np.stack(perpendicular_basis(a0), axis=2)  # (K, M, 2)
    lo, hi = axis_ranges(points, far, a0, beta, radius, reach)
    rows = np.arange(len(q))
    sq = q[..., 0] ** 2 + q[..., 1] ** 2
    width = np.where(mask, hi - lo, np.inf)
    narrowest = np.argmin(width, axis=1)
    fits = np.ones(len(q), bool)
    # The narrow ranges' parallelogram first (it rules out more), the other only on the cells it leaves.
    for i0, weight in ((narrowest, width + width[rows, narrowest][:, None]),
                       (np.argmax(np.where(mask, sq, -np.inf), axis=1), np.ones_like(width))):
        k = np.flatnonzero(fits)
        at = np.arange(len(k))
        d = q[k] - q[k, i0[k]][:, None]
        i1 = np.argmax(np.where(mask[k], np.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2) / weight[k], -np.inf), axis=1)
        off_line = d[..., 0] * d[at, i1][:, None, 1] - d[..., 1] * d[at, i1][:, None, 0]
        i2 = np.argmax(np.where(mask[k], np.abs(off_line) / weight[k], -np.inf), axis=1)
        fits[k] = _parallelogram_fits(q[k], sq[k], mask[k], lo[k], hi[k], (i0[k], i1, i2), radius, reach)
    return fits


def _parallelogram_fits(q, sq, mask, lo, hi, triple, radius, reach):
    """Whether the parallelogram that touches ``triple`` (each (K,)) hold c' in (:func:`fit_an_axis`) leaves
    every touch's range met and c' within ``R + r`` of the centroid (True where it is too thin to solve)."""
    rows = np.arange(len(q))
    i0, i1, i2 = triple
    d = q - q[rows, i0][:, None]
    normals = np.stack([d[rows, i1], d[rows, i2]], axis=1)  # (K, 2, 2): n_i = q_i - q_0
    base = (sq[rows, [i1, i2]].T - sq[rows, i0][:, None])  # |q_i|^2 - |q_0|^2, (K, 2)
    low = 0.5 * (base - hi[rows, [i1, i2]].T ** 2 + lo[rows, i0][:, None] ** 2)
    high = 0.5 * (base - lo[rows, [i1, i2]].T ** 2 + hi[rows, i0][:, None] ** 2)
    det = normals[:, 0, 0] * normals[:, 1, 1] - normals[:, 0, 1] * normals[:, 1, 0]
    solvable = np.abs(det) > 1e-9 * np.sum(normals**2, axis=(1, 2))
    inverse = np.stack([normals[:, 1, 1], -normals[:, 0, 1], -normals[:, 1, 0], normals[:, 0, 0]], axis=1)
    inverse = inverse.reshape(-1, 2, 2) / np.where(solvable, det, 1.0)[:, None, None]
    centre, half = 0.5 * (low + high), 0.5 * (high - low)
    middle = inverse[:, :, 0] * centre[:, :1] + inverse[:, :, 1] * centre[:, 1:]
    # The parallelogram's half-diagonals a + b and a - b: the longer is |a|^2 + |b|^2 + 2 |a.b| squared.
    a, b = inverse[:, :, 0] * half[:, :1], inverse[:, :, 1] * half[:, 1:]
    spread = np.sqrt(np.sum(a * a + b * b, axis=1) + 2.0 * np.abs(np.sum(a * b, axis=1)))
    dx, dy = q[..., 0] - middle[:, None, 0], q[..., 1] - middle[:, None, 1]
    distance = np.sqrt(dx * dx + dy * dy)
    misses = mask & ((distance - spread[:, None] > hi * (1.0 + SLACK) + SLACK)
                     | (distance + spread[:, None] < lo - SLACK))
    away = np.linalg.norm(middle, axis=1) - spread > (radius + reach) * (1.0 + SLACK) + SLACK
    return ~solvable | ~(misses.any(axis=1) | away)


def axis_ranges(points, far, a0, beta, radius, reach):
    """Each touch's range ``[lo, hi]`` (K, M), mm, of distances from the line along a0 (K, 3) through the axis's
    point nearest the touches' centroid, where the touches (K, M, 3, about their centroid; ``far`` their
    distances from it) lie within ``reach`` of a cylinder of ``radius`` whose axis lies within ``beta`` (rad)
    of a0 (:func:`fit_an_axis`)."""
    along = np.abs(points @ a0[:, :, None])[..., 0] + beta * far
    slack = reach + beta * along + 0.5 * radius * beta**2
    return np.maximum(radius - slack, 0.0), radius + slack


def box_distances(low, high):
    """The least and the greatest distance (S, S) between a point of box s and a point of box t (boxes (S, 3)
    from ``low`` to ``high``): the gap and the span axis by axis."""
    gap = np.maximum(0.0, np.maximum(low[:, None] - high[None], low[None] - high[:, None]))
    span = np.maximum(np.abs(high[:, None] - low[None]), np.abs(high[None] - low[:, None]))
    return np.linalg.norm(gap, axis=2), np.linalg.norm(span, axis=2)


def _plane(P, offset, reach):
    """Quads (Q, 4, 3) whose tetrahedron's least width is at most 2 reach."""
    e = P[:, 1:] - P[:, :1]
    volume6 = np.abs(np.linalg.det(e))
    widths = []
    for k in range(4):
        a, b, c = (m for m in range(4) if m != k)
        area2 = np.linalg.norm(np.cross(P[:, b] - P[:, a], P[:, c] - P[:, a]), axis=1)
        widths.append(np.where(area2 > 0.0, volume6 / np.where(area2 > 0.0, area2, 1.0), 0.0))
    for (a, b), (c, d) in (((0, 1), (2, 3)), ((0, 2), (1, 3)), ((0, 3), (1, 2))):
        across = np.linalg.norm(np.cross(P[:, b] - P[:, a], P[:, d] - P[:, c]), axis=1)
        widths.append(np.where(across > 0.0, volume6 / np.where(across > 0.0, across, 1.0), np.inf))
    return np.min(widths, axis=0) <= 2.0 * reach * (1.0 + SLACK) + SLACK


def _sphere(P, radius, reach):
    """Quads whose sphere centre, as the slabs of the module doc hold it, may lie within radius +- reach of
    the first touch; every quad passes whose first three differences are nearly dependent."""
    d = P[:, 1:] - P[:, :1]
    b = 0.5 * np.sum(d**2, axis=2)
    scale = np.linalg.norm(d, axis=(1, 2)) ** 3
    det = np.linalg.det(d)
    solvable = np.abs(det) > 1e-9 * scale
    inverse = np.linalg.inv(np.where(solvable[:, None, None], d, np.eye(3)))
    centre = np.einsum("qij,qj->qi", inverse, b)
    slab = 0.5 * ((radius + reach) ** 2 - max(radius - reach, 0.0) ** 2)
    half = np.linalg.norm(np.abs(inverse) @ np.full(3, slab), axis=1)
    far = np.linalg.norm(centre, axis=1)
    fits = (far - half <= (radius + reach) * (1.0 + SLACK) + SLACK) & (far + half >= radius - reach - SLACK)
    return fits | ~solvable


def _line(P, radius, reach):
    """Quads whose pairs' cones about the axis (module doc) meet two by two."""
    i, j = np.array(list(itertools.combinations(range(4), 2))).T
    cone, unit = pair_cones(P[:, j] - P[:, i], _span(radius, reach))  # (Q, 6)
    fits = np.ones(len(P), bool)
    for a, b in itertools.combinations(range(6), 2):
        fits &= line_angle(unit[:, a], unit[:, b]) <= cone[:, a] + cone[:, b] + SLACK
    return fits


def _span(radius, reach):
    """The most two touches within ``reach`` of a cylinder of ``radius`` (mm; 0: a line) lie apart across its
    axis: its diameter, rounding kept on the tests' side."""
    return 2.0 * (radius + reach) * (1.0 + SLACK)


def line_angle(u, v):
    """The angle (rad, 0 to pi/2) between the lines along unit vectors u and v (..., 3, broadcast)."""
    return np.arccos(np.clip(np.abs(np.sum(u * v, axis=-1)), 0.0, 1.0))


QUAD_TESTS = {"plane": _plane, "point": _sphere, "line": _line}
