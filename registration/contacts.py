"""The contact model: constraint rows of every contact type, with analytic Jacobians.

One description of each contact drives everything in fixturecad: the
catalogue's free-motion groups, registration residuals, the mobility of a
touch plan (rank of the stacked Jacobian) and the Fisher information.

A contact joins a *sensor* element (measurement frame) and a *fixture* element
(fixture frame, mapped by the pose ``p_meas = R p_fix + t``). Elements are
points (P), lines (L), planes (PL), spheres (S) and cylinders (C). A side is
fixed (F) when the contact location on it is known, mobile (M) otherwise.

Every element is a *core* (point, line or plane) grown by a radius: a sphere is
a point core, a cylinder a line core, a point or a line has radius 0. That is
the paper's observation that a point is a sphere of radius 0 and a line a
cylinder of radius 0, and it is why 41 contacts fall into 15 classes.

Rows are zero when the contact holds. A contact whose free motions have
dimension d gives 6 - d independent rows. The Jacobian is taken with respect
to a spatial twist (omega, v) in the measurement frame: R <- exp(omega) R,
t <- exp(omega) t + v, so a moved fixture point p' changes by omega x p' + v.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

from dataclasses import dataclass, field

import numpy as np

from .elements import CORE_KEYS, LETTERS, core_offset, cross, distance_and_outward, element, perpendicular_basis


# Keys of side geometry: points move with their body as points, the rest as directions.
POINT_KEYS = frozenset({"o", "c", "p", "q"})
DIRECTION_KEYS = frozenset({"u", "d", "n", "e1", "e2", "t1", "t2", "e", "f", "m"})


@dataclass(frozen=True)
class ContactType:
    """A contact between a sensor element and a fixture element, e.g. ``P/F-PL/M``.

    The sensor side is written first. Table I of the paper writes each contact
    in one order; ``canonical`` gives that name whatever the sides.
    """

    sensor: str
    sensor_fixed: bool
    fixture: str
    fixture_fixed: bool

    def __post_init__(self):
        for kind in (self.sensor, self.fixture):
            element(kind)  # ValueError for an unknown one
        if (self.sensor == "P" and not self.sensor_fixed) or (
            self.fixture == "P" and not self.fixture_fixed
        ):
            raise ValueError("a point is always fixed (P/F): its contact location is the point")

    @property
    def name(self) -> str:
        return f"{self.sensor}/{'F' if self.sensor_fixed else 'M'}-{self.fixture}/{'F' if self.fixture_fixed else 'M'}"

    @property
    def canonical(self) -> str:
        """The Table I name: elements in the order P, S, PL, L, C; F before M."""
        order = {"P": 0, "S": 1, "PL": 2, "L": 3, "C": 4}
        a = (order[self.sensor], not self.sensor_fixed, self.sensor, self.sensor_fixed)
        b = (order[self.fixture], not self.fixture_fixed, self.fixture, self.fixture_fixed)
        first, second = sorted([a, b])
        return f"{first[2]}/{'F' if first[3] else 'M'}-{second[2]}/{'F' if second[3] else 'M'}"

    @property
    def is_locus(self) -> bool:
        """Contacts along a line or a face: a plane with a line, a cylinder or a plane."""
        kinds = [self.sensor, self.fixture]
        if "PL" not in kinds:
            return False
        kinds.remove("PL")
        return kinds[0] in ("L", "C", "PL")

    def swapped(self) -> "ContactType":
        return ContactType(self.fixture, self.fixture_fixed, self.sensor, self.sensor_fixed)

    @classmethod
    def parse(cls, text: str) -> "ContactType":
        """Parse ``X/F-Y/M`` (spaces allowed); raise ValueError naming the valid forms."""
        cleaned = text.replace(" ", "").upper()
        parts = cleaned.split("-")
        if len(parts) != 2 or any(part.count("/") != 1 for part in parts):
            raise ValueError(f"cannot read contact {text!r}: write it like P/F-PL/M")
        sides = []
        for part in parts:
            kind, flag = part.split("/")
            if kind not in LETTERS or flag not in ("F", "M"):
                raise ValueError(
                    f"cannot read contact {text!r}: elements are {', '.join(LETTERS)} and sides F or M"
                )
            sides.append((kind, flag == "F"))
        return cls(sides[0][0], sides[0][1], sides[1][0], sides[1][1])


@dataclass
class Side:
    """Geometry of one side of a contact, arrays broadcast over touches.

    Keys (mm for points, unit vectors for directions):
    core point ``c``; core line ``p``, ``d`` with ``e1``, ``e2`` perpendicular
    to ``d``; core plane ``q``, ``n``; a fixed side adds the contact point
    ``o`` and, for surfaces and lines, the orientation ``u`` at ``o``
    (outward normal or line direction) with ``t1``, ``t2`` perpendicular to
    ``u``. A fixed plane in a line or face contact adds the locus line
    direction ``e`` and ``f = n x e``; a fixed cylinder in a plane contact adds
    ``m``, the unit radial direction from its axis to the contact line.
    """

    kind: str
    fixed: bool
    geometry: dict = field(default_factory=dict)

    def __getitem__(self, key):
        return self.geometry[key]

    def moved(self, rotation, translation) -> "Side":
        """The side with its geometry mapped by ``x -> R x + t`` (directions by R)."""
        moved = {}
        for key, value in self.geometry.items():
            if key in POINT_KEYS:
                moved[key] = value @ rotation.T + translation
            elif key in DIRECTION_KEYS:
                moved[key] = value @ rotation.T
            else:
                moved[key] = value
        return Side(self.kind, self.fixed, moved)


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def _units(shape):
    """The three coordinate unit vectors broadcast to ``shape`` (..., 3)."""
    eye = np.eye(3)
    return [np.broadcast_to(eye[axis], shape) for axis in range(3)]


def _orientation(kind):
    """What a fixed element knows at its contact point besides the point."""
    el = element(kind)
    return "normal" if el.surface else "direction" if el.core == "line" else None


class _Rows:
    """Rows under construction: a value and gradients by (side label, key) per row."""

    def __init__(self):
        self.values = []
        self.grads = []

    def add(self, value, grads):
        self.values.append(value)
        self.grads.append(grads)


def _distance_row(rows, xl, xkey, x, core, yl, y, radius):
    """One row: the signed distance of point ``x`` (key ``xkey`` of side ``xl``) from the core of side
    ``yl``'s element (``y``) grown by ``radius`` (:func:`.elements.distance_and_outward`)."""
    anchor_key, direction_key = CORE_KEYS[core]
    anchor, direction = y[anchor_key], y.get(direction_key)
    distance, u = distance_and_outward(core, anchor, direction, radius, x)
    grads = {(xl, xkey): u, (yl, anchor_key): -u}
    if core == "line":
        grads[(yl, "d")] = -_dot(x - anchor, direction)[..., None] * u
    elif core == "plane":
        grads[(yl, "n")] = x - anchor
    rows.add(distance, grads)


