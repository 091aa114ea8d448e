"""Issue 12: never a confident wrong pose. register_touches on seeded random layouts, judged against an
independent brute-force enumeration of the admissible poses (tests/brute_force.py, tests/search_cases.py).

Each variant (a kind of layout at a noise level) runs ``LAYOUTS`` layouts once per session; the four
checks below read the same outcomes. ``benchmarks/bench_search.py`` runs the same judge on many more.
The marks ``xfail(strict=True)`` are where the current start-based search fails: they come off with the
certified search.
"""

from functools import lru_cache

import pytest

from search_cases import VARIANTS, judge_all, variant_id

LAYOUTS = 4  # per variant in the normal suite; the benchmark runs many more


@lru_cache(maxsize=None)
def outcomes(index):
    case, noise_mm = VARIANTS[index]
    return judge_all(case, noise_mm, LAYOUTS)


def _variants(failing):
    """Every variant, ``failing`` (variant ids -> reason) marked xfail(strict=True)."""
    out = []
    for index, (case, noise_mm) in enumerate(VARIANTS):
        name = variant_id(case, noise_mm)
        marks = [pytest.mark.xfail(strict=True, reason=f"issue 12: {failing[name]}")] if name in failing else []
        out.append(pytest.param(index, id=name, marks=marks))
    return out


def _failed(index, *checks):
    return [(k, o.status, o.found) for k, o in enumerate(outcomes(index)) if any(getattr(o, c) for c in checks)]


@pytest.mark.parametrize("index", _variants({
    "v-block 2-2-2, noise-free": "unique with a wrong pose (layout 3)",
    "inclined-plane-cylinder 2+4, noise-free": "unique with a wrong pose (layout 1)",
}))
def test_no_unique_with_a_wrong_pose(index):
    assert _failed(index, "wrong_unique") == []


@pytest.mark.parametrize("index", _variants({
    "cube 2-2-2, noise-free": "unique with a second admissible exact pose (layout 3)",
    "v-block 2-2-2, noise-free": "unique with a second admissible exact pose (layout 3)",
    "inclined-plane-cylinder 2+4, noise-free": "ambiguous missing one of four admissible poses (layout 0), unique "
                                               "with five (layout 1)",
}))
def test_no_admissible_solution_is_missed(index):
    """unique only when the brute force finds exactly one admissible pose; ambiguous lists all of them."""
    assert _failed(index, "unique_missed", "unique_none", "ambiguous_missing") == []


@pytest.mark.parametrize("index", _variants({
    "inclined-plane-cylinder 2+4, 5 um": "inconsistent although an admissible pose passes (layout 0)",
    "collinear 4-3-2 cube, 5 um": "inconsistent although an admissible pose passes (layout 3)",
}))
def test_inconsistent_only_when_no_admissible_pose_passes(index):
    assert _failed(index, "false_inconsistent") == []


@pytest.mark.parametrize("index", _variants({
    "near-degenerate 3-2-1 cube, 5 um": "the separating touch lies off the real part (layouts 1, 2, 3)",
}))
def test_separating_touches_lie_on_the_part_and_separate(index):
    assert [(k, o.separating) for k, o in enumerate(outcomes(index)) if o.separating not in ("", "separates")] == []
