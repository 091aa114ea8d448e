"""Listings in the four formats every listing command offers: table, json, csv, md."""

import csv
import io
import json
from enum import Enum


class Format(str, Enum):
    table = "table"
    json = "json"
    csv = "csv"
    md = "md"


def render(rows: list[dict], columns: list[str], fmt: Format, document=None) -> str:
    """Rows (dicts keyed by column) as text; ``document`` is what json prints instead of rows."""
    if fmt is Format.json:
        return json.dumps(rows if document is None else document, indent=2)
    cells = [[_cell(row.get(column, "")) for column in columns] for row in rows]
    if fmt is Format.csv:
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows(cells)
        return out.getvalue().rstrip("\n")
    if fmt is Format.md:
        lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
        lines += ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in cells]
        return "\n".join(lines)
    widths = [max(len(column), *(len(row[i]) for row in cells)) if cells else len(column)
              for i, column in enumerate(columns)]
    line = lambda values: "  ".join(v.ljust(w) for v, w in zip(values, widths)).rstrip()
    return "\n".join([line(columns), line(["-" * w for w in widths])] + [line(row) for row in cells])


def _cell(value) -> str:
    if isinstance(value, (list, tuple)):
        return " ".join(str(v) for v in value)
    if isinstance(value, bool):
        return "yes" if value else "no"
    return str(value)
