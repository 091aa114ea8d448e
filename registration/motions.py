"""Names of free motions in standard form, relative to named geometry.

One algorithm for the catalogue's analysis and for a registration left
underdetermined: the free twists are covered, greatest first, by the
displacement subgroups the named points, lines and planes span, spherical
motion {S_o} about a point, planar motion {G_P} in a plane, cylindrical
motion {C_u} along a line, translation {T_P} in a plane, rotation {R_u}
about a line, translation {T_u} along a direction; what no named geometry
explains is given as screws with their pitch (0 is a rotation, never called
a screw) or as translations, in the coordinates the twists are given in.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

from .elements import CORE_WORDS, cross, element, perpendicular_basis
from .mobility import matrix_rank, null_space, weakest_motion

COLLINEAR_MM = 1e-6  # touches this close to the line through the first and last lie on it
PARALLEL_COS = 1e-9  # 1 - |cos| below which an axis is parallel to a named direction


def _rotation(p, d):
    return np.concatenate([d, cross(p, d)])


def _translation(d):
    return np.concatenate([np.zeros(3), d])


def _candidates(points, lines, planes):
    """(words, algebra (k, 6)) of the subgroups the named geometry spans, greatest first."""
    out = []
    for name, p in points.items():
        out.append((3, f"spherical motion {{S_o}} about {name}", [_rotation(p, e) for e in np.eye(3)]))
    for name, (p, n) in planes.items():
        e1, e2 = perpendicular_basis(n)
        out.append((3, f"planar motion {{G_P}} in the plane of {name}", [_rotation(p, n), _translation(e1), _translation(e2)]))
        out.append((2, f"translation {{T_P}} in the plane of {name}", [_translation(e1), _translation(e2)]))
    for name, (p, d) in lines.items():
        out.append((2, f"cylindrical motion {{C_u}} along {name}", [_rotation(p, d), _translation(d)]))
        out.append((1, f"rotation {{R_u}} about {name}", [_rotation(p, d)]))
    for name, (p, n) in planes.items():
        out.append((1, f"translation {{T_u}} along the normal of {name}", [_translation(n)]))
    for name, (p, d) in lines.items():
        out.append((1, f"translation {{T_u}} along {name}", [_translation(d)]))
    for axis, label in zip(np.eye(3), "xyz"):
        out.append((1, f"translation {{T_u}} along {label}", [_translation(axis)]))
    out.sort(key=lambda item: -item[0])  # stable: within a dimension, the order above
    return [(words, np.array(algebra)) for _, words, algebra in out]


def core_symmetry(feature, name) -> tuple:
    """(words, algebra (k, 6)) of the motions that carry a feature onto itself: {S_o} about a point
    core (a point, a sphere's centre), {C_u} along a line core (a line, a cylinder's axis), {G_P} in a plane."""
    core, anchor, direction, _ = feature.core()
    if core == "point":
        return f"spherical motion {{S_o}} about {name}", np.array([_rotation(anchor, e) for e in np.eye(3)])
    if core == "line":
        return f"cylindrical motion {{C_u}} along {name}", np.array([_rotation(anchor, direction), _translation(direction)])
    e1, e2 = perpendicular_basis(direction)
    return f"planar motion {{G_P}} in the plane of {name}", np.array(
        [_rotation(anchor, direction), _translation(e1), _translation(e2)])


def _vec(v, digits=3):
    """Coordinates in words, rounding off what is zero but for rounding (no -0)."""
    v = np.where(np.abs(v) < 1e-9 * max(np.abs(v).max(), 1.0), 0.0, v) + 0.0
    return "(" + ", ".join(f"{x:.{digits}g}" for x in v) + ")"


def screw_words(twist, directions=None) -> str:
    """A twist in words: a translation, a rotation (pitch 0) or a screw with its pitch (mm/rad).

    ``directions`` {name: unit (3,)}: a direction parallel to one is given by
    that name alone (the coordinates of a random example mean nothing).
    """
    w, v = twist[:3], twist[3:]
    if np.linalg.norm(w) < 1e-9 * max(np.linalg.norm(v), 1e-300):
        return f"translation {{T_u}} {_along(v / np.linalg.norm(v), directions)}"
    pitch = float(w @ v / (w @ w))
    point = cross(w, v) / (w @ w)
    d = w / np.linalg.norm(w)
    axis = _along(d, directions)
    axis = f"the axis through {_vec(point, 4)} mm {axis}" if axis.startswith("along (") else f"an axis {axis}"
    if abs(pitch) < 1e-9:
        return f"rotation {{R_u}} about {axis}"
    return f"screw motion of pitch {pitch:.4g} mm/rad about {axis}"


def _along(d, directions):
    for name, u in (directions or {}).items():
        if abs(float(np.dot(d, u))) > 1.0 - PARALLEL_COS:
            return f"parallel to {name}"
    return f"along {_vec(d)}"


def free_motion_names(free, points=None, lines=None, planes=None, length_mm=None, directions=None) -> list:
    """Names of the motions spanned by the free twists (m, 6), relative to named geometry.

    ``points`` {name: (3,)}, ``lines`` {name: (point (3,), unit direction (3,))},
    ``planes`` {name: (point (3,), unit normal (3,))}, in the twists' frame.
    ``length_mm`` balances rotation and translation in the rank tests.
    ``directions`` {name: unit (3,)} name the axes of what is left (:func:`screw_words`).
    """
    free = np.asarray(free, float).reshape(-1, 6)
    dim = len(free)
    words, covered = [], np.zeros((0, 6))
    candidates = _candidates(points or {}, lines or {}, planes or {})
    # First the subgroups that add all of their motions, then those that add some.
    for whole in (True, False):
        for text, algebra in candidates:
            if len(covered) == dim or text in words:
                continue
            inside = matrix_rank(np.vstack([free, algebra]), length_mm) == dim
            added = matrix_rank(np.vstack([covered, algebra]), length_mm) - len(covered)
            if inside and added > 0 and (added == len(algebra) or not whole):
                words.append(text)
                covered = np.vstack([covered, algebra])
                covered = np.linalg.svd(covered, full_matrices=False)[2][: matrix_rank(covered, length_mm)]
    if len(covered) < dim:
        # What the named geometry does not explain: the screws of the twists left.
        remaining = free - (free @ covered.T) @ covered if len(covered) else free
        for twist in np.linalg.svd(remaining, full_matrices=False)[2][: dim - len(covered)]:
            words.append(screw_words(twist, directions))
    return words


def free_motions(problem, solution, features=None, weak=False):
    """Names of the motions the touches leave free (``weak``: the one they determine worst), relative to
    the fixture's features, fixture frame.

    Named geometry: every feature (a plane, a sphere's centre, a cylinder's
    axis, a line), the lines through touches that lie on one, and the lines
    through two sphere centres.
    """
    length = problem.scale()
    free = (weakest_motion if weak else null_space)(solution.jacobian, length)
    if not len(free):
        return []
    # Measurement-frame twists (w, v) seen in the fixture frame: (R^T w, R^T (v + w x t)).
    R, t = solution.rotation, solution.translation
    free = np.hstack([free[:, :3] @ R, (free[:, 3:] + cross(free[:, :3], t)) @ R])
    points, lines, planes, touch_lines = {}, {}, {}, {}
    for g in problem.groups:
        if g.points is not None and g.count >= 2:
            local = (g.points - t) @ R
            span = np.linalg.norm(local - local[0], axis=1)
            if span.max() < COLLINEAR_MM * max(length, 1.0):
                continue  # the touches are one point: no line through them
            d = (local[span.argmax()] - local[0]) / span.max()
            off = local - local[0] - np.outer((local - local[0]) @ d, d)
            if np.all(np.linalg.norm(off, axis=1) < COLLINEAR_MM * max(length, 1.0)):
                touch_lines[f"the line through the touches on {g.feature.id}"] = (local[0], d)
    listed = {g.feature.id: g.feature for g in problem.groups}
    listed.update(features or {})
    spheres = [f for f in listed.values() if f.kind == "sphere"]
    for i, a in enumerate(spheres):
        for b in spheres[i + 1:]:
            gap = np.linalg.norm(b.center - a.center)
            if gap > COLLINEAR_MM * max(length, 1.0):  # two spheres about one centre (a face and its feature): no line
                lines[f"the line through the centres of {a.id} and {b.id}"] = (a.center, (b.center - a.center) / gap)
    for f in listed.values():
        # A feature names its core: a plane, a point or line itself, a sphere's centre, a cylinder's axis.
        core, anchor, direction, _ = f.core()
        name = f"the {CORE_WORDS[core]} of {f.id}" if element(f.kind).round else f.id
        if core == "point":
            points[name] = anchor
        else:
            (planes if core == "plane" else lines)[name] = (anchor, direction)
    # The features' own lines before those through touches or centres.
    return free_motion_names(free, points, {**{k: v for k, v in lines.items() if not k.startswith("the line")},
                                            **{k: v for k, v in lines.items() if k.startswith("the line")},
                                            **touch_lines}, planes, length)
