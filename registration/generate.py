"""Write the standalone ``register.py`` of a fixture from the template file.

The generated module embeds, verbatim, the sources of the registration
modules it runs and the fixture's features.json, and loads the modules into a
private in-memory package: it needs numpy and scipy, not fixturecad.
"""

import ast
import hashlib
import json
from importlib import resources
from pathlib import Path
from string import Template

from fixturecad import __version__

TEMPLATE_NAME = "register.py.tmpl"
# The registration modules register.py carries, loaded on import from its own copy of their sources.
EMBEDDED_MODULES = ("ambiguity", "assignments", "contacts", "controllers", "datums", "defaults", "deviations", "elements", "engine", "face_search", "features",
                    "fits", "least_squares", "mobility", "motions", "noise", "patches", "planning", "pose", "problem", "redundancy", "search", "sensor_bounds", "solve", "stand_ins",
                    "starts", "symmetry", "tolerance", "touches", "touchfile", "uncertainty", "units", "unlabelled", "verdict")


def _sources():
    package = resources.files(__package__)
    return {name: package.joinpath(f"{name}.py").read_text(encoding="utf-8") for name in EMBEDDED_MODULES}


def register_source(features_document: dict) -> str:
    """Source text of the standalone ``register.py`` for a features.json document."""
    if not isinstance(features_document, dict) or not isinstance(features_document.get("features"), list):
        raise ValueError('features document must be a dict with a "features" list')
    template = Template(resources.files(__package__).joinpath(TEMPLATE_NAME).read_text(encoding="utf-8"))
    sources = _sources()
    features_json = json.dumps(features_document, sort_keys=True)
    digest = hashlib.sha256((features_json + "".join(sources.values())).encode()).hexdigest()[:12]
    text = template.substitute(
        template=features_document.get("template", "fixture"),
        version=__version__,
        feature_ids=", ".join(entry["id"] for entry in features_document["features"]),
        features_json=repr(features_json),
        sources="{\n" + "".join(f"    {name!r}: {source!r},\n" for name, source in sources.items()) + "}",
        digest=digest,
    )
    ast.parse(text)
    return text


def write_register_script(features_dict: dict, path) -> Path:
    """Write ``register.py`` for the features.json document ``features_dict`` to ``path``."""
    path = Path(path)
    path.write_text(register_source(features_dict), encoding="utf-8")
    return path
