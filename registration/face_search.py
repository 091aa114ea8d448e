"""Which surfaces unlabelled touches may lie on, from a branch and bound over poses.

The interpretation tree (:mod:`.assignments`) tells assignments apart by the touches' shape alone; on a part
of many alike faces (a cube's six, touches anywhere) its tests leave tens of thousands. This search bounds
the poses instead, with the labelled search's cells (:mod:`.search`): a rotation box (centre ``v0``,
half-width ``w``, every rotation within ``delta = sqrt(3) w`` of ``R0``) times a box of images ``y`` of the
touches' centroid c, the place of touch i being ``x_i = R^T b_i + y``, ``b_i = p_i - c``. Over a cell x_i
lies in the box ``R0^T b_i + [ylo, yhi]`` grown by ``g_i = delta |b_i|`` (a turn moves it at most that far).
At a pose that passes under an assignment A, touch i lies within its reach ``sqrt(T) + e`` of A_i (``e`` the
printed part's deviation bound) and within A_i's patch box grown as the labelled search grows it; so each
touch keeps, cell by cell, the surfaces it may lie on (its *candidates*), A_i among them:

* a surface whose grown patch box the touch's box misses, or whose least distance from that box (a plane's
  along its normal, a sphere's or cylinder's :func:`.search.least_over_box`) less ``g_i`` exceeds its reach,
  is no candidate;
* a cell where a touch has none, or where the sum over the touches of their least distances (less their
  deviation bounds) squared exceeds ``T``, holds no pose that passes;
* y lies, for each touch, in the hull of its candidates' boxes less ``R0^T b_i +- g_i``, and for a touch with
  one plane left within the slab its reach allows along the normal (:func:`.search.propagated`).

Where the surfaces have symmetries S (:mod:`.symmetry`), a pose P passes under A exactly when ``P S^-1``
passes under the image of A; the orbit of rotations ``R R_S^T`` holds one of greatest trace, so only
rotations with ``tr(R) >= tr(R R_S^T)`` for every S are searched, and a cell goes where some S has
``tr(R0 R_S^T) - tr(R0) > 4 delta sin(phi_S / 2)`` (``phi_S`` the angle of R_S: the difference moves by at most
``|R - R0|_F |R_S - I|_F``). The assignments found are then put as the least of their orbits.

A cell is split (its rotation box in eight while a turn moves the touches more than half its y box is wide,
else its y box in two) until its touches have one candidate each, or its candidates' product is at most
``PRODUCT`` and it is narrower than the reach: every assignment that its candidates give is kept. So every
assignment under which a pose passes is kept (or one of its orbit), the labelled search decides each.

This module imports numpy only and nothing of fixturecad: it is inlined into the generated standalone
``register.py``.
"""

import itertools

import numpy as np

from .assignments import grown_boxes, least_of_orbits
from .pose import rotation_from_vector
from .search import beyond_pi, first_cells, least_over_box, propagated, split

MAX_CELLS = 600_000  # cells searched in all before the search stops (10-20 us each; the v-block needs up to 363,000)
MAX_LEVELS = 40  # splits of a cell before the search stops
PRODUCT = 64  # a cell narrower than the reach keeps every assignment its candidates give, at most this many
SLACK = 1e-9  # relative: rounding kept on the bounds' side
CHUNK = 32768  # cells bounded at once


