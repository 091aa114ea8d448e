"""CLI: ``fixturecad build | templates | suggest`` (fixture templates to files).

Template parameters differ per template, so ``build`` takes them as extra
``--name value`` options and checks them itself. cadquery is imported only
when a build runs.
"""

import re
from pathlib import Path
from typing import Annotated

import typer

from fixturecad.build import DEFAULT_STL_TOLERANCE_MM, STL_TOLERANCE_RANGE_MM
from fixturecad.registration.defaults import DEFAULT_ZONE_MM
from fixturecad.errors import InputError
from fixturecad.output import Format, render

app = typer.Typer()

FormatOption = Annotated[Format, typer.Option("--format", help="table, json, csv or md.")]
MAX_CLASS_MEMBERS = 64  # bounds what a typed "x1000000000" can ask for
CLASS_TOKEN = re.compile(r"\{([A-Z0-9-]+)\}(?:\s*[x*]\s*(\d+))?")


def parse_template_options(template_name: str, args: list[str]) -> dict:
    """``["--radius", "40", "--angle=45"]`` -> ``{"radius": "40", "angle": "45"}``; InputError on anything else."""
    from fixturecad.templates import get_template

    cls = get_template(template_name)
    valid = ", ".join("--" + p.name for p in cls.PARAMS)
    values, index = {}, 0
    while index < len(args):
        token = args[index]
        if not token.startswith("--") or len(token) == 2:
            raise InputError(f"unexpected argument {token!r} for template {template_name}; its parameters: {valid}")
        name, eq, value = token[2:].partition("=")
        if not eq:
            if index + 1 >= len(args) or (args[index + 1].startswith("--") and len(args[index + 1]) > 2):
                raise InputError(f"--{name} needs a value")
            value, index = args[index + 1], index + 1
        cls.param(name)  # InputError listing the valid parameters
        if name in values:
            raise InputError(f"--{name} given twice")
        values[name] = value
        index += 1
    return values


def template_parameters() -> str:
    """Each template's parameters with units, defaults and ranges: the epilog of ``build --help``."""
    from fixturecad.templates import TEMPLATES

    lines = ["Templates and their parameters (default, range):"]
    for cls in TEMPLATES.values():
        lines.append(f"{cls.name}: " + ", ".join(f"--{p.name} {p.default:g} {p.unit} ({p.minimum:g}..{p.maximum:g})"
                                                 for p in cls.PARAMS))
    return "\n\n".join(lines)


@app.command(context_settings={"allow_extra_args": True, "ignore_unknown_options": True}, epilog=template_parameters())
def build(
    ctx: typer.Context,
    template: Annotated[str, typer.Argument(help="Template name (see `fixturecad templates`).")],
    out: Annotated[Path | None, typer.Option(help="Output folder.", show_default="out/<template>-<parameters>")] = None,
    force: Annotated[bool, typer.Option(help="Replace the output folder if fixturecad wrote it.")] = False,
    base: Annotated[bool, typer.Option(help="Fuse a mounting base (stem and plate) onto a non-sensing face.")] = False,
    stl_tolerance: Annotated[float, typer.Option(
        help=f"STL chord tolerance, mm ({STL_TOLERANCE_RANGE_MM[0]:g} .. {STL_TOLERANCE_RANGE_MM[1]:g}).")
    ] = DEFAULT_STL_TOLERANCE_MM,
    fixture_tolerance: Annotated[float, typer.Option(
        help="Manufacturing tolerance of the printed part, mm: the width of the profile zone every sensing "
             "point lies in (0: an exact part). Recorded in features.json; registration allows for it.")
    ] = DEFAULT_ZONE_MM,
):
    """Build a fixture: fixture.step, fixture.stl, features.json, preview.png and a standalone register.py.

    Template parameters follow as options, e.g. `fixturecad build quarter-sphere --radius 40`.
    """
    from fixturecad.build import build as build_fixture, check_fixture_tolerance, check_stl_tolerance, default_target
    from fixturecad.templates import make

    values = parse_template_options(template, list(ctx.args))
    check_stl_tolerance(stl_tolerance)
    check_fixture_tolerance(fixture_tolerance)
    fixture = make(template, base=base, **values)
    target = out if out is not None else default_target(fixture)
    typer.echo(str(build_fixture(fixture, target, force=force, stl_tolerance=stl_tolerance,
                                 fixture_tolerance=fixture_tolerance)))


