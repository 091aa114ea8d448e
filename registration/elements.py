"""The element table: points, lines, planes, spheres and cylinders, and their distances.

Every element is a *core* (a point, a line or a plane) grown by a radius: a
sphere is a point grown by r, a cylinder a line grown by r, and a point, a
line or a plane has radius 0. That is the paper's observation that makes 41
contacts fall into 15 classes, and it is why one distance serves them all:
the offset of a point from the core, less the radius. The contact rows, the
features' distances, the touch groups, the schema's kinds and the theory's
generic placements all read this table; an unknown kind is an error.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np


@dataclass(frozen=True)
class Element:
    """One kind of element.

    ``letter``: the paper's (P, L, PL, S, C); ``kind``: features.json's name;
    ``core``: point, line or plane; ``keys``: features.json geometry keys, in
    order, mapped to the contact model's side keys (``c`` a point core, ``p``
    and ``d`` a line core, ``q`` and ``n`` a plane core, ``r`` a radius).
    """

    letter: str
    kind: str
    core: str
    keys: tuple

    @cached_property
    def json_keys(self) -> tuple:
        return tuple(json for json, _ in self.keys)

    @cached_property
    def round(self) -> bool:
        """Whether the element has a radius of its own (a sphere or a cylinder)."""
        return any(side == "r" for _, side in self.keys)

    @cached_property
    def surface(self) -> bool:
        """Whether the element bounds material, with an outward normal (a plane, a sphere, a cylinder)."""
        return self.round or self.core == "plane"

    @cached_property
    def anchor_key(self) -> str:
        """The contact-model key of the core's point: a point's ``c``, a line's ``p``, a plane's ``q``."""
        return CORE_KEYS[self.core][0]

    def side_geometry(self, geometry) -> dict:
        """Contact-model keys of the element from its features.json geometry: a mapping by json key,
        or an object with the json keys as attributes (a feature)."""
        if not isinstance(geometry, dict):
            return {side: getattr(geometry, json) for json, side in self.keys}
        return {side: geometry[json] for json, side in self.keys}

    def core_of(self, geometry) -> tuple:
        """(core, anchor (3,), direction (3,) or None, radius mm) of the distances below, from
        features.json geometry (see :meth:`side_geometry`)."""
        side = self.side_geometry(geometry)
        anchor, direction = CORE_KEYS[self.core]
        return self.core, side[anchor], side.get(direction), side.get("r", 0.0)


# The contact-model keys of each core: its point, and a line's direction or a plane's normal.
CORE_KEYS = {"point": ("c", None), "line": ("p", "d"), "plane": ("q", "n")}
CORE_WORDS = {"point": "centre", "line": "axis"}  # what a reader calls the core of a sphere, of a cylinder

ELEMENTS = (
    Element("P", "point", "point", (("point", "c"),)),
    Element("L", "line", "line", (("point", "p"), ("direction", "d"))),
    Element("PL", "plane", "plane", (("point", "q"), ("normal", "n"))),
    Element("S", "sphere", "point", (("center", "c"), ("radius", "r"))),
    Element("C", "cylinder", "line", (("point", "p"), ("axis", "d"), ("radius", "r"))),
)
LETTERS = tuple(e.letter for e in ELEMENTS)
KINDS = tuple(e.kind for e in ELEMENTS)
_BY_NAME = {**{e.letter: e for e in ELEMENTS}, **{e.kind: e for e in ELEMENTS}}


def element(name: str) -> Element:
    """The element of a letter (``PL``) or a kind (``plane``); ValueError naming the known ones."""
    try:
        return _BY_NAME[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown element {name!r}; choose from {', '.join(LETTERS)} "
                         f"or {', '.join(KINDS)}") from None


_LEVI_CIVITA = np.zeros((3, 3, 3))
_LEVI_CIVITA[[0, 1, 2], [1, 2, 0], [2, 0, 1]], _LEVI_CIVITA[[0, 2, 1], [2, 1, 0], [1, 0, 2]] = 1.0, -1.0
SMALL_CROSS = 200  # numbers in both operands up to which one einsum beats the nine ufunc calls


def cross(a, b):
    """The cross product of vectors along the last axis, broadcast: ``np.cross`` without its axis handling,
    which costs more than the product on the small arrays of the search."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.size + b.size <= SMALL_CROSS:  # a few touches: numpy's per-call cost is all there is
        return np.einsum("ijk,...j,...k->...i", _LEVI_CIVITA, a, b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))  # filled in place: cheaper than stacking the parts
    np.subtract(a[..., 1] * b[..., 2], a[..., 2] * b[..., 1], out=out[..., 0])
    np.subtract(a[..., 2] * b[..., 0], a[..., 0] * b[..., 2], out=out[..., 1])
    np.subtract(a[..., 0] * b[..., 1], a[..., 1] * b[..., 0], out=out[..., 2])
    return out


def dot(a, b):
    """The dot product of vectors along the last axis, broadcast: a reduction over a short last axis costs numpy
    several times the products."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def perpendicular_basis(v):
    """Two unit vectors perpendicular to unit ``v`` and to each other, shape like ``v``."""
    v = np.asarray(v, dtype=float)
    helper = np.where(np.abs(v[..., :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    e1 = cross(v, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    return e1, cross(v, e1)


def core_offset(core: str, anchor, direction, points):
    """The offset (n, 3) of points from a core: from its point, from its line (perpendicular part),
    or along its plane's normal. ``direction``: a line's unit direction or a plane's unit normal."""
    r = points - anchor
    if core == "point":
        return r
    along = np.einsum("...i,...i->...", r, direction)[..., None]
    return r - along * direction if core == "line" else along * direction


def distance_and_outward(core: str, anchor, direction, radius, points):
    """Signed distance (...,) of points (..., 3) from an element and the unit direction away from its
    core through them. The distance is the offset from the core less the radius: along the normal
    for a plane core (the direction is the normal itself), the offset's length for a point or a
    line core (unsigned for a point or a line, radius 0). A point on a point or line core has no
    such direction: an arbitrary one perpendicular to the core is given."""
    if core == "plane":
        return np.einsum("...i,...i->...", points - anchor, direction) - radius, direction
    offset = core_offset(core, anchor, direction, points)
    length = np.sqrt(np.einsum("...i,...i->...", offset, offset))
    if length.min(initial=np.inf) >= 1e-12:  # (no point on the core: the usual case, without errstate's cost)
        return length - radius, offset / length[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = offset / length[..., None]
    fallback = perpendicular_basis(direction)[0] if core == "line" else np.array([0.0, 0.0, 1.0])
    unit = np.where((length < 1e-12)[..., None], np.broadcast_to(fallback, unit.shape), unit)
    return length - radius, unit


def signed_distance(core: str, anchor, direction, radius, points):
    """Signed distance (...,) of points from an element (:func:`distance_and_outward`)."""
    return distance_and_outward(core, anchor, direction, radius, points)[0]


def outward(core: str, anchor, direction, points):
    """Unit directions (n, 3) away from the core through each point (:func:`distance_and_outward`)."""
    unit = distance_and_outward(core, anchor, direction, 0.0, points)[1]
    return np.broadcast_to(unit, np.shape(points)).copy()


def closest_point(core: str, anchor, direction, radius, points):
    """The closest points (n, 3) of an element to the given points."""
    points = np.asarray(points, float).reshape(-1, 3)
    _, unit = distance_and_outward(core, anchor, direction, radius, points)
    return points - core_offset(core, anchor, direction, points) + radius * unit
