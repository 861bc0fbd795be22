"""Field finish (issue 25), CSV as spreadsheet programs write it: trailing empty columns of an
Excel range, semicolon- and tab-separated files with decimal commas (European Excel), header names
in capitals.  Accepted with the same numbers as the plain file, and what was detected is said on
stderr and in the JSON ``warnings``; what stays ambiguous is one message naming the line."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from cmmwb.generator.cli import main
from cmmwb.xlfuncs import pointcloud as pc
from cmmwb.xlfuncs.csvtable import TableError, read_table
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator.recordings import parse_recordings, write_recordings

from tests.helpers import BAD_FILES

sys.path.insert(0, str(BAD_FILES))
from make_bad_files import POINTCLOUD_CSV, POINTCLOUD_TASK  # noqa: E402

from tests.helpers.files import assert_clear_failure  # noqa: E402

#: the plain points table with one coordinate that has decimals, to see a decimal comma read right
PLAIN = POINTCLOUD_CSV.replace("B,100,0,0", "B,100.25,0,0")


def build(tmp_path, capsys, csv_text: str, name: str = "small") -> tuple[int, dict | None, str]:
    work = tmp_path / name
    work.mkdir()
    (work / "small.toml").write_text(POINTCLOUD_TASK.replace('name = "small"', f'name = "{name}"'))
    (work / "small.csv").write_text(csv_text, encoding="utf-8")
    code = main(["build", str(work / "small.toml"), "--out", str(work / "out"), "--no-plots"])
    err = capsys.readouterr().err.strip()
    out = work / "out" / f"{name}.json"
    return code, (json.loads(out.read_text()) if code == 0 else None), err


@pytest.fixture
def plain(tmp_path, capsys) -> dict:
    code, res, err = build(tmp_path, capsys, PLAIN, "plain")
    assert code == 0 and err == "", err
    assert res["warnings"] == []
    return res


def same_distances(a: dict, b: dict) -> None:
    assert [(d["from"], d["to"]) for d in a["distances"]] == [(d["from"], d["to"]) for d in b["distances"]]
    for x, y in zip(a["distances"], b["distances"]):
        assert x["d_mm"] == pytest.approx(y["d_mm"], rel=1e-12)
        assert x["u_um"] == pytest.approx(y["u_um"], rel=1e-12)


def excel_range(text: str, empty_columns: int) -> str:
    """The table as Excel exports a range with ``empty_columns`` empty columns at its right."""
    return "".join(line + "," * empty_columns + "\n" for line in text.splitlines())


def european(text: str, sep: str) -> str:
    """The table as European Excel writes it: ``sep`` between fields, decimal commas."""
    return "".join(sep.join(f.replace(".", ",") for f in line.split(",")) + "\n" for line in text.splitlines())


# -- trailing empty columns ----------------------------------------------------------------------

def test_a_points_table_from_an_excel_range_with_empty_columns_builds_with_the_same_numbers(tmp_path, capsys,
                                                                                            plain):
    code, res, err = build(tmp_path, capsys, excel_range(PLAIN, 2), "excel")
    assert code == 0, err
    same_distances(res, plain)
    assert res["warnings"] == ["%s, line 1: columns 9, 10 without a name in the header and without values: "
                               "ignored" % (tmp_path / "excel" / "small.csv")]
    assert err == "cmmwb: warning: " + res["warnings"][0]


def test_a_value_in_a_column_without_a_name_is_an_error_naming_the_line(tmp_path, capsys):
    text = excel_range(PLAIN, 2).splitlines()
    text[3] = text[3] + "7"             # line 4 has a value in the last, unnamed column
    code, _, err = build(tmp_path, capsys, "\n".join(text) + "\n")
    assert_clear_failure(code, err, "small.csv", ["line 4", "'7'", "column 10", "no name in the header"])
    assert not (tmp_path / "small" / "out").exists()


# -- European CSV ----------------------------------------------------------------------------------

@pytest.mark.parametrize("sep,word", [(";", "semicolon"), ("\t", "tab")])
def test_a_european_points_table_builds_with_the_same_numbers_and_says_what_was_detected(tmp_path, capsys,
                                                                                         plain, sep, word):
    text = european(PLAIN, sep)
    assert "100,25" in text
    code, res, err = build(tmp_path, capsys, text, "eu")
    assert code == 0, err
    same_distances(res, plain)
    assert res["warnings"] == [f"{tmp_path / 'eu' / 'small.csv'}, line 1: read as {word}-separated (detected "
                               "from the header), decimal commas accepted"]
    assert err == "cmmwb: warning: " + res["warnings"][0]


def test_header_names_in_capitals_are_matched_and_said(tmp_path, capsys, plain):
    lines = PLAIN.splitlines()
    lines[0] = "ID,X,Y,Z,Nx,NY,nz,Probe"
    code, res, err = build(tmp_path, capsys, "\n".join(lines) + "\n", "caps")
    assert code == 0, err
    same_distances(res, plain)
    assert len(res["warnings"]) == 1
    assert "header names matched ignoring case: 'ID' as 'id', 'X' as 'x'" in res["warnings"][0]


def test_a_decimal_comma_in_a_comma_separated_file_is_still_an_error_naming_the_line(tmp_path, capsys):
    code, _, err = build(tmp_path, capsys, PLAIN.replace("100.25", "100,25"))
    assert_clear_failure(code, err, "small.csv", ["line 3", "9 fields", "header has 8", "decimal comma"])


def test_a_thousands_separator_is_not_a_number_even_in_a_semicolon_file(tmp_path, capsys):
    code, _, err = build(tmp_path, capsys, european(PLAIN, ";").replace("100,25", "1.100,25"))
    assert_clear_failure(code, err, "small.csv", ["line 3", "'x'", "'1.100,25' is not a number"])


def test_x_and_capital_x_are_one_column_given_twice(tmp_path, capsys):
    code, _, err = build(tmp_path, capsys, PLAIN.replace("id,x,y,z,nx,ny,nz,probe", "id,x,y,X,nx,ny,nz,probe"))
    assert_clear_failure(code, err, "small.csv", ["line 1", "'x' appears twice"])


def test_the_delimiter_is_the_one_that_splits_the_header_into_most_fields():
    assert read_table("id;x;y\n1;2;3\n").delimiter == ";"
    assert read_table("id\tx\ty\n1\t2\t3\n").delimiter == "\t"
    assert read_table("id,x;y\n").delimiter == ","          # a tie: comma
    assert read_table("# a, b, c, d\nid;x\n").delimiter == ";"   # comments are not the header
    with pytest.raises(TableError):
        read_table("# only a comment\n")


# -- recordings: the same parser -------------------------------------------------------------------

def recordings_text() -> str:
    L = sm.iso10360((pc.Probe("P1", (0.0, 0.0, -20.0)),), repeats=1)
    rec = sm.simulate(L, pc.Parameters(sigma_R_um=0.3), {}, seed=3, temperature_C=20.5)
    return write_recordings(rec)


def test_european_recordings_read_as_the_plain_ones():
    text = recordings_text()
    plain = parse_recordings(text)
    eu = parse_recordings(european(text, ";").replace("id;", "Id;", 1))
    assert eu.ids == plain.ids and eu.lines == plain.lines
    for name in ("X1_mm", "X2_mm", "reference_mm", "measured_mm", "temperature_C"):
        np.testing.assert_array_equal(getattr(eu, name), getattr(plain, name))
    assert plain.notes == ()
    assert eu.notes[0] == "line 1: read as semicolon-separated (detected from the header), decimal commas accepted"
    assert "'Id' as 'id'" in eu.notes[1]


def test_recordings_from_an_excel_range_with_empty_columns_read_as_the_plain_ones():
    text = recordings_text()
    rec = parse_recordings(excel_range(text, 3))
    np.testing.assert_array_equal(rec.measured_mm, parse_recordings(text).measured_mm)
    assert rec.extra == {} and "without a name in the header" in rec.notes[0]


def test_rows_may_end_without_the_empty_columns_that_end_the_header(tmp_path, capsys, plain):
    lines = PLAIN.splitlines()
    lines[0] += ",,"
    code, res, err = build(tmp_path, capsys, "\n".join(lines) + "\n", "short")
    assert code == 0, err
    same_distances(res, plain)


def test_diagnose_reads_european_recordings_to_the_same_answer_and_says_what_it_detected(tmp_path, capsys):
    text = recordings_text()
    (tmp_path / "plain.csv").write_text(text)
    (tmp_path / "eu.csv").write_text(european(text, ";"))
    answers = {}
    for name in ("plain", "eu"):
        assert main(["diagnose", str(tmp_path / f"{name}.csv"), "--sigma-um", "0.3", "--out",
                     str(tmp_path / name), "--no-plots", "--no-workbook"]) == 0
        answers[name] = (json.loads((tmp_path / name / "diagnosis.json").read_text()), capsys.readouterr().err)
    (plain, plain_err), (eu, eu_err) = answers["plain"], answers["eu"]
    assert plain["warnings"] == [] and plain_err == ""
    assert eu["warnings"] == [f"{tmp_path / 'eu.csv'}, line 1: read as semicolon-separated (detected from the "
                              "header), decimal commas accepted"]
    assert eu_err.strip() == f"cmmwb: warning: {eu['warnings'][0]}"
    assert eu["records"] == plain["records"]
    assert eu["chi2_before"] == pytest.approx(plain["chi2_before"], rel=1e-12)
