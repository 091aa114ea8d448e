"""Table V: the minimal combinations of contact classes that locate a part (eq. 2).

A multiset of classes locates the part when the constraint wrenches of
generic, randomly placed instances of its members have rank 6 (no free
motion is left), and it is minimal when removing any member lets the rank
drop. The search walks multisets in Table IV order and reuses the span of
each prefix: a member whose wrenches add nothing to its prefix would be
redundant in every extension, so that branch is cut, and a branch stops as
soon as its rank reaches the target. Every class found is checked again on
a second, independent set of random instances.
"""

from collections import Counter
from dataclasses import dataclass, field
from functools import cache
from math import comb

import numpy as np

from fixturecad.theory.catalogue import CLASSES, classes
from fixturecad.registration.mobility import matrix_rank, matrix_ranks
from fixturecad.theory.instances import generic_instance

SEARCH_SEED = 579
CHECK_SEED = 17460
SHORTCUT_SHARING = ("S", "G3")  # pairs of these share one freedom (Section IV)


@dataclass(frozen=True)
class Filters:
    """Which contacts the enumeration may use.

    ``sensor``/``fixture``: allowed elements on each side (None: any);
    ``mobile_only``: the fixture side of every contact is mobile (a passive,
    uninstrumented fixture).
    """

    sensor: frozenset | None = None
    fixture: frozenset | None = None
    mobile_only: bool = False

    def orient(self, ctype):
        """The contact written sensor first as the filters allow it (Table I's order when both
        orientations are allowed), or None."""
        for orientation in (ctype, ctype.swapped()):
            if self.sensor is not None and orientation.sensor not in self.sensor:
                continue
            if self.fixture is not None and orientation.fixture not in self.fixture:
                continue
            if self.mobile_only and orientation.fixture_fixed:
                continue
            return orientation
        return None

    def allows(self, ctype) -> bool:
        return self.orient(ctype) is not None


@dataclass
class CombinationClass:
    members: tuple[str, ...]
    combinations: int
    verified: bool

    @property
    def name(self) -> str:
        return "".join("{" + member + "}" for member in self.members)


@dataclass
class Enumeration:
    target_dim: int
    max_contacts: int
    filters: Filters
    found: list[CombinationClass] = field(default_factory=list)
    shortcut_disagreements: list[dict] = field(default_factory=list)
    contacts_by_class: dict = field(default_factory=dict)

    @property
    def total_combinations(self) -> int:
        return sum(item.combinations for item in self.found)


def allowed_contacts(filters: Filters) -> dict[str, list[str]]:
    """Contacts of each class that the filters allow, classes with none left out."""
    out = {}
    for name, entries in classes().items():
        names = [filters.orient(entry.ctype).name for entry in entries if filters.allows(entry.ctype)]
        if names:
            out[name] = names
    return out


def class_wrenches(seed: int, copies: int) -> dict[str, list[np.ndarray]]:
    """``copies`` independent random instances of each class, as wrench rows (k, 6)."""
    rng = np.random.default_rng(seed)
    members = classes()
    return {
        name: [generic_instance(members[name][i % len(members[name])].ctype, rng).wrenches()
               for i in range(copies)]
        for name in CLASSES
    }


def combinations_of(members, contacts_by_class) -> int:
    """Concrete contact combinations of a class multiset: multisets of contacts per class."""
    counts = Counter(members)
    total = 1
    for name, multiplicity in counts.items():
        n = len(contacts_by_class[name])
        total *= comb(n + multiplicity - 1, multiplicity)
    return total


def _orthonormal(rows):
    if len(rows) == 0:
        return np.zeros((0, 6))
    return np.linalg.svd(rows, full_matrices=False)[2][: matrix_rank(rows)]


def _is_minimal(blocks, target_rank) -> bool:
    """Whether leaving out any one block drops the rank below ``target_rank`` (one batched test)."""
    if len(blocks) < 2:
        return True
    rows = sum(len(block) for block in blocks)
    stack = np.zeros((len(blocks), rows, 6))
    for skip in range(len(blocks)):
        rest = np.vstack([block for i, block in enumerate(blocks) if i != skip])
        stack[skip, : len(rest)] = rest
    return bool(np.all(matrix_ranks(stack) < target_rank))


