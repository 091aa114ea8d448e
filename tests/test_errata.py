"""docs/errata.md against the computation: every listed row is wrong in print, every other printed row is right."""

import re
from collections import Counter
from pathlib import Path

import pytest

from fixturecad.theory.catalogue import CLASSES
from fixturecad.theory.enumeration import enumerate_classes
from paper import table_v

ERRATA = Path(__file__).parents[1] / "docs" / "errata.md"


def _errata_rows():
    rows = []
    for line in ERRATA.read_text().splitlines():
        match = re.match(r"\| (\d) \| (\d) \| `([^`]*)` \| (\d+) \| ([^|]+) \| `([^`]*)` \|", line)
        if match:
            page, column, printed, count, kind, corrected = match.groups()
            members = tuple(sorted(re.findall(r"\{([^}]*)\}", corrected), key=CLASSES.index))
            rows.append(((int(page), int(column), printed, int(count)), kind.strip(), members))
    return rows


@pytest.fixture(scope="module")
def computed():
    return {item.members: item.combinations for item in enumerate_classes().found}


def test_printed_totals_are_right(computed):
    printed = table_v()
    assert len(printed) == 579 == len(computed)
    assert sum(row["count"] for row in printed) == 17460 == sum(computed.values())


def test_every_printed_row_is_right_unless_listed(computed):
    # A row printed twice in the same place is listed once: one copy is right.
    listed = Counter(key for key, _, _ in _errata_rows())
    right = 0
    for row in table_v():
        key = (row["page"], row["column"], row["class"], row["count"])
        if listed[key]:
            listed[key] -= 1
            continue
        assert computed.get(row["members"]) == row["count"], row
        right += 1
    assert right == 579 - 19


def test_every_listed_row_is_wrong_in_print_and_right_as_corrected(computed):
    rows = _errata_rows()
    assert len(rows) == 19
    printed_right = {row["members"] for row in table_v() if computed.get(row["members"]) == row["count"]}
    corrections = [members for _, _, members in rows]
    for (_, _, printed, count), kind, corrected in rows:
        assert computed[corrected] == count
        assert corrected not in printed_right
        members = re.findall(r"\{([^}]*)\}", printed)
        if kind == "garbled class name":
            assert not all(m in CLASSES for m in members)
        elif kind == "printed twice":
            assert sum(1 for r in table_v() if r["class"] == printed) == 2
        else:
            assert tuple(sorted(members, key=CLASSES.index)) not in computed
    # Right rows and corrections together name every computed class exactly once.
    assert sorted(map(str, printed_right | set(corrections))) == sorted(map(str, computed))
    assert len(set(corrections)) == len(corrections)
