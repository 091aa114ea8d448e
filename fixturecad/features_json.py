"""features.json: the one module that builds, validates, writes and reads it.

The schema (``fixturecad/schema/features.schema.json``, shipped in the
package) holds the schema id; a build's own document is validated against it
before it is written, and a folder's is read back with one-line errors.
"""

import json
from importlib import resources
from pathlib import Path

from fixturecad import __version__
from fixturecad.errors import InputError

NAME = "features.json"
# The recorded manufacturing tolerance: what its zone means.
TOLERANCE_DEFINITION = ("ISO 1101 profile tolerance of every sensing patch: each point of the printed patch "
                        "lies within +-zone_mm/2 of its nominal surface; 0: the part is exact")


def load_schema() -> dict:
    """The JSON Schema of features.json shipped in the package."""
    text = resources.files("fixturecad").joinpath("schema/features.schema.json").read_text(encoding="utf-8")
    return json.loads(text)


def schema_id() -> str:
    """The schema id every features.json carries (``"schema"``), as the shipped schema states it."""
    return load_schema()["properties"]["schema"]["const"]


def validate(document: dict) -> None:
    """Raise jsonschema.ValidationError if ``document`` does not follow the features.json schema."""
    from jsonschema.validators import validator_for

    schema = load_schema()
    # the schema itself is checked once, by the tests, not on every build
    validator_for(schema)(schema).validate(document)


def document(template, files: dict, fixture_tolerance_mm: float, touch_candidates=None, faces=None) -> dict:
    """The features.json content of a template instance (no CAD needed); ``files`` its "files" entry;
    ``touch_candidates`` the reachable touches a build finds on its mesh (:func:`.build.touch_candidates`);
    ``faces`` every face of its solid as features, or the reason there are none (:func:`.cad.faces.face_features`)."""
    plans = template.touch_plans()
    return {
        "schema": schema_id(),
        "units": "mm",
        "generator": f"fixturecad {__version__}",
        "template": template.name,
        "parameters": template.parameters_json(),
        "contact_class": template.contact_class,
        "frame": template.FRAME,
        "datums": template.DATUMS.to_json(template.DATUM_TEXT),
        "tolerance": {"zone_mm": fixture_tolerance_mm, "definition": TOLERANCE_DEFINITION},
        "volume_mm3": template.volume(),
        "files": files,
        "features": [feature.to_json() for feature in template.features()],
        "plans": {name: plan.to_json() for name, plan in plans.items()},
        **({} if faces is None else {"faces": faces}),
        **({} if touch_candidates is None else {"touch_candidates": touch_candidates}),
        **template.extras(),
    }


def write(document: dict, path) -> Path:
    """Validate ``document`` and write it to ``path``."""
    validate(document)
    path = Path(path)
    path.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    return path


def read(folder) -> dict:
    """The features.json of a fixture folder; InputError (one line) when missing, not JSON or of an older schema."""
    path = Path(folder) / NAME
    if not path.is_file():
        raise InputError(f"no {NAME} in {folder}: run fixturecad build first")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as error:  # RecursionError: nested too deep
        raise InputError(f"{path} is not valid JSON: {getattr(error, 'msg', error)}") from None
    if not isinstance(data, dict) or data.get("schema") != schema_id():
        found = data.get("schema") if isinstance(data, dict) else None
        raise InputError(f"{path} is {found or 'not a fixturecad features file'}, this fixturecad reads "
                         f"{schema_id()}: rebuild the fixture")
    return data
