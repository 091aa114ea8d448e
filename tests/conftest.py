"""Fixtures shared by the test modules."""

import pytest

# The modules whose tests take longest go first, so that no worker is still in one of them when the rest are done
# (a worker that runs out takes tests queued for another: --dist worksteal, pyproject.toml).
LONGEST = ("test_docs_commands.py", "test_solution_search.py")


def pytest_collection_modifyitems(items):
    items.sort(key=lambda item: item.path.name not in LONGEST)  # stable: the rest keep their order


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
