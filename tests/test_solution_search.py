"""Issue 12: never a confident wrong pose. register_touches on seeded random layouts, judged against an
independent brute-force enumeration of the admissible poses (tests/brute_force.py, tests/search_cases.py).

Each variant (a kind of layout at a noise level) runs ``LAYOUTS`` layouts; ``benchmarks/bench_search.py``
runs the same judge on many more.
"""

import pytest

from search_cases import VARIANTS, judge_all, variant_id

LAYOUTS = 4  # per variant in the normal suite; the benchmark runs many more
CHECKS = {
    "unique with a wrong pose": ("wrong_unique",),
    "an admissible pose missed": ("unique_missed", "unique_none", "ambiguous_missing"),
    "inconsistent although an admissible pose passes": ("false_inconsistent",),
}


@pytest.mark.parametrize("case,noise_mm", [pytest.param(case, noise_mm, id=variant_id(case, noise_mm))
                                            for case, noise_mm in VARIANTS])
def test_never_a_confident_wrong_pose(case, noise_mm):
    """No unique with a wrong pose; unique only when the brute force finds exactly one admissible pose and
    ambiguous listing all of them; inconsistent only when it finds none; a separating touch on the real
    part that, added, gives the true pose. Failures as {check: [(layout, status, poses found)]}."""
    outcomes = judge_all(case, noise_mm, LAYOUTS)
    failures = {check: [(k, o.status, o.found) for k, o in enumerate(outcomes)
                        if any(getattr(o, attribute) for attribute in attributes)]
                for check, attributes in CHECKS.items()}
    failures["separating touch"] = [(k, o.separating) for k, o in enumerate(outcomes)
                                    if o.separating not in ("", "separates")]
    assert {check: found for check, found in failures.items() if found} == {}
