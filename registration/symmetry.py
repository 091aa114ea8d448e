"""The rigid motions that map a fixture's surfaces onto themselves: its symmetries.

A motion S (``x -> R x + t``, fixture frame) is a symmetry of the surfaces when it maps each one onto one of
them, ``pi(f)``, exactly: the same kind, radius and sensing, its core (a sphere's centre, a cylinder's axis, a
plane) onto the other's, and its patch's constraints (half-spaces, balls, cylinders, axial interval) onto the
other's, one to one, within ``TOL_MM`` (and ``TOL`` on unit vectors). Then touches on features ``A`` at a pose P
are the same touches on ``pi(A)`` at ``P S^-1``: the one fits exactly as the other, so a search of one
assignment answers every assignment of its orbit (:mod:`.unlabelled`).

The candidates: each rotation that maps two non-parallel vectors of the surfaces (their centres' differences,
planes' normals, cylinders' axes either way) onto two of the same kind, length and angle, each with a
translation that maps the cores onto cores; every candidate is then checked, surface by surface. A symmetry
this misses is only a search not saved; one it keeps has been checked on every surface.

This module imports numpy only and nothing of fixturecad: it is inlined into the generated standalone
``register.py``.
"""

import itertools

import numpy as np

from .elements import perpendicular_basis
from .fits import frame_from

TOL_MM = 1e-6  # two cores, patches or offsets within this are one (a nanometre: rounding of the template's trig)
TOL = 1e-9  # ... and two unit vectors within this
_KEPT = {}  # ids of the surfaces -> (the surfaces, their symmetries): each registration asks for the same ones
KEPT = 64  # fixtures' symmetries kept before they are all forgotten


def symmetries(surfaces):
    """The symmetries of the ``surfaces`` other than the identity: (R (3, 3), t (3,), {id: image id}) each."""
    key = tuple(map(id, surfaces))
    kept = _KEPT.get(key)
    if kept is None or any(a is not b for a, b in zip(kept[0], surfaces)):
        if len(_KEPT) >= KEPT:
            _KEPT.clear()
        kept = _KEPT[key] = (tuple(surfaces), _symmetries(surfaces))
    return kept[1]


def _symmetries(surfaces):
    """:func:`symmetries`, found (see the module doc): those that move some surface onto another."""
    vectors = _vectors(surfaces)
    base = next(((a, b) for a, b in itertools.combinations(vectors, 2)
                 if np.linalg.norm(np.cross(a[1], b[1])) > 1e-6 * np.linalg.norm(a[1]) * np.linalg.norm(b[1])), None)
    if base is None:
        return []  # no two directions to turn by: no rotation is pinned down, none is looked for
    (kind_a, a), (kind_b, b) = base
    found = []
    for (kind_c, c), (kind_d, d) in itertools.permutations(vectors, 2):
        if (kind_c, kind_d) != (kind_a, kind_b) or abs(np.linalg.norm(c) - np.linalg.norm(a)) > TOL_MM \
                or abs(np.linalg.norm(d) - np.linalg.norm(b)) > TOL_MM or abs(c @ d - a @ b) > TOL_MM * (
                    np.linalg.norm(a) + np.linalg.norm(b) + 1.0):
            continue
        R = frame_from(c / np.linalg.norm(c), d) @ frame_from(a / np.linalg.norm(a), b).T
        for t in _translations(surfaces, R):
            image = _images(surfaces, R, t)
            if image is not None and not any(np.allclose(R, Rk, atol=TOL) and np.allclose(t, tk, atol=TOL_MM)
                                             for Rk, tk, _ in found):
                found.append((R, t, image))
    return [s for s in found if any(k != v for k, v in s[2].items())]


def _vectors(surfaces):
    """The directions a symmetry turns onto directions of the same kind: (kind, vector) each."""
    out = []
    for f, g in itertools.permutations(surfaces, 2):
        core_f, anchor_f, _, radius_f = f.core()
        core_g, anchor_g, _, radius_g = g.core()
        if core_f == core_g == "point":
            out.append((("centres", radius_f, radius_g), anchor_g - anchor_f))
    for f in surfaces:
        core, _, direction, radius = f.core()
        if core == "plane":
            out.append((("normal",), direction))
        elif core == "line":
            out += [(("axis", radius), direction), (("axis", radius), -direction)]
    return out


def _rows(f, g, R):
    """The rows (A, b) of ``A t = b`` that put f's core turned by R on g's, or None where they cannot meet."""
    core_f, anchor_f, direction_f, radius_f = f.core()
    core_g, anchor_g, direction_g, radius_g = g.core()
    if core_f != core_g or abs(radius_f - radius_g) > TOL_MM:
        return None
    if core_f == "point":
        return np.eye(3), anchor_g - R @ anchor_f
    turned = R @ direction_f
    if core_f == "plane":
        if np.linalg.norm(turned - direction_g) > TOL:
            return None
        return direction_g[None], np.array([direction_g @ anchor_g - direction_f @ anchor_f])
    if np.linalg.norm(np.cross(turned, direction_g)) > TOL:
        return None
    across = np.stack(perpendicular_basis(direction_g))
    return across, across @ (anchor_g - R @ anchor_f)


