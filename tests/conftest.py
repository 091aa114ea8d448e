"""Fixtures shared by the test modules."""

import pytest


@pytest.fixture(scope="session")
def built(tmp_path_factory):
    """Build a template at its default parameters once per session; tests copy a folder before changing it."""
    build = pytest.importorskip("fixturecad.build")
    templates = pytest.importorskip("fixturecad.templates")
    root = tmp_path_factory.mktemp("fixtures")
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = build.build(templates.make(name), root / name)
        return cache[name]

    return get
