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
from fixturecad.theory.groups import Subgroup
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
    """Name the free motions left by stacked constraint rows, shape (k, 6)."""
    free = null_space(wrenches)
    dim = len(free)
    within = lambda group: matrix_rank(np.vstack([free, group.algebra()])) == dim
    points, lines = named_entities(instances)
    candidates = [(f"spherical motion about {name}", Subgroup("S", p, np.zeros(3))) for name, p in points.items()]
    for name, (p, d) in lines.items():
        candidates += [
            (f"cylindrical motion along {name}", Subgroup("C", p, d)),
            (f"rotation about {name}", Subgroup("R", p, d)),
            (f"translation along {name}", Subgroup("T1", p, d)),
        ]
    for axis, label in zip(np.eye(3), "xyz"):
        candidates.append((f"translation along {label}", Subgroup("T1", np.zeros(3), axis)))
    words, covered = [], np.zeros((0, 6))
    for text, group in candidates:
        if within(group) and matrix_rank(np.vstack([covered, group.algebra()])) > len(covered):
            words.append(text)
            covered = np.vstack([covered, group.algebra()])
            covered = np.linalg.svd(covered, full_matrices=False)[2][: matrix_rank(covered)]
        if len(covered) == dim:
            return words
    # What the named geometry cannot explain: give the screws of the remaining twists.
    remaining = free - (free @ covered.T) @ covered if len(covered) else free
    for twist in np.linalg.svd(remaining, full_matrices=False)[2][: dim - len(covered)]:
        words.append(_screw_words(twist))
    return words


def _screw_words(twist) -> str:
    w, v = twist[:3], twist[3:]
    if np.linalg.norm(w) < 1e-9:
        d = v / np.linalg.norm(v)
        return f"translation along ({d[0]:.3f}, {d[1]:.3f}, {d[2]:.3f})"
    pitch = w @ v / (w @ w)
    point = np.cross(w, v) / (w @ w)
    d = w / np.linalg.norm(w)
    return (
        f"screw motion of pitch {pitch:.3f} mm/rad about the axis through "
        f"({point[0]:.1f}, {point[1]:.1f}, {point[2]:.1f}) mm along ({d[0]:.3f}, {d[1]:.3f}, {d[2]:.3f})"
    )