def locates_minimally(members, wrenches, target_rank=6) -> bool:
    """Whether instances of the class multiset reach ``target_rank`` and every member is needed.

    ``wrenches``: from :func:`class_wrenches`, with at least as many copies as
    any class repeats; the i-th copy of a class stands for its i-th member.
    """
    if any(members.count(name) > len(wrenches[name]) for name in members):
        return False
    blocks = [wrenches[name][members[:i].count(name)] for i, name in enumerate(members)]
    return matrix_rank(np.vstack(blocks)) == target_rank and _is_minimal(blocks, target_rank)


def _search(names, wrenches, target_rank, max_contacts, progress=None):
    """Minimal multisets (tuples of class names) whose wrench rank equals target_rank."""
    found = []

    def walk(start, basis, members, blocks):
        for index in range(start, len(names)):
            name = names[index]
            block = wrenches[name][members.count(name)]
            residual = block - (block @ basis.T) @ basis
            added = _orthonormal(residual)
            if len(added) == 0:
                continue
            grown = np.vstack([basis, added])
            chosen, stack = members + [name], blocks + [block]
            if len(grown) == target_rank:
                if _is_minimal(stack, target_rank):
                    found.append(tuple(chosen))
            elif len(grown) < target_rank and len(chosen) < max_contacts:
                walk(index, grown, chosen, stack)
            if progress is not None and not members:
                progress()

    walk(0, np.zeros((0, 6)), [], [])
    return found


@cache
def _class_dims() -> dict:
    return {name: entries[0].dim for name, entries in classes().items()}


def _shortcut_rank(members) -> int:
    """The paper's count: six minus freedom per member, less one per sharing pair."""
    total = sum(6 - _class_dims()[m] for m in members)
    sharing = sum(1 for m in members if m in SHORTCUT_SHARING)
    return total - sharing * (sharing - 1) // 2


def _shortcut_search(names, target_rank, max_contacts):
    """Minimal multisets by the paper's counting rule, for comparison with the rank."""
    found = []

    def walk(start, members):
        for index in range(start, len(names)):
            chosen = members + [names[index]]
            count = _shortcut_rank(chosen)
            if count >= target_rank:
                if all(_shortcut_rank(chosen[:i] + chosen[i + 1:]) < target_rank for i in range(len(chosen))):
                    found.append(tuple(chosen))
            elif len(chosen) < max_contacts:
                walk(index, chosen)

    walk(0, [])
    return found


def enumerate_classes(
    target_dim: int = 0, max_contacts: int = 6, filters: Filters = Filters(), progress=None
) -> Enumeration:
    """Table V (``target_dim`` 0) or its analogue leaving ``target_dim`` freedoms."""
    contacts_by_class = allowed_contacts(filters)
    names = [name for name in CLASSES if name in contacts_by_class]
    target_rank = 6 - target_dim
    copies = min(max_contacts, target_rank)
    search = class_wrenches(SEARCH_SEED, copies)
    check = class_wrenches(CHECK_SEED, copies)
    result = Enumeration(target_dim, max_contacts, filters, contacts_by_class=contacts_by_class)
    for members in _search(names, search, target_rank, max_contacts, progress):
        verified = locates_minimally(members, check, target_rank)
        result.found.append(CombinationClass(members, combinations_of(members, contacts_by_class), verified))
    if target_dim == 0:
        by_rank = {item.members for item in result.found}
        by_count = set(_shortcut_search(names, target_rank, max_contacts))
        for members in sorted(by_rank ^ by_count, key=lambda m: [CLASSES.index(x) for x in m]):
            result.shortcut_disagreements.append(
                {
                    "class": "".join("{" + m + "}" for m in members),
                    "rank_says": "minimal and complete" if members in by_rank else "not minimal or not complete",
                    "count_says": "minimal and complete" if members in by_count else "not minimal or not complete",
                }
            )
    return result


def expand(enumeration: Enumeration):
    """Every concrete contact combination of every class, as tuples of contact names."""
    from itertools import combinations_with_replacement, product

    for item in enumeration.found:
        counts = Counter(item.members)
        per_class = [
            combinations_with_replacement(enumeration.contacts_by_class[name], counts[name])
            for name in sorted(counts, key=CLASSES.index)
        ]
        for choice in product(*per_class):
            yield item, tuple(contact for group in choice for contact in group)


def class_of_contacts(names) -> tuple[str, ...]:
    """The class multiset of concrete contacts, in Table IV order."""
    from fixturecad.theory.catalogue import lookup

    members = [lookup(name).contact_class for name in names]
    return tuple(sorted(members, key=CLASSES.index))