def _translations(surfaces, R):
    """Every t that puts the first surfaces' cores turned by R on cores of the others, as far as they pin t."""
    systems = [(np.zeros((0, 3)), np.zeros(0))]
    for f in surfaces:
        if all(np.linalg.matrix_rank(A, tol=1e-9) == 3 for A, _ in systems):
            break
        grown = []
        for A, b in systems:
            if np.linalg.matrix_rank(A, tol=1e-9) == 3:
                grown.append((A, b))
                continue
            for g in surfaces:
                rows = _rows(f, g, R)
                if rows is not None:
                    grown.append((np.vstack([A, rows[0]]), np.concatenate([b, rows[1]])))
        systems = grown
    out = []
    for A, b in systems:
        if np.linalg.matrix_rank(A, tol=1e-9) == 3:
            t = np.linalg.lstsq(A, b, rcond=None)[0]
            if np.all(np.abs(A @ t - b) <= TOL_MM):
                out.append(t)
    return out


def _images(surfaces, R, t):
    """Each surface's image id under ``x -> R x + t`` where every surface maps onto a distinct one, else None."""
    cores = {f.id: [g for g in surfaces if g.kind == f.kind and g.sensing == f.sensing and core_onto(f, g, R, t)]
             for f in surfaces}
    if not all(cores.values()):
        return None  # a core lands on none: the patches, the costly part, are not compared
    image = {}
    for f in surfaces:
        match = [g for g in cores[f.id] if _same_patch(f, g, R, t)]
        if len(match) != 1:
            return None
        image[f.id] = match[0].id
    return image if len(set(image.values())) == len(image) else None


def core_onto(f, g, R=np.eye(3), t=np.zeros(3)):
    """Whether f's core (its element: a centre, an axis, a plane, and its radius) turned by ``x -> R x + t`` is
    g's, within the tolerances."""
    rows = _rows(f, g, R)
    return rows is not None and bool(np.all(np.abs(rows[0] @ t - rows[1]) <= TOL_MM))


def _same_patch(f, g, R, t):
    """Whether f's patch turned by ``x -> R x + t`` is g's: its constraints one to one."""
    e, h = f.extent, g.extent
    halfspaces = np.column_stack([e.halfspaces[:, :3] @ R.T, e.halfspaces[:, 3] + e.halfspaces[:, :3] @ R.T @ t])
    balls = np.column_stack([e.balls[:, :3] @ R.T + t, e.balls[:, 3]])
    if not (_one_to_one(halfspaces, h.halfspaces, [TOL] * 3 + [TOL_MM]) and _one_to_one(balls, h.balls, TOL_MM)
            and len(e.cylinders) == len(h.cylinders)):
        return False
    for row in e.cylinders:
        point, axis = R @ row[:3] + t, R @ row[3:6]
        if not any(abs(row[6] - other[6]) <= TOL_MM and np.linalg.norm(np.cross(axis, other[3:6])) <= TOL
                   and np.linalg.norm(np.cross(point - other[:3], other[3:6])) <= TOL_MM for other in h.cylinders):
            return False
    if (e.interval is None) != (h.interval is None):
        return False
    if e.interval is None:
        return True
    # The interval's two ends along the axis, as points: the axis's anchor and sense are each surface's own.
    ends = [R @ (f.point + s * f.core()[2]) + t for s in e.interval]
    others = [g.point + s * g.core()[2] for s in h.interval]
    return any(all(np.linalg.norm(p - q) <= TOL_MM for p, q in zip(ends, order)) for order in (others, others[::-1]))


def _one_to_one(rows, others, tol):
    """Whether each row matches a distinct row of ``others`` within ``tol`` (per column), the same count."""
    if len(rows) != len(others):
        return False
    tol = np.broadcast_to(np.asarray(tol, dtype=float), rows.shape[1:])
    # Rows within tol column by column have keys (a generic mix of the columns) within |w|.tol: each row's
    # candidates are the others whose keys lie that near, found in the sorted keys.
    w = np.cos(np.arange(1, rows.shape[1] + 1))
    key, keys = rows @ w, others @ w
    order = np.argsort(keys)
    sorted_keys = keys[order]
    lo = np.searchsorted(sorted_keys, key - np.abs(w) @ tol, "left")
    hi = np.searchsorted(sorted_keys, key + np.abs(w) @ tol, "right")
    if np.all(hi - lo == 1):  # the usual case: one candidate each
        k = order[lo]
        return bool(np.all(np.abs(others[k] - rows) <= tol)) and len(np.unique(k)) == len(k)
    free = np.ones(len(others), bool)
    for row, a, b in zip(rows, lo, hi):
        k = order[a:b][np.all(np.abs(others[order[a:b]] - row) <= tol, axis=1) & free[order[a:b]]]
        if not len(k):
            return False
        free[k[0]] = False
    return True
