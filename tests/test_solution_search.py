"""Issue 12: never a confident wrong pose. register_touches on seeded random layouts, judged against an
independent brute-force enumeration of the admissible poses (tests/brute_force.py, tests/search_cases.py).

Each variant (a kind of layout at a noise level) runs ``LAYOUTS`` layouts; ``benchmarks/bench_search.py``
runs the same judge on many more.
"""

import pytest

from search_cases import VARIANTS, judge, judge_all, variant_id

LAYOUTS = 4  # per variant in the normal suite; the benchmark runs many more ...
ISSUE_LAYOUTS = 30  # ... and the three kinds of layout that missed poses (issue 18) this many, so that a 3 % miss
ISSUE_CASES = ("cube 2-2-2, printed", "v-block 2-2-2, printed", "inclined-plane-cylinder 2+4, printed")  # rate fails
CHECKS = {
    "unique with a wrong pose": ("wrong_unique",),
    "an admissible pose missed": ("unique_missed", "unique_none", "ambiguous_missing"),
    "inconsistent although an admissible pose passes": ("false_inconsistent",),
    "underdetermined although the touches plainly fix the pose": ("false_underdetermined",),
}


BLOCK = 10  # layouts a test, so that the many layouts of a case spread over the workers


def _blocks():
    for case, noise_mm in VARIANTS:
        count = ISSUE_LAYOUTS if case.name in ISSUE_CASES else LAYOUTS
        for first in range(0, count, BLOCK):
            name = variant_id(case, noise_mm) + (f", layouts {first}-{first + min(BLOCK, count) - 1}" if count > BLOCK else "")
            yield pytest.param(case, noise_mm, first, min(BLOCK, count - first), id=name)


@pytest.mark.parametrize("case,noise_mm,first,layouts", list(_blocks()))
def test_never_a_confident_wrong_pose(case, noise_mm, first, layouts):
    """No unique with a wrong pose; unique only when the brute force finds exactly one admissible pose and
    ambiguous listing all of them; inconsistent only when it finds none; a separating touch on the real
    part that, added, gives the true pose; and a search that completes on every layout (a plan of point touches
    and sensors with stand-ins that fixes the pose is never left unproven). Failures as {check: [(layout, status, poses found)]}."""
    outcomes = judge_all(case, noise_mm, layouts, first=first)
    failures = {check: [(first + k, o.status, o.found) for k, o in enumerate(outcomes)
                        if any(getattr(o, attribute) for attribute in attributes)]
                for check, attributes in CHECKS.items()}
    failures["separating touch"] = [(first + k, o.separating) for k, o in enumerate(outcomes)
                                    if o.separating not in ("", "separates")]
    # Not complete, and not underdetermined (which claims no pose, exit 4): exit 6, no claim, but no answer.
    failures["search not complete"] = [(first + k, o.status) for k, o in enumerate(outcomes)
                                       if o.search != "complete" and o.status != "underdetermined"]
    assert {check: found for check, found in failures.items() if found} == {}


def test_a_wide_region_listed_off_its_patches_is_not_called_inconsistent():
    """Layout 1114 of the near-degenerate 3-2-1 cube at 5 um (fresh seeds, on feb4b2c: the only false
    ``inconsistent`` of 6,200 layouts): its touches leave a valley of poses 60 mm long that pass, the true pose
    among them, and the search's regions there are listed at poses that put a touch off its patch (one at rank
    5). A region may hold admissible poses wherever its listed pose lies within its reach of the patches:
    the answer is ``underdetermined``, not ``inconsistent``."""
    case = next(c for c, _ in VARIANTS if c.name == "near-degenerate 3-2-1 cube")
    outcome = judge(case, 0.005, 1114)
    assert outcome.status == "underdetermined" and not outcome.false_underdetermined, outcome