@app.command()
def templates(fmt: FormatOption = Format.table):
    """Fixture templates: parameters with units, defaults and ranges, and the classes they realise."""
    from fixturecad.templates import TEMPLATES

    rows, document = [], []
    for cls in TEMPLATES.values():
        plans = {name: plan.contact_class for name, plan in cls().touch_plans().items()}
        params = [{"name": p.name, "unit": p.unit, "default": p.default, "min": p.minimum, "max": p.maximum,
                   "help": p.help} for p in cls.PARAMS]
        document.append({"template": cls.name, "title": cls.title, "origin": cls.origin,
                         "contact_class": cls.contact_class, "plans": plans, "parameters": params})
        plan_rows = list(plans.items())
        for index in range(max(len(cls.PARAMS), len(plan_rows))):
            p = cls.PARAMS[index] if index < len(cls.PARAMS) else None
            plan, plan_class = plan_rows[index] if index < len(plan_rows) else ("", "")
            rows.append({
                "template": cls.name if index == 0 else "",
                "parameter": f"--{p.name}" if p else "",
                "unit": p.unit if p else "",
                "default": f"{p.default:g}" if p else "",
                "range": f"{p.minimum:g}..{p.maximum:g}" if p else "",
                "plan": plan,
                "class": plan_class,
                "origin": cls.origin if index == 0 else "",
            })
    columns = ["template", "parameter", "unit", "default", "range", "plan", "class", "origin"]
    typer.echo(render(rows, columns, fmt, document))


def class_members(text: str) -> tuple:
    """``"{G3}{S-S}"`` or ``"{S-C}x3 {S-T2}x3"`` -> sorted member tuple; InputError if unreadable."""
    from fixturecad.theory.catalogue import CLASSES

    cleaned = text.strip()
    members, position = [], 0
    for match in CLASS_TOKEN.finditer(cleaned):
        if cleaned[position : match.start()].strip():
            break
        count = int(match.group(2) or 1)
        if len(members) + count > MAX_CLASS_MEMBERS:
            raise InputError(f"class {text!r} has more than {MAX_CLASS_MEMBERS} contacts; "
                             "a locating combination needs at most 6 (Table V), a plan a few more")
        members += [match.group(1)] * count
        position = match.end()
    if not members or cleaned[position:].strip():
        raise InputError(f"cannot read class {text!r}: write it like {{G3}}{{S-S}}{{S-T2}}{{C-R-C}} or {{S-C}}x3{{S-T2}}x3")
    unknown = sorted(set(members) - set(CLASSES))
    if unknown:
        raise InputError(f"unknown class {', '.join(unknown)}; Table IV classes: {', '.join(CLASSES)}")
    return tuple(sorted(members, key=CLASSES.index))


def table_five_class(text: str) -> tuple:
    """The members of a class of Table V (a minimal locating class); InputError, the one reason suggest and
    design give, if it is not one."""
    from fixturecad.design.combination import in_table_five

    members = class_members(text)
    if not in_table_five(members):
        raise InputError(f"{text} is not a class of Table V: it does not locate the part minimally")
    return members


@app.command()
def suggest(
    contact_class: Annotated[str, typer.Argument(help='Catalogue class, e.g. "{G3}{S-S}{S-T2}{C-R-C}".')],
    fmt: FormatOption = Format.table,
):
    """Templates (with parameters and plan) that realise a catalogue class."""
    from fixturecad.templates import TEMPLATES

    wanted = class_members(contact_class)
    rows = []
    for cls in TEMPLATES.values():
        fixture = cls()
        for name, plan in fixture.touch_plans().items():
            if class_members(plan.contact_class) != wanted:
                continue
            options = " ".join(f"--{p.name} {p.default:g}" for p in cls.PARAMS)
            rows.append({"template": cls.name, "plan": name, "class": plan.contact_class,
                         "build": f"fixturecad build {cls.name} {options}", "note": plan.note})
    if not rows:  # no template realises it: a designed fixture, if it is a class design takes
        name = "".join("{" + member + "}" for member in table_five_class(contact_class))
        rows.append({"template": "design", "plan": "default", "class": name,
                     "build": f'fixturecad design --class "{name}"', "note": "no template realises it: a designed fixture"})
    typer.echo(render(rows, ["template", "plan", "class", "build", "note"], fmt))
