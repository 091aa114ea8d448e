"""Every template plan against the theory: its class is in Table V and its touches locate the part."""

from collections import Counter

import numpy as np
import pytest

from fixturecad.registration.problem import Problem
from fixturecad.registration.synthetic import plan_touches
from fixturecad.registration.touches import build_groups
from fixturecad.templates import TEMPLATES, make
from fixturecad.theory.enumeration import class_of_contacts, enumerate_classes

PLANS = [(name, plan) for name in TEMPLATES for plan in make(name).touch_plans()]


@pytest.fixture(scope="module")
def catalogue_classes():
    return {item.name for item in enumerate_classes().found}


def _contacts(plan):
    """One contact name per touch of the plan."""
    return [entry["contact"] for entry in plan.touches for _ in np.reshape(entry["points"], (-1, 3))]


@pytest.mark.parametrize("template,plan_name", PLANS)
def test_plan_class_is_a_catalogue_class_its_touches_realise(template, plan_name, catalogue_classes):
    plan = make(template).touch_plans()[plan_name]
    assert plan.contact_class in catalogue_classes
    declared = Counter(plan.contact_class.strip("{}").split("}{"))
    realised = Counter(class_of_contacts(_contacts(plan)))
    assert not declared - realised, f"{plan.contact_class} is not within the plan's {realised}"


@pytest.mark.parametrize("template,plan_name", PLANS)
def test_concrete_plan_has_mobility_zero(template, plan_name):
    """The rank of the stacked rows at the real geometry: no degenerate placement."""
    fixture = make(template)
    plan = fixture.touch_plans()[plan_name]
    touches, contacts = plan_touches(plan.touches, np.eye(4))
    groups = build_groups(fixture.feature_map(), touches, contacts=contacts)
    _, jacobian = Problem(groups).evaluate(np.eye(3), np.zeros(3))
    assert np.linalg.matrix_rank(jacobian, tol=1e-9 * np.abs(jacobian).max()) == 6


def test_three_collinear_plane_touches_are_degenerate_though_the_class_is_not():
    """The paper's warning: the catalogue speaks of generic placements only."""
    fixture = make("cube")
    plan = fixture.touch_plans()["minimal"]
    entries = [dict(e) for e in plan.touches]
    first = entries[0]
    points = np.reshape(first["points"], (-1, 3))
    start, end = points[0], points[1]
    first["points"] = [list(start), list((start + end) / 2), list(end)]
    touches, contacts = plan_touches(entries, np.eye(4))
    groups = build_groups(fixture.feature_map(), touches, contacts=contacts)
    _, jacobian = Problem(groups).evaluate(np.eye(3), np.zeros(3))
    assert len(_contacts(plan)) == 6
    assert np.linalg.matrix_rank(jacobian, tol=1e-9 * np.abs(jacobian).max()) == 5
