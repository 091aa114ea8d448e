"""Datum frames: the fixture frame defined by the fixture's own sensing features.

A printed part has no CAD origin. As ISO 5459 / ASME Y14.5 datum systems do,
its frame is built from datum features, primary first:

``planes`` (primary, secondary, tertiary plane)
    the first axis is the primary's normal, the second the secondary's
    normal made perpendicular to it, the third their cross product; the
    origin is where the three planes meet.
``axis-plane`` (primary cylinder or line, secondary plane)
    the paper's Example Two: Z along the axis, the origin where the axis
    meets the plane, Y = n x Z, X = Y x Z.
``planes-point`` (primary plane, secondary plane, tertiary sphere or point)
    axes as ``planes``; the origin is the sphere's centre (or the point)
    dropped onto the line where the two planes meet.
``points`` (three spheres or points)
    the origin at the first centre, the first axis towards the second, the
    third normal to the plane of all three.

The construction is the same for every part, so it moves with the part
(equivariant): the fixture frame of a printed part is ``D(printed)
D(nominal)^-1`` in the nominal frame, the identity for the drawing. A
nominal build's frame is the datum frame of its nominal features.

This module imports numpy only and nothing of fixturecad: it is inlined into
the generated standalone ``register.py``.
"""

from dataclasses import dataclass

import numpy as np

from .elements import cross
from .tolerance import moved

CONSTRUCTIONS = {
    "planes": ("plane", "plane", "plane"),
    "axis-plane": ("axis", "plane"),
    "planes-point": ("plane", "plane", "centre"),
    "points": ("centre", "centre", "centre"),
}
ROLES = ("primary", "secondary", "tertiary")
_ACCEPTS = {"plane": ("plane",), "axis": ("cylinder", "line"), "centre": ("sphere", "point")}


def _centre(feature):
    return feature.center if feature.kind == "sphere" else feature.point


def _axis(feature):
    return feature.axis if feature.kind == "cylinder" else feature.direction


def _meet(normals, points):
    """The point where three planes (unit normals (3, 3), points on them (3, 3)) meet."""
    return np.linalg.solve(np.asarray(normals), np.einsum("ij,ij->i", normals, points))


def _frame(x, y, origin):
    """A 4x4 frame with first axis ``x``, second ``y`` made perpendicular to it, at ``origin``."""
    x = x / np.linalg.norm(x)
    y = y - (y @ x) * x
    y = y / np.linalg.norm(y)
    D = np.eye(4)
    D[:3, :3] = np.column_stack([x, y, cross(x, y)])
    D[:3, 3] = origin
    return D


@dataclass(frozen=True)
class DatumScheme:
    """Which features fix the frame, in order, and by which construction (see the module doc)."""

    construction: str
    features: tuple

    def __post_init__(self):
        if self.construction not in CONSTRUCTIONS:
            raise ValueError(f"unknown datum construction {self.construction!r}; "
                             f"choose from {', '.join(CONSTRUCTIONS)}")
        if len(self.features) != len(CONSTRUCTIONS[self.construction]):
            raise ValueError(f"a {self.construction} datum scheme takes "
                             f"{len(CONSTRUCTIONS[self.construction])} features, got {len(self.features)}")

    def check(self, features):
        """Raise ValueError unless every datum feature exists and is of the right kind."""
        for fid, role in zip(self.features, CONSTRUCTIONS[self.construction]):
            if fid not in features:
                raise ValueError(f"datum feature {fid!r} is not a feature of this fixture")
            if features[fid].kind not in _ACCEPTS[role]:
                raise ValueError(f"datum feature {fid} is a {features[fid].kind}; the {self.construction} "
                                 f"scheme needs a {' or '.join(_ACCEPTS[role])} there")

    def frame(self, features) -> np.ndarray:
        """The datum frame D (4, 4) built from the features (dict id -> feature), fixture coordinates."""
        f = [features[fid] for fid in self.features]
        if self.construction == "planes":
            origin = _meet([g.normal for g in f], [g.point for g in f])
            return _frame(f[0].normal, f[1].normal, origin)
        if self.construction == "axis-plane":
            axis, plane = f
            d = _axis(axis)
            along = ((plane.point - axis.point) @ plane.normal) / (d @ plane.normal)
            origin = axis.point + along * d
            y = cross(plane.normal, d)
            return _frame(cross(y, d), y, origin)
        if self.construction == "planes-point":
            line = cross(f[0].normal, f[1].normal)
            on_line = _meet([f[0].normal, f[1].normal, line], [f[0].point, f[1].point, _centre(f[2])])
            return _frame(f[0].normal, f[1].normal, on_line)
        c = [_centre(g) for g in f]
        return _frame(c[1] - c[0], c[2] - c[0], c[0])

    def to_json(self, text: str = "") -> dict:
        """The features.json ``datums`` entry: construction, roles, and the scheme in words."""
        return {
            "construction": self.construction,
            "features": [{"feature": fid, "role": role} for fid, role in zip(self.features, ROLES)],
            "text": text,
        }

    @classmethod
    def from_json(cls, data) -> "DatumScheme":
        return cls(data["construction"], tuple(entry["feature"] for entry in data["features"]))


def frame_change(scheme, nominal, actual):
    """The rigid motion (4, 4) from the nominal frame to the printed part's datum frame, nominal coordinates.

    A point with datum-frame coordinates x lies at ``frame_change @ x`` in the
    nominal frame the printed features are given in.
    """
    return scheme.frame(actual) @ np.linalg.inv(scheme.frame(nominal))


def in_datum_frame(scheme, nominal, actual):
    """The printed features (dict id -> feature) re-expressed in their own datum frame."""
    inverse = np.linalg.inv(frame_change(scheme, nominal, actual))
    return {fid: moved(f, inverse[:3, :3], inverse[:3, 3]) for fid, f in actual.items()}
