"""Concrete structures: contacts that share fixture features, placed and ranked by the one contact model.

``P/F-PL/M@a P/F-PL/M@a P/F-PL/M@a P/F-PL/M@b P/F-PL/M@b P/F-PL/M@c`` is the
cube's 3-2-1: contacts with the same label touch the same fixture element
(the contact's second, fixture side; contacts are written sensor first).
Each label gets one randomly placed feature of its element, each contact a
random touch on it with its sensor laid on the surface there, and the
touches become registration touch groups (:func:`touches.contact_touch`),
so the mobility is the rank of the registration's own rows at the identity
pose. Special positions are found the same way: the structure is moved into
a candidate degeneration (touches on a line, two directions parallel or
perpendicular) and its rank compared with the generic one.
"""

from dataclasses import dataclass, field, replace
from itertools import combinations

import numpy as np

from fixturecad.registration.contacts import ContactType
from fixturecad.registration.elements import CORE_WORDS, element, perpendicular_basis
from fixturecad.registration.features import Cylinder, Line, Plane, Point, Sphere
from fixturecad.registration.mobility import matrix_rank, null_space
from fixturecad.registration.motions import core_symmetry, free_motion_names
from fixturecad.registration.problem import Problem
from fixturecad.registration.touches import contact_touch, laid_sensor

STRUCTURE_SEED = 11
SIZE_MM = 50.0  # features within this of the origin, touches within this of their feature's anchor
LENGTH_MM = 50.0  # balances rotations and translations in the rank tests


def parse_labelled(tokens) -> list:
    """``["P/F-PL/M@a", "L/M-C/M"]`` -> [(ContactType, label or None)]; ValueError (one line) naming
    the bad token: an unknown contact, an empty label, or a label on two kinds of fixture element."""
    parsed, kinds = [], {}
    for token in tokens:
        name, at, label = token.partition("@")
        if at and not label.strip():
            raise ValueError(f"{token!r}: a label follows @, e.g. P/F-PL/M@a")
        ctype = ContactType.parse(name)
        label = label.strip() or None
        if label is not None:
            kind = element(ctype.fixture).kind
            if kinds.setdefault(label, kind) != kind:
                raise ValueError(f"label {label!r} is on a {kinds[label]} and on a {kind} ({token}): "
                                 "one label names one fixture element")
        parsed.append((ctype, label))
    return parsed


@dataclass
class Touch:
    """One contact on its feature: where (parameters on the feature) and its sensor's shape."""

    ctype: ContactType
    label: str
    at: np.ndarray  # (2,) parameters of the contact point on the feature (see ``_on_feature``)
    tangent: float  # rad: the direction of a line or cylinder sensor in the tangent plane
    radius: float  # mm: a sphere or cylinder sensor's radius


@dataclass
class Structure:
    """Features by label and the touches on them; contacts without a label get a feature each."""

    features: dict
    touches: list = field(default_factory=list)

    @classmethod
    def generic(cls, parsed, seed=STRUCTURE_SEED) -> "Structure":
        rng = np.random.default_rng(seed)
        features, touches = {}, []
        for number, (ctype, label) in enumerate(parsed, start=1):
            label = label or f"#{number}"
            if label not in features:
                features[label] = _random_feature(element(ctype.fixture).kind, label, rng)
            touches.append(Touch(ctype, label, rng.uniform(-1.0, 1.0, size=2), rng.uniform(0, np.pi),
                                 rng.uniform(3.0, 10.0)))
        return cls(features, touches)

    def groups(self) -> list:
        """The touch groups of the registration, one per contact, at the identity pose."""
        return [_group(self.features[t.label], t, index) for index, t in enumerate(self.touches)]

    def rows(self) -> list:
        """Each contact's rows (6 - d, 6) on twists at the identity pose, the registration's own."""
        out = []
        for group in self.groups():
            _, jacobian = Problem([group]).evaluate(np.eye(3), np.zeros(3))
            out.append(jacobian)
        return out

    def rank(self, leave_out=None) -> int:
        rows = [r for k, r in enumerate(self.rows()) if k != leave_out]
        return matrix_rank(np.vstack(rows), LENGTH_MM) if rows else 0

    def mobility(self) -> int:
        return 6 - self.rank()

    def redundant(self) -> list:
        """Indices of the contacts whose removal keeps the rank."""
        rank = self.rank()
        return [k for k in range(len(self.touches)) if self.rank(leave_out=k) == rank]

    def free_twists(self) -> np.ndarray:
        return null_space(np.vstack(self.rows()), LENGTH_MM)

    def freedom(self) -> list:
        """The free motions in standard form, named after the features (their labels); an axis no
        feature carries is named by the feature direction it is parallel to, never by coordinates of
        the random placement unless none is."""
        points, lines, planes = {}, {}, {}
        for label, feature in self.features.items():
            core, anchor, direction, _ = feature.core()
            {"point": points, "line": lines, "plane": planes}[core][_core_name(feature, label)] = (
                anchor if core == "point" else (anchor, direction))
        directions = {_direction_word(f, label): f.core()[2] for label, f in self.features.items()
                      if f.core()[2] is not None}
        planes_only = [(label, f.normal) for label, f in self.features.items() if f.kind == "plane"]
        for (a, na), (b, nb) in combinations(planes_only, 2):
            meet = np.cross(na, nb)
            if np.linalg.norm(meet) > 1e-9:
                directions[f"the line where {a} and {b} meet"] = meet / np.linalg.norm(meet)
        return free_motion_names(self.free_twists(), points, lines, planes, LENGTH_MM, directions)

    def is_symmetry_of(self, label) -> tuple:
        """(whether the free motions are exactly the symmetry of feature ``label``, its words)."""
        words, algebra = core_symmetry(self.features[label], _core_name(self.features[label], label))
        free = self.free_twists()
        if len(free) != len(algebra):
            return False, words
        both = np.vstack([free, algebra])
        return matrix_rank(both, LENGTH_MM) == len(algebra), words

    def special_positions(self) -> list:
        """Degenerations (in words) that lower the rank: touches on one line or at one point, features'
        directions parallel or perpendicular; each tested on the rows, none assumed."""
        rank = self.rank()
        found = []
        for words, moved in self._degenerations():
            if moved.rank() < rank:
                found.append(words)
        return found

    def _degenerations(self):
        by_label = {}
        for k, t in enumerate(self.touches):
            by_label.setdefault(t.label, []).append(k)
        for label, indices in by_label.items():
            kind = self.features[label].kind
            if len(indices) >= 3 and kind in ("plane", "cylinder"):
                first, second = (self.touches[i].at for i in indices[:2])
                touches = list(self.touches)
                for j, i in enumerate(indices[2:], start=2):
                    touches[i] = replace(touches[i], at=first + (j / 2.0 + 0.3) * (second - first))
                what = "collinear" if kind == "plane" else "on one helix"
                yield f"the touches on {label} are {what}", Structure(self.features, touches)
            if kind == "cylinder" and len(indices) >= 2:
                for coordinate, what in ((0, "on one circle about the axis"), (1, "on one line along the axis")):
                    touches = list(self.touches)
                    for i in indices[1:]:
                        at = touches[i].at.copy()
                        at[coordinate] = touches[indices[0]].at[coordinate]
                        touches[i] = replace(touches[i], at=at)
                    yield f"the touches on {label} are {what}", Structure(self.features, touches)
            if len(indices) >= 2 and kind != "point":
                touches = list(self.touches)
                for i in indices[1:]:
                    touches[i] = replace(touches[i], at=touches[indices[0]].at.copy())
                yield f"the touches on {label} coincide", Structure(self.features, touches)
        directed = [label for label, f in self.features.items() if f.core()[2] is not None]
        for a, b in combinations(directed, 2):
            da = self.features[a].core()[2]
            for relation, direction in (("parallel to", da), ("perpendicular to", perpendicular_basis(da)[0])):
                features = dict(self.features)
                features[b] = _with_direction(self.features[b], direction)
                yield f"{_direction_word(self.features[b], b)} is {relation} {_direction_word(self.features[a], a)}", \
                    Structure(features, self.touches)


