"""What every fixture template shares: typed parameters, validation, the mounting base.

A template is a small class in the build123d manner: its parameters (with
units and ranges) are declared once in ``PARAMS``; an instance holds checked
values and gives its CadQuery body, the labelled sensing features (analytic,
:mod:`fixturecad.registration.features`), the analytic volume and named touch
plans. CadQuery is imported inside ``body()`` only (the rest of the CAD work
is :mod:`fixturecad.cad`), so listing templates and reading their features
stays fast.

Touch plans
-----------
``touch_plans()`` returns ``{name: Plan}``; ``"default"`` always exists. Each
entry is ``{"contact": "P/F-PL/M", "feature": id, "points": [[x, y, z], ...]}``
with nominal points ON the feature, fixture frame, mm; one touch per point.
Entries whose sensor is not a point carry ``"sensor"``:

* a plane sensor (``PL/F-PL/F``, ``PL/M-...``): ``{"kind": "plane", "point",
  "normal"}``, the sensor face lying on the feature, its normal pointing into
  the fixture material; ``points`` holds the known contact point.
* a line sensor (``L/M-L/M``, ``L/F-...``): ``{"kind": "line", "point",
  "direction"}``, the sensor line (e.g. a taut wire or a knife edge) crossing
  the fixture line outside the material; ``points`` holds the crossing point.
"""

import math
from dataclasses import dataclass

import numpy as np

from fixturecad.errors import InputError
from fixturecad.registration.datums import DatumScheme

# Gap between a mounting base and the nearest sensing patch, mm.
BASE_CLEARANCE_MM = 1.0


@dataclass(frozen=True)
class Param:
    """One template parameter: ``--<name> value`` on the command line."""

    name: str
    unit: str  # "mm" or "deg"
    default: float
    minimum: float
    maximum: float
    help: str
    short: str  # letter used in output folder names, e.g. "r" -> quarter-sphere-r40
    limit_reason: str = ""  # why the range stops where it does, quoted when a value is refused


@dataclass
class Plan:
    """A named touch plan: its catalogue class and its touch entries."""

    contact_class: str
    touches: list
    note: str = ""

    def to_json(self) -> dict:
        return {"contact_class": self.contact_class, "note": self.note, "touch_plan": self.touches}


def _fmt(value: float) -> str:
    return f"{value:g}"