def _point_on(rows, xl, x, kind, yl, y):
    """Point ``x`` (key ``o`` of side ``xl``) lies on the element ``y`` of side ``yl``.

    A point or a line: the components of the offset from it; otherwise the
    element's signed distance (:func:`_distance_row`).
    """
    if kind == "P":
        r = core_offset("point", y["c"], None, x)
        for axis, unit in enumerate(_units(r.shape)):
            rows.add(r[..., axis], {(xl, "o"): unit, (yl, "c"): -unit})
    elif kind == "L":
        r = x - y["p"]
        for key in ("e1", "e2"):
            e = y[key]
            rows.add(_dot(r, e), {(xl, "o"): e, (yl, "p"): -e, (yl, key): r})
    else:
        _distance_row(rows, xl, "o", x, element(kind).core, yl, y, y.get("r", 0.0))


def _line_tangent(rows, xl, x, kind, yl, y):
    """The fixed line of side ``xl`` (point ``o``, direction ``u``) is tangent to surface ``y``."""
    if kind == "S":
        r = x["o"] - y["c"]
        rows.add(_dot(x["u"], r), {(xl, "u"): r, (xl, "o"): x["u"], (yl, "c"): -x["u"]})
    else:
        r = x["o"] - y["p"]
        along = _dot(r, y["d"])
        w = r - along[..., None] * y["d"]
        du = _dot(x["u"], y["d"])
        proj = x["u"] - du[..., None] * y["d"]
        rows.add(
            _dot(x["u"], w),
            {
                (xl, "u"): w,
                (xl, "o"): proj,
                (yl, "p"): -proj,
                (yl, "d"): -(du[..., None] * r + along[..., None] * x["u"]),
            },
        )


def _normals_parallel(rows, al, a, bl, nb, key):
    """Two rows: the normal ``nb`` (key of side ``bl``) is parallel to side ``al``'s ``u``."""
    for t in ("t1", "t2"):
        rows.add(_dot(nb, a[t]), {(bl, key): a[t], (al, t): nb})


