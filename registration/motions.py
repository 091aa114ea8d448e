"""Names of the motions a set of touches leaves free, relative to the fixture's features.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

import numpy as np

def _feature_directions(problem, rotation, features=None):
    """(description, unit direction in the measurement frame, feature): touched features first."""
    out = []
    seen = set()
    listed = [g.feature for g in problem.groups] + list((features or {}).values())
    for f in listed:
        if f is None or f.id in seen:
            continue
        seen.add(f.id)
        if f.kind == "plane":
            out.append((f"the normal of {f.id}", rotation @ f.normal, f))
        elif f.kind == "cylinder":
            out.append((f"the axis of {f.id}", rotation @ f.axis, f))
        elif f.kind == "line":
            out.append((f"the direction of {f.id}", rotation @ f.direction, f))
    return out


def _vec(v):
    return "(" + ", ".join(f"{x:.3g}" for x in v) + ")"


def free_motions(problem, solution, features=None):
    """Names of the motions the touches do not constrain, relative to the features.

    Directions are matched with the touched features first, then with the
    other ``features`` (dict id -> feature) of the fixture.
    """
    length = problem.scale()
    D = np.array([length] * 3 + [1.0] * 3)
    scaled = solution.jacobian / D
    _, s, vt = np.linalg.svd(scaled, full_matrices=True)
    rank = solution.rank
    null = (vt[rank:] / D).T  # (6, k) twists
    if null.shape[1] == 0:
        return []
    R, t = solution.rotation, solution.translation
    directions = _feature_directions(problem, R, features)
    names = []
    # Pure translations: the null space of the rotation part within the null space.
    _, sw, vw = np.linalg.svd(null[:3], full_matrices=True)
    rank_w = int(np.sum(sw > 1e-9 * max(np.abs(null).max(), 1e-300)))
    trans = null @ vw[rank_w:].T  # (6, k - rank_w)
    rot = null @ vw[:rank_w].T
    if trans.shape[1]:
        T_dirs = np.linalg.qr(trans[3:])[0]
        if T_dirs.shape[1] == 1:
            u = T_dirs[:, 0]
            match = [name for name, d, _ in directions if abs(d @ u) > 0.999]
            planes = [(f.id, d) for _, d, f in directions if f.kind == "plane"]
            match += [f"both {a} and {b}" for i, (a, da) in enumerate(planes) for b, db in planes[i + 1:]
                      if abs(da @ u) < 1e-3 and abs(db @ u) < 1e-3 and abs(da @ db) < 0.999]
            if match and match[0].startswith("both "):
                names.append("translation parallel to " + match[0])
            else:
                names.append("translation along " + (match[0] if match else _vec(u)))
        elif T_dirs.shape[1] == 2:
            n = np.cross(T_dirs[:, 0], T_dirs[:, 1])
            match = [f.id for name, d, f in directions if f.kind == "plane" and abs(d @ n) > 0.999]
            names.append("translation in the plane of " + match[0] if match else f"translation normal to {_vec(n)}")
        else:
            names.append("translation in every direction")
    if rot.shape[1]:
        omega_basis = np.linalg.qr(rot[:3])[0]
        shifts = trans[3:] if trans.shape[1] else np.zeros((3, 0))

        def twist_with(w):
            """The free twist whose rotation part is ``w`` and the axis point (m, 3)."""
            coeff = np.linalg.lstsq(null[:3], w, rcond=None)[0]
            v = null[3:] @ coeff
            return np.cross(w, v) / (w @ w)

        def on_axis(points, w):
            """Whether the points lie on the free axis along w (shifted by free translations)."""
            off = points - twist_with(w)
            off = off - np.outer(off @ w, w)
            moves = np.cross(w, shifts.T).T if shifts.shape[1] else np.zeros((3, 0))
            if moves.shape[1]:
                q = np.linalg.qr(moves)[0]
                off = off - (off @ q) @ q.T
            return bool(np.all(np.linalg.norm(off, axis=1) < 1e-6 * length))

        def take(w):
            nonlocal omega_basis
            if omega_basis.shape[1] == 0 or np.linalg.norm(omega_basis @ (omega_basis.T @ w) - w) > 1e-6:
                return False
            rest = omega_basis - np.outer(w, w @ omega_basis)
            q, sv, _ = np.linalg.svd(rest, full_matrices=False)
            omega_basis = q[:, sv > 1e-6]
            return True

        # Axes through collinear touches, then feature directions, then anything left.
        for g in problem.groups:
            if g.points is None or g.count < 2:
                continue
            d = g.points[-1] - g.points[0]
            d = d / np.linalg.norm(d)
            if on_axis(g.points, d) and take(d):
                names.append(f"rotation about the line through the touches on {g.feature.id}")
        for name, d, f in directions:
            if take(d):
                names.append("rotation about " + name)
        for k in range(omega_basis.shape[1]):
            w = omega_basis[:, k]
            label = None
            spheres = [g.feature for g in problem.groups if getattr(g.feature, "kind", None) == "sphere"]
            for i, a in enumerate(spheres):
                for b in spheres[i + 1:]:
                    centres = np.array([R @ a.center + t, R @ b.center + t])
                    if label is None and on_axis(centres, w):
                        label = f"the line through the centres of {a.id} and {b.id}"
            for g in problem.groups if label is None else ():
                if getattr(g.feature, "kind", None) == "sphere":
                    c = R @ g.feature.center + t
                    if on_axis(c[None], w):
                        label = f"an axis {_vec(w)} through the centre of {g.feature.id}"
                        break
            names.append("rotation about " + (label or f"the axis {_vec(w)} through {_vec(twist_with(w))} mm"))
    return names