def parse_number(name: str, text) -> float:
    """A finite float from the command line, or InputError naming the parameter."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise InputError(f"--{name} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise InputError(f"--{name} must be finite, got {text!r}")
    return value


@dataclass
class Anchor:
    """Where a mounting base attaches: a stem along ``direction`` from ``start``.

    The stem (radius ``stem_radius``) runs from ``start`` (inside the solid or
    on a non-sensing face) to ``start + length * direction``; a square plate of
    side ``plate_size`` and thickness ``plate_thickness`` closes it, normal to
    the stem. ``inside_volume`` is the part of the stem inside the fixture
    solid (0 when it starts on a flat face).
    """

    start: np.ndarray
    direction: np.ndarray
    stem_radius: float
    length: float
    plate_size: float
    plate_thickness: float
    inside_volume: float = 0.0

    def volume(self) -> float:
        """Volume the base adds to the fixture, mm^3."""
        stem = math.pi * self.stem_radius**2 * self.length - self.inside_volume
        return stem + self.plate_size**2 * self.plate_thickness


class Template:
    """Base class: subclasses set the class attributes and the geometry methods."""

    name: str = ""
    title: str = ""
    origin: str = ""  # where it comes from (paper figure, shop practice)
    PARAMS: tuple = ()
    contact_class: str = ""  # catalogue class of the default plan
    FRAME: str = ""  # where the fixture frame sits, in words (features.json "frame")
    DATUMS: DatumScheme  # the features that fix the frame on the printed part
    DATUM_TEXT: str = ""  # how each datum feature fixes the frame, in words
    # Two directions the preview looks from (towards the origin), chosen to show the sensing faces.
    VIEW_DIRECTIONS: tuple = ((1.0, -1.6, 1.1), (-1.0, 1.6, -1.1))

    def __init__(self, base: bool = False, **values):
        self.base = bool(base)
        self.values = self.validate(values)
        for key, value in self.values.items():
            setattr(self, key, value)
        self.check()

    # -- parameters ---------------------------------------------------------
    @classmethod
    def param(cls, name: str) -> Param:
        for param in cls.PARAMS:
            if param.name == name:
                return param
        raise InputError(
            f"template {cls.name} has no parameter --{name}; valid: {', '.join('--' + p.name for p in cls.PARAMS)}"
        )

    @classmethod
    def validate(cls, values: dict) -> dict:
        """Defaults filled in, every value a finite number within its range; InputError otherwise."""
        out = {}
        for key, value in values.items():
            param = cls.param(key.replace("_", "-"))
            number = parse_number(param.name, value)
            if not (param.minimum <= number <= param.maximum):
                reason = f" ({param.limit_reason})" if param.limit_reason else ""
                raise InputError(
                    f"--{param.name} must be between {_fmt(param.minimum)} and {_fmt(param.maximum)} {param.unit}"
                    f"{reason}, got {_fmt(number)}"
                )
            out[param.name] = number
        for param in cls.PARAMS:
            out.setdefault(param.name, param.default)
        return {key.replace("-", "_"): value for key, value in out.items()}

    def check(self) -> None:
        """Checks across parameters; raise InputError."""

    def slug(self) -> str:
        """Folder name: template and parameters, e.g. ``quarter-sphere-r40``.

        Parameters at their default are left out, except the first (the size).
        """
        parts = [self.name]
        for index, param in enumerate(self.PARAMS):
            value = self.values[param.name.replace("-", "_")]
            if index == 0 or value != param.default:
                parts.append(f"{param.short}{_fmt(value)}")
        if self.base:
            parts.append("base")
        return "-".join(parts)

    # -- geometry (subclasses) ---------------------------------------------
    def body(self):
        """The fixture body without base, CadQuery solid."""
        raise NotImplementedError

    def body_volume(self) -> float:
        raise NotImplementedError

    def anchor(self) -> Anchor:
        """Where the mounting base attaches (on non-sensing material)."""
        raise NotImplementedError

    def features(self) -> list:
        raise NotImplementedError

    def touch_plans(self) -> dict:
        raise NotImplementedError

    # -- shared --------------------------------------------------------------
    def volume(self) -> float:
        """Analytic volume of the fixture solid (body and base), mm^3."""
        return self.body_volume() + (self.anchor().volume() if self.base else 0.0)

    def feature_map(self) -> dict:
        return {feature.id: feature for feature in self.features()}

    def extras(self) -> dict:
        """Top-level features.json entries of this kind of fixture beyond the common ones."""
        return {}

    def parameters_json(self) -> dict:
        out = {param.name: self.values[param.name.replace("-", "_")] for param in self.PARAMS}
        out["base"] = self.base
        return out


def unit(vector) -> np.ndarray:
    vector = np.asarray(vector, dtype=np.float64)
    return vector / np.linalg.norm(vector)


def halfspace(normal, offset: float) -> list:
    """Extent row ``n . x <= offset`` with ``n`` normalised (offset scaled to match)."""
    normal = np.asarray(normal, dtype=np.float64)
    length = np.linalg.norm(normal)
    return [*(normal / length), offset / length]


def box_halfspaces(lower, upper, skip_axis: int) -> list:
    """Extent rows of an axis-aligned rectangle: the box minus the bounds along ``skip_axis``."""
    rows = []
    for axis in range(3):
        if axis == skip_axis:
            continue
        e = np.eye(3)[axis]
        rows.append(halfspace(e, upper[axis]))
        rows.append(halfspace(-e, -lower[axis]))
    return rows


def touch(contact: str, feature: str, points, sensor: dict | None = None) -> dict:
    """One touch-plan entry (see module doc), plain JSON types."""
    out = {"contact": contact, "feature": feature,
           "points": [[float(v) for v in point] for point in np.atleast_2d(points)]}
    if sensor:
        out["sensor"] = {key: (value if isinstance(value, str) else [float(v) for v in value])
                         for key, value in sensor.items()}
    return out
