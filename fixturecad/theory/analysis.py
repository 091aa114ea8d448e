"""Does a set of contacts locate the part, and what freedom is left if not.

Each contact is placed at random (generic placement, as in the paper); the
stacked constraint rows give the mobility, the redundant contacts and the
free twists, which are then described with the named points and lines of the
contacts: "rotation about the line through the two sphere centres". Contacts
with a feature label (``P/F-PL/M@a``) share that fixture element: the
concrete structure (:mod:`.structure`) gives the mobility, the special
positions that lose rank and, for one feature, whether the freedom is its
own symmetry.
"""

from dataclasses import dataclass, field
import numpy as np

from fixturecad.theory.catalogue import CLASSES, lookup
from fixturecad.theory.enumeration import SEARCH_SEED, class_wrenches, locates_minimally
from fixturecad.registration.mobility import matrix_rank, null_space
from fixturecad.registration.motions import free_motion_names
from fixturecad.theory.instances import generic_instance, named_entities
from fixturecad.theory.structure import Structure, parse_labelled

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
    special_positions: list[str] = field(default_factory=list)
    target: str | None = None  # whether the freedom is what --target-dim or the one feature asks for

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
            "special_positions": self.special_positions,
            "target": self.target,
        }


def analyze(names: list[str], target_dim: int | None = None) -> Analysis:
    """Analyse contacts given by name (either side order), e.g. ``["PL/F-PL/F", "P/F-S/M"]``, or with
    feature labels, sensor first (``["P/F-PL/M@a", ...]``).

    Raises ValueError for an unknown contact, naming the valid ones, or contradictory labels.
    """
    if target_dim is not None and not 0 <= target_dim <= 5:
        raise ValueError(f"--target-dim must be 0 to 5 freedoms, got {target_dim}")
    if any("@" in name for name in names):
        return _analyze_structure(names, target_dim)
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
        target=None if target_dim is None else _dimension_words(mobility, target_dim),
    )


def _analyze_structure(names, target_dim) -> Analysis:
    parsed = parse_labelled(names)
    entries = [lookup(ctype.name) for ctype, _ in parsed]
    structure = Structure.generic(parsed)
    mobility = structure.mobility()
    redundant = [names[k] for k in structure.redundant()]
    members = sorted((entry.contact_class for entry in entries), key=CLASSES.index)
    target = None if target_dim is None else _dimension_words(mobility, target_dim)
    if len(structure.features) == 1 and mobility:
        label = next(iter(structure.features))
        exact, words = structure.is_symmetry_of(label)
        target = (f"the freedom is exactly the symmetry of {label}: {words}" if exact
                  else f"the freedom is not the symmetry of {label} ({words})")
    return Analysis(
        contacts=list(names),
        members=members,
        mobility=mobility,
        minimal=mobility == 0 and not redundant,
        redundant=redundant,
        in_catalog=locates_minimally(members, class_wrenches(SEARCH_SEED, 6)),
        freedom=structure.freedom() if mobility else [],
        special_positions=structure.special_positions(),
        target=target,
    )


def _dimension_words(mobility, target_dim) -> str:
    if mobility == target_dim:
        return f"leaves {target_dim} freedoms, as asked"
    return f"leaves {mobility} freedoms, not the {target_dim} asked"


def describe_freedom(wrenches: np.ndarray, instances) -> list[str]:
    """Name the free motions left by stacked constraint rows, shape (k, 6), after the contacts' geometry."""
    points, lines = named_entities(instances)
    return free_motion_names(null_space(wrenches), points, lines)
