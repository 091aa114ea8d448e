"""CLI: ``fixturecad design``, a printable fixture for any catalogue combination or class."""

from pathlib import Path
from typing import Annotated

import typer

from fixturecad.design import DEFAULT_BALL_MM, DEFAULT_SIZE_MM, DESIGN_SEED
from fixturecad.errors import InputError

app = typer.Typer()


@app.command()
def design(
    contacts: Annotated[list[str] | None, typer.Argument(
        help="Contacts, sensor first, each with an optional @LABEL: contacts with one label touch one "
             "fixture feature, e.g. P/F-PL/M@a P/F-PL/M@a P/F-PL/M@a P/F-PL/M@b P/F-PL/M@b P/F-PL/M@c.",
        show_default=False)] = None,
    contact_class: Annotated[str | None, typer.Option(
        "--class", help='A class of Table V instead, e.g. "{S-S}x3 {S-T2}x3": a combination of it is chosen.')] = None,
    size: Annotated[float, typer.Option(help="Side of the base block, mm.")] = DEFAULT_SIZE_MM,
    sensor_ball: Annotated[float, typer.Option(help="Radius of ball and cylinder sensors, mm.")] = DEFAULT_BALL_MM,
    out: Annotated[Path | None, typer.Option(help="Output folder.", show_default="out/design-<class>-s<size>")] = None,
    force: Annotated[bool, typer.Option(help="Replace the output folder if fixturecad wrote it.")] = False,
    seed: Annotated[int, typer.Option(min=0, help="Seed of the layout search (0 or more).")] = DESIGN_SEED,
):
    """Design and build a fixture that realises a contact combination: what `build` writes, and the
    combination and class in features.json."""
    from fixturecad.build import build, default_target
    from fixturecad.design.combination import for_class, parse
    from fixturecad.design.fixture import design as make_design
    from fixturecad.fixture_commands import table_five_class

    if bool(contacts) == (contact_class is not None):
        raise InputError("give either contacts (e.g. P/F-PL/M@a ...) or --class, not both or neither")
    combination = parse(contacts) if contacts else for_class(table_five_class(contact_class))
    fixture = make_design(combination, size, sensor_ball, seed)
    target = out if out is not None else default_target(fixture)
    typer.echo(str(build(fixture, target, force=force)))
    typer.echo(f"{fixture.contact_class}: {' '.join(combination.tokens())}")
