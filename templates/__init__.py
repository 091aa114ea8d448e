"""Fixture templates: one module per family, registered in ``TEMPLATES`` by name."""

from fixturecad.errors import InputError
from fixturecad.templates.base import Template
from fixturecad.templates.cube import Cube
from fixturecad.templates.inclined_plane_cylinder import InclinedPlaneCylinder
from fixturecad.templates.quarter_sphere import QuarterSphere
from fixturecad.templates.sphere_plate import SpherePlate
from fixturecad.templates.v_block import VBlock

TEMPLATES: dict[str, type[Template]] = {
    cls.name: cls for cls in (Cube, QuarterSphere, InclinedPlaneCylinder, SpherePlate, VBlock)
}


def get_template(name: str) -> type[Template]:
    """The template class called ``name``; InputError listing the valid names otherwise."""
    try:
        return TEMPLATES[name]
    except KeyError:
        raise InputError(f"unknown template {name!r}; choose from {', '.join(TEMPLATES)}") from None


def make(name: str, base: bool = False, **values) -> Template:
    """A checked template instance, e.g. ``make("quarter-sphere", radius=40)``."""
    return get_template(name)(base=base, **values)