def _fixed_fixed(rows, A, a, B, b):
    """Both contact points known: they coincide, and the orientations there agree."""
    r = a["o"] - b["o"]
    for axis, unit in enumerate(_units(r.shape)):
        rows.add(r[..., axis], {("A", "o"): unit, ("B", "o"): -unit})
    shapes = {_orientation(A.kind), _orientation(B.kind)}
    if shapes == {"normal"}:
        _normals_parallel(rows, "A", a, "B", b["u"], "u")
    elif shapes == {"normal", "direction"}:
        rows.add(_dot(a["u"], b["u"]), {("A", "u"): b["u"], ("B", "u"): a["u"]})


def _fixed_mobile(rows, xl, X, x, yl, Y, y, rho):
    """X fixed (its contact point ``o`` known), Y mobile."""
    shape = _orientation(X.kind)
    if shape is None or shape == "direction":
        _point_on(rows, xl, x["o"], Y.kind, yl, y)
        if shape == "direction" and Y.kind in ("S", "C"):
            _line_tangent(rows, xl, x, Y.kind, yl, y)
        return
    # A fixed surface: the core of Y sits at the offset point o + rho u.
    target = x["o"] + rho[..., None] * x["u"]
    core = element(Y.kind).core
    if core == "point":
        r = target - y["c"]
        for axis, unit in enumerate(_units(r.shape)):
            rows.add(r[..., axis], {(xl, "o"): unit, (xl, "u"): rho[..., None] * unit, (yl, "c"): -unit})
    elif core == "line":
        r = target - y["p"]
        for key in ("e1", "e2"):
            e = y[key]
            rows.add(_dot(r, e), {(xl, "o"): e, (xl, "u"): rho[..., None] * e, (yl, "p"): -e, (yl, key): r})
        rows.add(_dot(x["u"], y["d"]), {(xl, "u"): y["d"], (yl, "d"): x["u"]})
    else:
        r = target - y["q"]
        n = y["n"]
        rows.add(_dot(n, r), {(xl, "o"): n, (xl, "u"): rho[..., None] * n, (yl, "q"): -n, (yl, "n"): r})
        _normals_parallel(rows, xl, x, yl, n, "n")


def _mobile_mobile(rows, A, a, B, b, rho):
    """One row: the signed distance between the two cores equals rho."""
    sides = [("A", A, a), ("B", B, b)]
    order = {"point": 0, "line": 1, "plane": 2}
    sides.sort(key=lambda side: order[element(side[1].kind).core])
    (l1, s1, g1), (l2, s2, g2) = sides
    cores = (element(s1.kind).core, element(s2.kind).core)
    if cores[0] == "point":
        _distance_row(rows, l1, "c", g1["c"], cores[1], l2, g2, rho)
    elif cores == ("line", "line"):
        # Unsigned distance between the lines: the sign of a cross product flips
        # when the lines turn past parallel, the distance does not.
        r = g1["p"] - g2["p"]
        across = cross(g1["d"], g2["d"])
        sign = np.where(_dot(r, across) < 0, -1.0, 1.0)[..., None]
        m = sign * across
        size = np.linalg.norm(m, axis=-1)[..., None]
        value = _dot(r, m) / size[..., 0]
        g_m = sign * (r - value[..., None] * m / size) / size  # gradient with respect to the cross product
        rows.add(
            value - rho,
            {
                (l1, "p"): m / size,
                (l2, "p"): -m / size,
                (l1, "d"): cross(g2["d"], g_m),
                (l2, "d"): cross(g_m, g1["d"]),
            },
        )
    else:
        raise ValueError(f"no mobile-mobile row between a {cores[0]} and a {cores[1]}")


