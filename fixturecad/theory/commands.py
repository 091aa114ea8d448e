"""CLI: ``fixturecad contacts | catalog | analyze`` (the theory; never imports cadquery)."""

from typing import Annotated

import typer

from fixturecad.errors import InputError
from fixturecad.output import Format, render

app = typer.Typer()

FormatOption = Annotated[Format, typer.Option("--format", help="table, json, csv or md.")]


@app.command()
def contacts(fmt: FormatOption = Format.table):
    """Tables I, III and IV as computed: contact, elements, F/M, group, dimension, class, description."""
    from fixturecad.registration.elements import element
    from fixturecad.theory.catalogue import catalogue

    rows = []
    for entry in catalogue():
        c = entry.ctype
        rows.append({
            "contact": entry.name,
            "elements": f"{element(c.sensor).kind} - {element(c.fixture).kind}",
            "sides": f"{'F' if c.sensor_fixed else 'M'} - {'F' if c.fixture_fixed else 'M'}",
            "group": entry.group,
            "dim": entry.dim,
            "class": entry.contact_class,
            "description": entry.description,
        })
    typer.echo(render(rows, ["contact", "elements", "sides", "group", "dim", "class", "description"], fmt))


def _elements(text: str | None, option: str):
    from fixturecad.registration.elements import LETTERS

    if text is None:
        return None
    chosen = frozenset(part.strip().upper() for part in text.split(",") if part.strip())
    unknown = sorted(chosen - set(LETTERS))
    if unknown or not chosen:
        raise InputError(f"{option} takes elements from {', '.join(LETTERS)} separated by commas, got {text!r}")
    return chosen


@app.command()
def catalog(
    target_dim: Annotated[int, typer.Option(help="Freedoms left by each combination (0 locates the part).")] = 0,
    sensor: Annotated[str | None, typer.Option(help="Elements allowed on the sensor side, e.g. P or P,S.")] = None,
    fixture: Annotated[str | None, typer.Option(help="Elements allowed on the fixture side, e.g. PL,C.")] = None,
    mobile_only: Annotated[bool, typer.Option(help="Only contacts whose fixture side is mobile.")] = False,
    max_contacts: Annotated[int, typer.Option(help="Most contacts in a combination.")] = 6,
    expand: Annotated[bool, typer.Option(help="List the concrete contact combinations instead of classes.")] = False,
    fmt: FormatOption = Format.table,
):
    """Table V: minimal combinations of contact classes that locate the part (eq. 2)."""
    from fixturecad.theory.enumeration import Filters, enumerate_classes, expand as expand_combinations

    if max_contacts < 1:
        raise InputError(f"--max-contacts must be at least 1, got {max_contacts}")
    if not 0 <= target_dim <= 5:
        raise InputError(f"--target-dim must be between 0 and 5, got {target_dim}")
    filters = Filters(_elements(sensor, "--sensor"), _elements(fixture, "--fixture"), mobile_only)
    beyond_paper = target_dim != 0 or max_contacts > 6 or filters != Filters()
    with typer.progressbar(length=15, label="enumerating", file=_progress_stream(beyond_paper)) as bar:
        result = enumerate_classes(target_dim, max_contacts, filters, progress=lambda: bar.update(1))
    document = {
        "total_classes": len(result.found),
        "total_combinations": result.total_combinations,
        "target_dim": target_dim,
        "max_contacts": max_contacts,
        "shortcut_disagreements": result.shortcut_disagreements,
    }
    if expand:
        rows = [
            {"class": item.name, "contacts": list(names)}
            for item, names in expand_combinations(result)
        ]
        document["combinations"] = rows
        typer.echo(render(rows, ["class", "contacts"], fmt, document))
        return
    rows = [
        {"class": item.name, "members": list(item.members), "combinations": item.combinations,
         "verified": item.verified}
        for item in result.found
    ]
    document["classes"] = rows
    typer.echo(render(rows, ["class", "combinations", "verified"], fmt, document))
    if fmt is Format.table:
        typer.echo(f"{len(result.found)} classes, {result.total_combinations} combinations", err=True)


def _progress_stream(wanted: bool):
    """stderr for long work on a terminal; otherwise a sink."""
    import io
    import sys

    return sys.stderr if wanted and sys.stderr.isatty() else io.StringIO()


@app.command()
def analyze(
    names: Annotated[list[str], typer.Argument(help="Contacts, e.g. PL/F-PL/F P/F-S/M P/F-PL/M L/M-L/M; a label "
                                                    "after @ (P/F-PL/M@a) puts contacts on one fixture feature.")],
    target_dim: Annotated[int | None, typer.Option(help="Freedoms the contacts should leave (0 to 5).")] = None,
    fmt: FormatOption = Format.table,
):
    """Whether a set of contacts locates the part, and what freedom remains if not.

    With feature labels, sensor first (the cube's 3-2-1 is P/F-PL/M@a x3, P/F-PL/M@b x2, P/F-PL/M@c), the
    concrete structure is analysed: its mobility, redundant contacts, and the special positions that lose rank.
    """
    from fixturecad.theory.analysis import analyze as analyze_contacts

    try:
        result = analyze_contacts(names, target_dim)
    except ValueError as error:
        raise InputError(str(error)) from None
    if fmt is Format.json:
        typer.echo(render([], [], fmt, result.to_json()))
        return
    rows = [
        {"property": "class", "value": result.contact_class},
        {"property": "mobility", "value": result.mobility},
        {"property": "locates the part", "value": result.mobility == 0},
        {"property": "minimal", "value": result.minimal},
        {"property": "redundant", "value": ", ".join(result.redundant) or "none"},
        {"property": "in catalogue", "value": result.in_catalog},
    ] + [{"property": "free motion", "value": text} for text in result.freedom]
    rows += [{"property": "loses rank when", "value": text} for text in result.special_positions]
    if result.target is not None:
        rows.append({"property": "target", "value": result.target})
    typer.echo(render(rows, ["property", "value"], fmt))
