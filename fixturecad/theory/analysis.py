"""Does a set of contacts locate the part, and what freedom is left if not.

Each contact is placed at random (generic placement, as in the paper); the
stacked constraint rows give the mobility, the redundant contacts and the
free twists, which are then described with the named points and lines of the
contacts: "rotation about the line through the two sphere centres".
"""

from dataclasses import dataclass
import numpy as np

from fixturecad.theory.catalogue import CLASSES, lookup
from fixturecad.theory.enumeration import SEARCH_SEED, class_wrenches, locates_minimally
from fixturecad.registration.mobility import matrix_rank, null_space
from fixturecad.registration.motions import free_motion_names
from fixturecad.theory.instances import generic_instance, named_entities

ANALYSIS_SEED = 8


@dataclass
class Analysis:
    contacts: list[str]
    members: list[str]
    mobility: int
    minimal: bool
    redundant: list[str]
    in_catalog: bool
    freedom: list[str]

    @property
    def contact_class(self) -> str:
        return "".join("{" + m + "}" for m in self.members)

    def to_json(self) -> dict:
        return {
            "contacts": self.contacts,
            "class": self.contact_class,
            "members": self.members,
            "mobility": self.mobility,
            "minimal": self.minimal,
            "redundant": self.redundant,
            "in_catalog": self.in_catalog,
            "freedom": self.freedom,
        }


def analyze(names: list[str]) -> Analysis:
    """Analyse contacts given by name (either side order), e.g. ``["PL/F-PL/F", "P/F-S/M"]``.

    Raises ValueError for an unknown contact, naming the valid ones.
    """
    entries = [lookup(name) for name in names]
    rng = np.random.default_rng(ANALYSIS_SEED)
    instances = [generic_instance(entry.ctype, rng) for entry in entries]
    blocks = [instance.wrenches() for instance in instances]
    rank = matrix_rank(np.vstack(blocks))
    redundant = [
        entries[i].name
        for i in range(len(blocks))
        if matrix_rank(np.vstack(blocks[:i] + blocks[i + 1:] or [np.zeros((1, 6))])) == rank
    ]
    members = sorted((entry.contact_class for entry in entries), key=CLASSES.index)
    mobility = 6 - rank
    return Analysis(
        contacts=[entry.name for entry in entries],
        members=members,
        mobility=mobility,
        minimal=mobility == 0 and not redundant,
        redundant=redundant,
        # Table V's own test, on the instances its search uses.
        in_catalog=locates_minimally(members, class_wrenches(SEARCH_SEED, 6)),
        freedom=describe_freedom(np.vstack(blocks), instances) if mobility else [],
    )


def describe_freedom(wrenches: np.ndarray, instances) -> list[str]:
    """Name the free motions left by stacked constraint rows, shape (k, 6), after the contacts' geometry."""
    points, lines = named_entities(instances)
    return free_motion_names(null_space(wrenches), points, lines)
