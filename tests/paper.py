"""The paper's printed tables, read from tests/data (transcribed as printed, typos included)."""

import re
from pathlib import Path

DATA = Path(__file__).parent / "data"


def _rows(name):
    lines = [line.rstrip("\n") for line in (DATA / name).read_text().splitlines()]
    lines = [line for line in lines if line and not line.startswith("#")]
    header = lines[0].split("\t")
    return [dict(zip(header, line.split("\t"))) for line in lines[1:]]


def table_iii():
    """{contact: (printed group, printed dimension)}"""
    return {row["contact"]: (row["group"], int(row["dim"])) for row in _rows("paper_table_iii.tsv")}


def table_iv():
    """[(class, [contacts])] in printed order."""
    return [(row["class"], row["contacts"].split(",")) for row in _rows("paper_table_iv.tsv")]


def table_v():
    """Printed rows: dicts with page, column, class (as printed), count, members (None if garbled)."""
    from fixturecad.theory.catalogue import CLASSES

    out = []
    for row in _rows("paper_table_v.tsv"):
        members = re.findall(r"\{([^}]*)\}", row["class"])
        valid = all(m in CLASSES for m in members)
        out.append({
            "page": int(row["page"]),
            "column": int(row["column"]),
            "class": row["class"],
            "count": int(row["count"]),
            "members": tuple(sorted(members, key=CLASSES.index)) if valid else None,
        })
    return out
