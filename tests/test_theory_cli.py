"""``fixturecad contacts | catalog | analyze`` from the command line."""

import csv
import io
import json

import pytest

from cli import assert_bad_input, run


def test_contacts_json_lists_41_with_classes():
    rows = json.loads(run("contacts", "--format", "json").stdout)
    assert len(rows) == 41
    by_name = {row["contact"]: row for row in rows}
    assert by_name["P/F-PL/M"] | {} == by_name["P/F-PL/M"]
    assert (by_name["P/F-PL/M"]["dim"], by_name["P/F-PL/M"]["class"], by_name["P/F-PL/M"]["group"]) == (
        5, "S-T2", "{S_o}{T_P}")
    assert by_name["PL/M-C/F"]["class"] == "G3"


@pytest.mark.parametrize("fmt", ["table", "csv", "md"])
def test_contacts_in_every_format(fmt):
    out = run("contacts", "--format", fmt).stdout
    assert "L/M-L/M" in out and "C-R-C" in out
    if fmt == "csv":
        assert len(list(csv.reader(io.StringIO(out)))) == 42


def test_catalog_json_has_the_paper_totals_and_example_one():
    doc = json.loads(run("catalog", "--format", "json").stdout)
    assert (doc["total_classes"], doc["total_combinations"]) == (579, 17460)
    example = next(c for c in doc["classes"] if c["class"] == "{G3}{S-S}{S-T2}{C-R-C}")
    assert example["members"] == ["G3", "S-S", "S-T2", "C-R-C"] and example["combinations"] == 36


def test_catalog_with_filters_and_expansion():
    doc = json.loads(run("catalog", "--sensor", "P", "--fixture", "PL,C", "--expand", "--format", "json").stdout)
    assert len(doc["combinations"]) == doc["total_combinations"] > 0
    assert all(c.startswith("P/F-") for row in doc["combinations"] for c in row["contacts"])


def test_analyze_example_one():
    doc = json.loads(run("analyze", "PL/F-PL/F", "P/F-S/M", "P/F-PL/M", "L/M-L/M", "--format", "json").stdout)
    assert doc["class"] == "{G3}{S-S}{S-T2}{C-R-C}"
    assert (doc["mobility"], doc["minimal"], doc["redundant"], doc["in_catalog"]) == (0, True, [], True)


def test_analyze_names_the_remaining_freedom():
    doc = json.loads(run("analyze", "S/F-S/F", "--format", "json").stdout)
    assert doc["mobility"] == 1
    assert doc["freedom"] == ["rotation {R_u} about the line through the sensor sphere centre and the fixture sphere centre"]
    doc = json.loads(run("analyze", "P/F-S/M", "P/F-S/M", "P/F-S/M", "PL/F-PL/F", "--format", "json").stdout)
    assert (doc["class"], doc["mobility"], doc["redundant"], doc["in_catalog"]) == (
        "{G3}{S-S}{S-S}{S-S}", 0, [], True)


def test_analyze_flags_redundant_contacts():
    # {R} takes five freedoms: one more touch locates, the second is spare.
    doc = json.loads(run("analyze", "S/F-S/F", "P/F-PL/M", "P/F-PL/M", "--format", "json").stdout)
    assert doc["mobility"] == 0 and not doc["minimal"] and not doc["in_catalog"]
    assert doc["redundant"] == ["P/F-PL/M", "P/F-PL/M"]


@pytest.mark.parametrize(
    "args,words",
    [
        (["analyze", "X/F-PL/M"], ["X/F-PL/M", "P, L, PL, S, C"]),
        (["analyze", "PL/F-L/M"], ["not a contact of Table I", "valid contacts"]),
        (["catalog", "--max-contacts", "0"], ["--max-contacts"]),
        (["catalog", "--sensor", "Q"], ["--sensor", "P, L, PL, S, C"]),
        (["catalog", "--target-dim", "7"], ["--target-dim"]),
        (["catalog", "--format", "xml"], ["xml"]),
        (["contacts", "--bogus"], ["--bogus"]),
    ],
)
def test_bad_input_is_one_line_and_exit_2(args, words):
    result = run(*args)
    assert_bad_input(result, *words)
    assert result.stdout == ""


def test_theory_paths_never_import_cadquery():
    import subprocess
    import sys

    code = (
        "import sys\nfrom fixturecad.cli import main\n"
        "try:\n    main(['catalog', '--format', 'json'])\nexcept SystemExit:\n    pass\n"
        "assert 'cadquery' not in sys.modules, 'cadquery imported'\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
