"""The contact catalogue: Tables I, III and IV computed from the contact model.

For each contact the free motions are the twists that the contact rows leave
free (their number is the dimension); the group representation is the
product of the mobile sides' symmetry groups with the motions that keep both
contact loci in place, rewritten in the paper's compact form; the class is
the kinds of that product.
"""

from dataclasses import dataclass
from functools import cache, cached_property

import numpy as np

from fixturecad.registration.contacts import ContactType
from fixturecad.registration.elements import element
from fixturecad.registration.mobility import matrix_rank, null_space
from fixturecad.theory.groups import Subgroup, class_name, group_notation, labelled, simplify
from fixturecad.theory.instances import Instance, generic_instance, named_entities

SEED = 1994  # the catalogue is computed on seeded generic instances
# Table IV order, which is also the order of classes within a Table V row.
CLASSES = ("R", "T1", "R-R", "C", "R-C", "S", "G3", "S-R", "S-T1", "G3-R", "R-R-C", "S-S", "S-C", "S-T2", "C-R-C")
ELEMENT_ORDER = ("P", "S", "PL", "L", "C")


def table_one() -> list[ContactType]:
    """The 41 contacts of Table I, in its order.

    Every pair of elements with each side fixed or mobile (a point is always
    fixed), except that the paper keeps one plane-plane contact (a face
    contact is the whole plane, so F and M do not differ) and, for a line on a
    plane, only PL/F-L/F and PL/M-L/F.
    """
    sides = {kind: [True] if kind == "P" else [True, False] for kind in ELEMENT_ORDER}
    contacts = []
    for i, first in enumerate(ELEMENT_ORDER):
        for second in ELEMENT_ORDER[i:]:
            for a in sides[first]:
                for b in sides[second]:
                    if first == second and not a and b:
                        continue
                    if first == second == "PL" and not (a and b):
                        continue
                    if (first, second) == ("PL", "L") and not b:
                        continue
                    contacts.append(ContactType(first, a, second, b))
    return contacts


@dataclass(frozen=True)
class CatalogueEntry:
    """One computed row of Tables III and IV."""

    ctype: ContactType
    dim: int
    chain: tuple
    instance: Instance

    @property
    def name(self) -> str:
        return self.ctype.name

    @cached_property
    def contact_class(self) -> str:
        return class_name(list(self.chain))

    @property
    def group(self) -> str:
        return group_notation(list(self.chain))

    @property
    def description(self) -> str:
        """What each letter of the group stands for, e.g. ``o: the contact point``."""
        return "; ".join(f"{anchor}: {_anchor_words(factor, self.instance)}"
                         for factor, _, anchor in labelled(list(self.chain)))


def _anchor_words(factor: Subgroup, instance: Instance) -> str:
    """Name the point, line or plane that places a subgroup, from the instance's named entities."""
    points, lines = named_entities([instance])
    p, w = factor.point, factor.direction
    if factor.kind == "S":
        return next(name for name, q in points.items() if np.linalg.norm(p - q) < 1e-6)
    if factor.kind in ("T2", "G3"):
        for label, side in (("sensor", instance.sensor), ("fixture", instance.fixture)):
            if side.kind == "PL" and abs(side["n"] @ w) > 1 - 1e-9:
                return f"the {label} plane"
        return "the tangent plane at the contact point"
    parallel = [(name, q, d) for name, (q, d) in lines.items() if abs(d @ w) > 1 - 1e-9]
    if factor.kind == "T1":
        return "parallel to " + parallel[0][0]
    on_axis = [name for name, q, d in parallel if np.linalg.norm(np.cross(p - q, d)) < 1e-6]
    if on_axis:
        return on_axis[0]
    return "the line through the contact point along " + parallel[0][0]


def free_twists(instance: Instance) -> np.ndarray:
    """Basis of the twists the contact leaves free, shape (d, 6)."""
    return null_space(instance.wrenches())


