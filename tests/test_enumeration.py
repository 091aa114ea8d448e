"""Table V: totals, verification by rank, filters, target dimensions, expansion."""

from collections import Counter
from itertools import combinations_with_replacement

import numpy as np
import pytest

from fixturecad.theory.catalogue import catalogue
from fixturecad.theory.enumeration import Filters, class_of_contacts, enumerate_classes, expand
from fixturecad.theory.instances import generic_instance


@pytest.fixture(scope="module")
def table_v():
    return enumerate_classes()


def test_totals_match_the_paper(table_v):
    assert len(table_v.found) == 579
    assert table_v.total_combinations == 17460


def test_every_class_is_verified_on_independent_instances(table_v):
    assert all(item.verified for item in table_v.found)


def test_the_counting_shortcut_agrees_with_the_rank(table_v):
    assert table_v.shortcut_disagreements == []


def test_the_worked_examples_are_classes_with_their_printed_counts(table_v):
    counts = {item.name: item.combinations for item in table_v.found}
    assert counts["{G3}{S-S}{S-T2}{C-R-C}"] == 36  # Example One
    assert counts["{S-C}{S-C}{S-C}{S-T2}{S-T2}{S-T2}"] == 40  # Example Two
    assert counts["{S-T2}{S-T2}{S-T2}{S-T2}{S-T2}{S-T2}"] == 7  # Fig. 1, the cube


def test_more_than_six_contacts_are_allowed_and_add_nothing_minimal(table_v):
    wide = enumerate_classes(max_contacts=9)
    assert [i.members for i in wide.found] == [i.members for i in table_v.found]


def test_four_lines_on_a_cylinder_leave_two_freedoms():
    result = enumerate_classes(target_dim=2)
    names = {item.name for item in result.found}
    assert "{C-R-C}{C-R-C}{C-R-C}{C-R-C}" in names
    assert "{C-R-C}{C-R-C}{C-R-C}" not in names


def _brute_force(filters, max_contacts=6):
    """Independent count: every multiset of allowed concrete contacts, rank on fresh instances."""
    allowed = [e for e in catalogue() if filters.allows(e.ctype)]
    rng = np.random.default_rng(99)
    total = 0
    for size in range(1, max_contacts + 1):
        for combo in combinations_with_replacement(allowed, size):
            blocks = [generic_instance(e.ctype, rng).wrenches() for e in combo]
            if np.linalg.matrix_rank(np.vstack(blocks)) < 6:
                continue
            if all(np.linalg.matrix_rank(np.vstack(blocks[:i] + blocks[i + 1:])) < 6 for i in range(size)):
                total += 1
    return total


def test_point_probe_on_planes_and_cylinders_matches_brute_force():
    filters = Filters(sensor=frozenset({"P"}), fixture=frozenset({"PL", "C"}))
    result = enumerate_classes(filters=filters)
    assert result.contacts_by_class == {"S": ["P/F-PL/F", "P/F-C/F"], "S-C": ["P/F-C/M"], "S-T2": ["P/F-PL/M"]}
    assert result.total_combinations == _brute_force(filters)


def test_passive_fixture_for_a_point_probe_is_points_on_surfaces():
    result = enumerate_classes(filters=Filters(sensor=frozenset({"P"}), mobile_only=True))
    assert set(result.contacts_by_class) == {"S-S", "S-T1", "S-C", "S-T2"}
    # Six single-freedom touches, or five with a point on a line taking two.
    assert all(sum(1 for m in i.members if m != "S-T1") + 2 * i.members.count("S-T1") == 6 for i in result.found)


def test_expand_lists_every_combination_once():
    result = enumerate_classes(filters=Filters(sensor=frozenset({"P"}), fixture=frozenset({"PL", "C"})))
    rows = list(expand(result))
    assert len(rows) == result.total_combinations
    assert len({tuple(sorted(c)) for _, c in rows}) == len(rows)
    for item, contacts in rows:
        assert class_of_contacts(contacts) == item.members


def test_expanded_quarter_sphere_plan_is_in_its_class():
    assert class_of_contacts(["PL/F-PL/F", "P/F-S/M", "P/F-PL/M", "L/M-L/M"]) == ("G3", "S-S", "S-T2", "C-R-C")
    assert Counter(class_of_contacts(["P/F-PL/M"] * 3)) == Counter({"S-T2": 3})
