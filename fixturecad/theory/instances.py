"""Generic instances: two elements placed in contact at random, ready for the contact rows.

A generic instance is what the paper calls a contact "in general": random
contact point, normal, directions and radii, with no special alignment. The
free motions, the class and every rank test are computed on such instances.
"""

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from fixturecad.registration.contacts import ContactType, Side, contact_rows, make_side, residuals_and_jacobian
from fixturecad.registration.elements import CORE_WORDS, element


@dataclass
class Instance:
    """A contact placed at the identity pose, both sides in one frame.

    ``points`` and ``lines`` name the geometric entities a free motion can be
    described with (e.g. ``"the sphere centre"``): points (3,), lines
    (point (3,), unit direction (3,)).
    """

    ctype: ContactType
    sensor: Side
    fixture: Side
    rho: float
    contact_point: np.ndarray
    normal: np.ndarray
    points: dict
    lines: dict

    def rows(self):
        values, grads = contact_rows(self.ctype, self.sensor, self.fixture, self.rho)
        return values, grads

    def wrenches(self) -> np.ndarray:
        """Constraint rows as covectors on twists (omega, v) of the fixture, shape (6 - d, 6):
        the contact model's twist Jacobian at the identity pose."""
        _, jacobian = residuals_and_jacobian(self.ctype, self.sensor, self.fixture, np.eye(3), np.zeros(3), self.rho)
        return jacobian.reshape(-1, 6)


def _unit(rng, perpendicular_to=None):
    v = rng.normal(size=3)
    if perpendicular_to is not None:
        v -= v.dot(perpendicular_to) * perpendicular_to
    return v / np.linalg.norm(v)


def generic_instance(ctype: ContactType, rng: np.random.Generator) -> Instance:
    """Place the two elements of ``ctype`` in contact at a random spot.

    The random draws depend on the elements only, not on F or M: the same
    generator state gives the same geometry for every F/M variant of a pair.
    """
    o = rng.uniform(-50.0, 50.0, size=3)
    radii = {"A": rng.uniform(5.0, 30.0), "B": rng.uniform(5.0, 30.0)}
    kinds = {"A": ctype.sensor, "B": ctype.fixture}
    fixed = {"A": ctype.sensor_fixed, "B": ctype.fixture_fixed}
    labels = {"A": "sensor", "B": "fixture"}
    if kinds["A"] == "L" and kinds["B"] == "L":
        dirs = {"A": _unit(rng), "B": _unit(rng)}
        nz = np.cross(dirs["A"], dirs["B"])
        nz /= np.linalg.norm(nz)
    else:
        nz = _unit(rng)
        dirs = {side: (_unit(rng) if "P" in kinds.values() and kinds[side] == "L" else _unit(rng, nz))
                for side in "AB"}
    # A lies below the tangent plane (outward normal +nz), B above (outward normal -nz).
    outward = {"A": nz, "B": -nz}
    points, lines = {"the contact point": o}, {}
    geometry = {}
    for side in "AB":
        # The element's core one radius inside its surface, along the outward normal.
        el = element(kinds[side])
        r = radii[side] if el.round else 0.0
        anchor = o - r * outward[side] if el.round else o
        values = {el.anchor_key: anchor, "d": dirs[side], "n": outward[side], "r": r}
        geometry[side] = {key: values[key] for _, key in el.keys}
        who = labels[side]
        if el.core == "point" and el.round:
            points[f"the {who} {el.kind} {CORE_WORDS[el.core]}"] = anchor
        elif el.core == "line":
            name = f"the {who} {el.kind} {CORE_WORDS[el.core]}" if el.round else f"the {who} line"
            lines[name] = (anchor, dirs[side])
    rho = 0.0
    if ctype.is_locus:
        plane_side = "A" if kinds["A"] == "PL" else "B"
        other = "B" if plane_side == "A" else "A"
        n_plane = geometry[plane_side]["n"]
        if kinds[other] == "C":
            # The axis runs parallel to the plane, one radius out along its normal.
            geometry[other]["p"] = o + radii[other] * n_plane
            rho = radii[other]
            lines[f"the {labels[other]} cylinder axis"] = (geometry[other]["p"], geometry[other]["d"])
            if fixed[other]:
                geometry[other]["m"] = -n_plane
        if kinds[other] in ("L", "C") and fixed[plane_side]:
            geometry[plane_side]["e"] = geometry[other]["d"]
            lines["the contact line"] = (o, geometry[other]["d"])
    for side in "AB":
        if fixed[side]:
            geometry[side]["o"] = o
            if element(kinds[side]).surface:
                geometry[side]["u"] = outward[side]
    lines["the contact normal"] = (o, nz)
    sides = {side: make_side(kinds[side], fixed[side], **geometry[side]) for side in "AB"}
    if not ctype.is_locus:
        mobile_core = [s for s in "AB" if not fixed[s]]
        if len(mobile_core) == 1 and fixed["AB".replace(mobile_core[0], "")] and \
                element(kinds["AB".replace(mobile_core[0], "")]).surface:
            rho = radii[mobile_core[0]] if element(kinds[mobile_core[0]]).round else 0.0
        elif not fixed["A"] and not fixed["B"]:
            values, _ = contact_rows(ctype, sides["A"], sides["B"], 0.0)
            rho = float(values[0])
    return Instance(ctype, sides["A"], sides["B"], rho, o, nz, points, lines)


def named_entities(instances):
    """Points and lines of the placed contacts, named for a reader."""
    points, lines = {}, {}
    several = len(instances) > 1
    for number, instance in enumerate(instances, start=1):
        suffix = f" of contact {number} ({instance.ctype.name})" if several else ""
        for name, point in instance.points.items():
            points[name + suffix] = point
        for name, (point, direction) in instance.lines.items():
            lines[name + suffix] = (point, direction)
    # Lines through two named points come first, those avoiding contact points before the rest:
    # "the line through the two sphere centres" reads better than "the contact normal".
    pairs = sorted(combinations(points.items(), 2), key=lambda pair: sum("contact point" in n for n, _ in pair))
    through = {}
    for (name_a, a), (name_b, b) in pairs:
        if np.linalg.norm(a - b) > 1e-6:
            through[f"the line through {name_a} and {name_b}"] = (a, (b - a) / np.linalg.norm(b - a))
    return points, through | lines