def symmetry(side) -> Subgroup:
    """The motions that map an element onto itself: the freedom of a mobile side."""
    g = side.geometry
    core = element(side.kind).core
    if core == "point":
        return Subgroup("S", g["c"], np.zeros(3))
    if core == "line":
        return Subgroup("C", g["p"], g["d"])
    return Subgroup("G3", g["q"], g["n"])


def _core_motions(instance: Instance) -> list[Subgroup]:
    """The motions that keep both contact loci where they are, as named subgroups.

    Computed as the free twists of the same contact with both sides fixed and
    recognised among the subgroups the geometry suggests: the spherical motion
    about the contact point, rotations about the normal and the line
    directions there, the translation along a contact line, the planar motion
    of a face.
    """
    o = instance.contact_point
    free = free_twists(instance)
    axes = [instance.normal] + [
        side["u"] for side in (instance.sensor, instance.fixture) if "u" in side.geometry
    ] + [side["d"] for side in (instance.sensor, instance.fixture) if "d" in side.geometry]
    candidates = [Subgroup("S", o, np.zeros(3)), Subgroup("G3", o, instance.normal)]
    for axis in axes:
        candidates += [Subgroup("R", o, axis), Subgroup("T1", o, axis)]
    dim = len(free)
    within = lambda group: matrix_rank(np.vstack([free, group.algebra()])) == dim
    for group in candidates:
        if group.algebra().shape[0] == dim and within(group):
            return [group]
    rotations = [g for g in candidates if g.kind == "R" and within(g)]
    for i, first in enumerate(rotations):
        for second in rotations[i + 1:]:
            if matrix_rank(np.vstack([first.algebra(), second.algebra()])) == dim == 2:
                return _line_side_outward([first, second], instance)
    raise ValueError(f"cannot name the fixed-fixed motions of {instance.ctype.name}")


def _line_side_outward(rotations, instance):
    """Order two rotations so that the line's own rotation stands on the line's side."""
    sensor_is_line = instance.sensor.kind == "L"
    line = instance.sensor if sensor_is_line else instance.fixture
    own = [g for g in rotations if abs(g.direction @ line["d"]) > 1 - 1e-9]
    other = [g for g in rotations if g not in own]
    return own + other if sensor_is_line else other + own


def compute_entry(ctype: ContactType, seed: int) -> CatalogueEntry:
    """Free motions, dimension, group representation and class of one contact."""
    instance = generic_instance(ctype, np.random.default_rng(seed))
    both_fixed_type = ContactType(ctype.sensor, True, ctype.fixture, True)
    both_fixed = generic_instance(both_fixed_type, np.random.default_rng(seed))
    chain = []
    if not ctype.sensor_fixed:
        chain.append(symmetry(instance.sensor))
    chain += _core_motions(both_fixed)
    if not ctype.fixture_fixed:
        chain.append(symmetry(instance.fixture))
    dim = len(free_twists(instance))
    return CatalogueEntry(ctype, dim, tuple(simplify(chain)), instance)


@cache
def catalogue() -> tuple[CatalogueEntry, ...]:
    """Tables I and III: every contact with its computed free motions."""
    return tuple(compute_entry(ctype, SEED + i) for i, ctype in enumerate(table_one()))


def classes() -> dict[str, list[CatalogueEntry]]:
    """Table IV: the contacts of each class, classes in the paper's order."""
    return {name: list(entries) for name, entries in _classes().items()}


@cache
def _classes() -> dict[str, tuple]:
    grouped = {name: [] for name in CLASSES}
    for entry in catalogue():
        grouped[entry.contact_class].append(entry)
    return {name: tuple(entries) for name, entries in grouped.items()}


def lookup(name: str) -> CatalogueEntry:
    """The catalogue entry of a contact name in either side order, e.g. ``PL/M-P/F``."""
    ctype = ContactType.parse(name)
    for entry in catalogue():
        if entry.ctype.canonical == ctype.canonical:
            return entry
    valid = ", ".join(entry.name for entry in catalogue())
    raise ValueError(f"{name!r} is not a contact of Table I; valid contacts: {valid}")