def _core_name(feature, label) -> str:
    """A feature's core in words: the plane, line or point itself, a sphere's centre, a cylinder's axis."""
    core = feature.core()[0]
    return f"the {CORE_WORDS[core]} of {label}" if element(feature.kind).round else label


def _direction_word(feature, label) -> str:
    return {"plane": f"the normal of {label}", "cylinder": f"the axis of {label}", "line": label}[feature.kind]


def _random_feature(kind, label, rng):
    """A feature of ``kind`` placed at random within SIZE_MM of the origin."""
    point = rng.uniform(-SIZE_MM, SIZE_MM, size=3)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    radius = rng.uniform(5.0, 20.0)
    return {"plane": lambda: Plane(label, point, direction),
            "sphere": lambda: Sphere(label, point, radius),
            "cylinder": lambda: Cylinder(label, point, direction, radius),
            "line": lambda: Line(label, point, direction),
            "point": lambda: Point(label, point)}[kind]()


def _with_direction(feature, direction):
    key = {"plane": "normal", "cylinder": "axis", "line": "direction"}[feature.kind]
    return replace(feature, **{key: np.asarray(direction, float)})


def _on_feature(feature, at):
    """The contact point on the feature at parameters ``at`` in [-1, 1]^2, and the outward normal there."""
    core, anchor, direction, radius = feature.core()
    if core == "point" and feature.kind == "point":
        e1, e2 = perpendicular_basis(np.array([0.0, 0.0, 1.0]))
        n = np.cos(np.pi * at[0]) * e1 + np.sin(np.pi * at[0]) * e2
        return anchor, n
    if core == "point":  # a sphere: longitude, latitude
        lon, lat = np.pi * at[0], 0.45 * np.pi * at[1]
        n = np.array([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)])
        return anchor + radius * n, n
    e1, e2 = perpendicular_basis(direction)
    if core == "plane":
        return anchor + SIZE_MM * (at[0] * e1 + at[1] * e2), direction
    # a line or a cylinder: angle about the axis, position along it
    n = np.cos(np.pi * at[0]) * e1 + np.sin(np.pi * at[0]) * e2
    return anchor + SIZE_MM * at[1] * direction + radius * n, n


def _group(feature, touch, index):
    """The registration's touch group of one contact, its sensor laid on the feature at the touch."""
    ctype = touch.ctype
    c, n = _on_feature(feature, touch.at)
    if feature.kind == "line":
        # Across the line, in the plane its normal n makes with it.
        tangent = np.cross(n, feature.direction)
    else:
        t1, t2 = perpendicular_basis(n)
        tangent = np.cos(touch.tangent) * t1 + np.sin(touch.tangent) * t2
    sensor = laid_sensor(ctype.sensor, c, n, tangent, touch.radius)
    fixture = {"o": c} if ctype.fixture_fixed else None
    return contact_touch(feature, ctype.name, sensor, index, fixture=fixture, contact_point=c)