def _locus(rows, pl, P, p, ol, O, o, rho):
    """Plane ``P`` with a line, a cylinder or a plane ``O`` lying on it along a line or a face."""
    n = p["n"]
    if O.kind == "PL":
        _normals_parallel(rows, pl, p, ol, o["n"], "n")
        r = o["q"] - p["q"]
        rows.add(_dot(n, r), {(pl, "n"): r, (ol, "q"): n, (pl, "q"): -n})
        return
    # The line, or the cylinder axis, is parallel to the plane at distance rho.
    d, r = o["d"], o["p"] - p["q"]
    rows.add(_dot(n, d), {(pl, "n"): d, (ol, "d"): n})
    rows.add(_dot(n, r) - rho, {(pl, "n"): r, (ol, "p"): n, (pl, "q"): -n})
    if O.kind == "C" and O.fixed:
        # The known contact line of the cylinder faces the plane.
        h = cross(n, d)
        rows.add(
            _dot(o["m"], h),
            {(ol, "m"): h, (pl, "n"): cross(d, o["m"]), (ol, "d"): cross(o["m"], n)},
        )
    if P.fixed:
        # The contact line lies on the known locus line (point o, direction e) of the plane.
        f = p["f"]
        s = o["p"] - p["o"]
        rows.add(_dot(d, f), {(ol, "d"): f, (pl, "f"): d})
        rows.add(_dot(s, f), {(ol, "p"): f, (pl, "o"): -f, (pl, "f"): s})
        if O.kind == "L" and O.fixed:
            # Both know the locus pointwise: the line's contact point meets the plane's.
            s = o["o"] - p["o"]
            rows.add(_dot(s, p["e"]), {(ol, "o"): p["e"], (pl, "o"): -p["e"], (pl, "e"): s})


def contact_rows(ctype: ContactType, sensor: Side, fixture: Side, rho=0.0):
    """Rows of one contact with the fixture side already in the measurement frame.

    Parameters
    ----------
    ctype : ContactType
    sensor, fixture : Side
        Geometry broadcast over N touches, both in the measurement frame.
    rho : float or array, shape (N,), mm
        Signed offset: the core distance of a mobile-mobile contact, or the
        offset along the fixed surface normal to the mobile core.

    Returns
    -------
    values : ndarray, shape (N, k)
    grads : list of k dicts {(side, key): ndarray (N, 3)}, side "A" (sensor) or "B" (fixture)
    """
    A, B = sensor, fixture
    a, b = A.geometry, B.geometry
    rows = _Rows()
    rho = np.asarray(rho, dtype=float)
    if ctype.is_locus:
        if A.kind == "PL":
            _locus(rows, "A", A, a, "B", B, b, rho)
        else:
            _locus(rows, "B", B, b, "A", A, a, rho)
    elif A.fixed and B.fixed:
        _fixed_fixed(rows, A, a, B, b)
    elif A.fixed:
        _fixed_mobile(rows, "A", A, a, "B", B, b, rho)
    elif B.fixed:
        _fixed_mobile(rows, "B", B, b, "A", A, a, rho)
    else:
        _mobile_mobile(rows, A, a, B, b, rho)
    values = np.stack(np.broadcast_arrays(*rows.values), axis=-1)
    return values, rows.grads


def residuals_and_jacobian(ctype, sensor: Side, fixture: Side, rotation, translation, rho=0.0):
    """Rows of a contact at pose ``fixture -> measurement`` and their twist Jacobian.

    Returns
    -------
    values : ndarray, shape (N, k), mm (or unitless for direction rows)
    jacobian : ndarray, shape (N, k, 6), columns (omega_x, omega_y, omega_z, v_x, v_y, v_z)
    """
    moved = fixture.moved(np.asarray(rotation, float), np.asarray(translation, float))
    values, grads = contact_rows(ctype, sensor, moved, rho)
    k = len(grads)
    values = values.reshape(-1, k)
    n = values.shape[0]
    jacobian = np.zeros((n, k, 6))
    for row, grad in enumerate(grads):
        for (label, key), g in grad.items():
            if label != "B":
                continue
            jacobian[:, row, :3] += cross(moved[key], g)
            if key in POINT_KEYS:
                jacobian[:, row, 3:] += g
    return values, jacobian


def make_side(kind: str, fixed: bool, **geometry) -> Side:
    """A Side from its defining geometry; fills the derived keys.

    Give ``c`` (and ``r``) for P and S, ``p``, ``d`` (and ``r``) for L and C,
    ``q``, ``n`` for PL; a fixed side also ``o`` and ``u`` (``u`` is implied
    for a plane or a line), a fixed plane of a line contact ``e``, a fixed
    cylinder of a plane contact ``m``.
    """
    g = {key: np.asarray(value, dtype=float) for key, value in geometry.items()}
    if "d" in g:
        g["e1"], g["e2"] = perpendicular_basis(g["d"])
    if fixed and kind == "PL":
        g.setdefault("u", g["n"])
    if fixed and kind == "L":
        g.setdefault("u", g["d"])
    if kind == "PL":
        g["t1"], g["t2"] = perpendicular_basis(g["n"])
        if "e" in g:
            g["f"] = cross(g["n"], g["e"])
    elif "u" in g:
        g["t1"], g["t2"] = perpendicular_basis(g["u"])
    return Side(kind, fixed, g)