def face_search(surfaces, points, ball_radius_mm, tolerance, q, threshold, group=()):
    """The assignments of the touches ``points`` (n, 3), mm, to the ``surfaces`` under which a pose may pass
    (tuples of ids, one per touch; each the least of its orbit under the ``group``'s maps, :mod:`.symmetry`),
    the reason the search stopped (else ""), and the cells kept per level. ``threshold``: the test's largest
    cost, mm^2; ``q`` that over sigma^2, for the ``tolerance``'s deviation bounds (None: an exact part)."""
    root = float(np.sqrt(threshold))
    n, F = len(points), len(surfaces)
    centroid = points.mean(axis=0)
    b = points - centroid
    rho = np.linalg.norm(b, axis=1)
    cores = [f.core() for f in surfaces]
    plane = np.array([core == "plane" for core, *_ in cores])
    point = np.array([core == "point" for core, *_ in cores])
    anchor = np.array([a for _, a, _, _ in cores], float)
    direction = np.array([np.zeros(3) if d is None else d for _, _, d, _ in cores], float)
    offset = np.array([radius + ball_radius_mm for *_, radius in cores])
    level = np.einsum("fd,fd->f", anchor, direction) + offset  # a plane's touches' n.x at contact
    dev, low, high = grown_boxes(surfaces, offset, tolerance, q, root)
    reach = (root + dev) * (1.0 + SLACK) + SLACK
    turns = np.array([R for R, _, _ in group]).reshape(-1, 3, 3)
    sines = np.sqrt(np.maximum(3.0 - np.trace(turns, axis1=1, axis2=2), 0.0) / 4.0)  # sin(phi / 2)

    v, w, _, _ = first_cells()
    ylo, yhi = np.repeat(low.min(axis=0)[None], len(v), 0), np.repeat(high.max(axis=0)[None], len(v), 0)
    C = np.ones((len(v), n, F), bool)
    def pruned(v, w, ylo, yhi, C):
        """The cells that may hold a pose that passes, their y boxes narrowed and their candidates ``C`` (K, n,
        F) left, and each touch's turn (K, n), mm."""
        K = len(v)
        R0 = rotation_from_vector(v)
        a = np.einsum("kji,nj->kni", R0, b)  # R0^T b_i
        delta = np.sqrt(3.0) * w
        g = delta[:, None] * rho[None]
        ylo, yhi = _contracted(C, a, g, ylo, yhi, low, high, plane, direction, level, reach)
        half = 0.5 * (yhi - ylo)
        middle = a + (0.5 * (ylo + yhi))[:, None]
        around = half[:, None] + g[..., None]
        least = np.empty((K, n, F))
        for f in range(F):
            meets = np.all((middle - around <= high[f]) & (middle + around >= low[f]), axis=2)
            if plane[f]:
                d = np.abs(middle @ direction[f] - level[f]) - (half @ np.abs(direction[f]))[:, None]
            else:
                d = least_over_box(middle - anchor[f], np.broadcast_to(half[:, None], middle.shape), direction[f],
                                   point[f:f + 1], np.zeros(1, bool), offset[f])
            least[..., f] = np.where(meets, np.maximum(d - g, 0.0), np.inf)
        C = C & (least <= reach)
        nearest = np.min(np.where(C, np.maximum(least - dev, 0.0), np.inf), axis=2)
        keep = (np.all(ylo <= yhi, axis=1) & C.any(axis=2).all(axis=1) & ~beyond_pi(v, w)
                & (np.sum(np.where(np.isfinite(nearest), nearest, 0.0) ** 2, axis=1) <= threshold * (1.0 + SLACK)))
        if len(turns):
            gain = np.einsum("kij,sij->ks", R0, turns) - np.trace(R0, axis1=1, axis2=2)[:, None]
            keep &= ~np.any(gain > 4.0 * delta[:, None] * sines[None], axis=1)
        return v[keep], w[keep], ylo[keep], yhi[keep], C[keep], g[keep]

    found, kept, searched = set(), [], 0
    for _ in range(MAX_LEVELS):
        if not len(v):
            break
        searched += len(v)
        # A chunk of cells at a time: a level's arrays grow with cells x touches x surfaces.
        parts = [pruned(*(x[s:s + CHUNK] for x in (v, w, ylo, yhi, C))) for s in range(0, len(v), CHUNK)]
        v, w, ylo, yhi, C, g = (np.concatenate(x) for x in zip(*parts))
        kept.append(len(v))
        count = np.prod(C.sum(axis=2), axis=1)
        done = (count == 1) | ((count <= PRODUCT) & (g.max(axis=1, initial=0.0) <= root)
                               & ((yhi - ylo).max(axis=1) <= 2.0 * root))
        for k in np.flatnonzero(done):
            found.update(itertools.product(*[np.flatnonzero(c) for c in C[k]]))
        v, w, ylo, yhi, C, g = v[~done], w[~done], ylo[~done], yhi[~done], C[~done], g[~done]
        turning = g.max(axis=1, initial=0.0) > 0.25 * (yhi - ylo).max(axis=1)
        if searched + 8 * turning.sum() + 2 * (~turning).sum() > MAX_CELLS:  # before the split takes the memory
            return [], f"the touches' surfaces were not told within {MAX_CELLS} cells of poses", kept
        C = np.concatenate([np.repeat(C[turning], 8, axis=0), np.repeat(C[~turning], 2, axis=0)])
        v, w, ylo, yhi = split(v, w, ylo, yhi, turning, np.ones(3, bool))
    if len(v):
        return [], f"the touches' surfaces were not told within {MAX_LEVELS} splits of a cell of poses", kept
    return _least_of_orbits(found, surfaces, group), "", kept


def _contracted(C, a, g, ylo, yhi, low, high, plane, direction, level, reach):
    """The y boxes narrowed to the hull, for each touch, of its candidates' boxes less its place, and to the
    slab of each touch with one plane left."""
    K, n, F = C.shape
    lo, hi = np.full((K, n, 3), np.inf), np.full((K, n, 3), -np.inf)
    for f in range(F):
        on = C[..., f, None]
        np.minimum(lo, np.where(on, low[f], np.inf), out=lo)
        np.maximum(hi, np.where(on, high[f], -np.inf), out=hi)
    ylo = np.maximum(ylo, np.max(lo - a - g[..., None], axis=1))
    yhi = np.minimum(yhi, np.min(hi - a + g[..., None], axis=1))
    only = np.argmax(C, axis=2)
    on_plane = (C.sum(axis=2) == 1) & plane[only]
    if not on_plane.any():
        return ylo, yhi
    normal = direction[only]
    at = level[only] - np.einsum("knd,knd->kn", normal, a)
    width = reach[only] + g
    return propagated([(np.where(on_plane[..., None], normal, 0.0), np.where(on_plane, at - width, -np.inf),
                       np.where(on_plane, at + width, np.inf))], ylo, yhi, 1)


def _least_of_orbits(found, surfaces, group):
    """The assignments (tuples of surface indices) as ids, each the least of its orbit under the group's maps
    (by the surfaces' order), once each: their orbits' members, of which :func:`.assignments.least_of_orbits`
    keeps the least."""
    if not found:
        return []
    ids = [f.id for f in surfaces]
    index = {fid: k for k, fid in enumerate(ids)}
    maps = [np.array([index[to[fid]] for fid in ids]) for _, _, to in group]
    rows = np.array(sorted(found), int)
    members = np.unique(np.concatenate([rows] + [m[rows] for m in maps]), axis=0)
    return sorted(tuple(ids[k] for k in row) for row in least_of_orbits(members, maps))
