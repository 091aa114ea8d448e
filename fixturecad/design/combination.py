"""What a design realises: contacts written sensor first, each on a labelled fixture feature.

``P/F-PL/M@a P/F-PL/M@a S/M-S/M@b``: contacts with one label touch one
fixture element (the side written second). A class of Table V is realised by
one contact of each of its members, in the orientation a touch plan can make
with the sensors of a cell: a point probe first, then a ball tip, a plane, a
line, a cylinder, on the fixture's faces, balls, bosses and edges.
"""

import re
from dataclasses import dataclass

from fixturecad.errors import InputError
from fixturecad.registration.contacts import ContactType
from fixturecad.design.layout import FEATURE_NAMES
from fixturecad.theory.catalogue import CLASSES, classes, lookup
from fixturecad.theory.structure import parse_labelled

SENSOR_PREFERENCE = ("P", "S", "PL", "L", "C")  # what a cell most likely holds first
FIXTURE_PREFERENCE = ("PL", "S", "C", "L", "P")  # what prints best first
LABEL = re.compile(r"^[a-z][a-z0-9_]{0,30}$")  # a features.json id


@dataclass
class Combination:
    """Contacts (sensor first) with the feature id each touches, and the class they make."""

    contacts: list
    labels: list

    @property
    def members(self) -> list:
        return sorted((lookup(c.name).contact_class for c in self.contacts), key=CLASSES.index)

    @property
    def contact_class(self) -> str:
        return "".join("{" + m + "}" for m in self.members)

    def tokens(self) -> list:
        return [f"{c.name}@{label}" for c, label in zip(self.contacts, self.labels)]


def plan_gap(ctype: ContactType) -> str:
    """Why a touch plan cannot make this contact ('' when it can)."""
    if ctype.is_locus and ctype.fixture == "PL" and ctype.fixture_fixed and ctype.sensor != "PL":
        return (f"{ctype.name}: a touch plan cannot say where on the fixture's face the contact line lies; "
                f"write it {ctype.swapped().name} (the plane as the sensor) or with the face mobile")
    return ""


def parse(tokens) -> Combination:
    """``["P/F-PL/M@a", "S/M-S/M"]`` -> Combination; InputError (one line) for anything unreadable
    (:func:`~fixturecad.theory.structure.parse_labelled`). An unlabelled contact gets a feature of its own."""
    if not tokens:
        raise InputError("give contacts (e.g. P/F-PL/M@a) or --class")
    try:
        parsed = parse_labelled(tokens)
        for ctype, _ in parsed:
            lookup(ctype.name)
    except ValueError as error:
        raise InputError(str(error).split("; valid")[0]) from None
    labels = []
    for number, (ctype, label) in enumerate(parsed, start=1):
        if label is not None and not LABEL.match(label):
            raise InputError(f"cannot read label {label!r}: a lower-case letter, then lower-case letters, digits or _ "
                             "(it names the feature in features.json)")
        if plan_gap(ctype):
            raise InputError(plan_gap(ctype))
        labels.append(label or f"{FEATURE_NAMES[ctype.fixture]}_{number}")
    return Combination([ctype for ctype, _ in parsed], labels)


def preferred_contact(member: str) -> ContactType:
    """The contact of a Table IV class a design uses: the handiest sensor on the handiest feature."""
    options = []
    for entry in classes()[member]:
        for ctype in (entry.ctype, entry.ctype.swapped()):
            if not plan_gap(ctype):
                options.append((SENSOR_PREFERENCE.index(ctype.sensor), FIXTURE_PREFERENCE.index(ctype.fixture),
                                not ctype.sensor_fixed, ctype.fixture_fixed, ctype.name, ctype))
    return min(options)[-1]


def for_class(members) -> Combination:
    """One combination of the class ``members`` (Table IV names), each contact on its own feature."""
    contacts = [preferred_contact(member) for member in members]
    return Combination(contacts, [f"{FEATURE_NAMES[c.fixture]}_{n}" for n, c in enumerate(contacts, start=1)])


def in_table_five(members) -> bool:
    """Whether the class locates the part minimally (Table V's own test)."""
    from fixturecad.theory.enumeration import SEARCH_SEED, class_wrenches, locates_minimally

    return len(members) <= 6 and locates_minimally(list(members), class_wrenches(SEARCH_SEED, 6))
