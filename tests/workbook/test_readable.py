"""What a person reads (issue 25): units in the headers, readable numbers, charts that show every
series at the size of the printed page, plots whose log ticks are text, a visible flag when a
feature book's points were edited after the fit, summaries that say what was found, no progress
bar in a pipe, and TOML errors that name the line of the key."""

from __future__ import annotations

import math
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import openpyxl
import pytest

from cmmwb.generator.build import build_task
from cmmwb.generator.errors import InputError
from cmmwb.generator.feature import va_sheets
from cmmwb.generator.feature.task import FIT_CURRENT, FIT_STALE
from cmmwb.generator.taskfile import key_line
from cmmwb.generator.workbook import plots
from cmmwb.generator.workbook.pagesetup import CM_PER_CHAR
from cmmwb.generator.workbook.recalc import default_engine, results_rows
from cmmwb.generator.workbook.styles import FMT_SCI

from tests.helpers import EXAMPLES, recalc

CMMWB = [sys.executable, "-m", "cmmwb.generator"]


def built(example: str, out: Path) -> tuple[dict, Path]:
    results, files = build_task(EXAMPLES / example, out, plots=False)
    return results, next(f for f in files if f.suffix == ".xlsx")


@pytest.fixture(scope="module")
def sphere_book(tmp_path_factory):
    """The six-point sphere of Forbes 2022 Table 8: the smallest feature book."""
    return built("feature_table8_sphere_six.toml", tmp_path_factory.mktemp("sphere"))


# -- plots: log ticks are text, not mathtext source ---------------------------------------------

def test_decade_labels_are_plain_text():
    assert [plots.decade_label(v) for v in (1e-4, 0.01, 1.0, 1000.0, 1e5, 0.2)] == \
        ["10⁻⁴", "0.01", "1", "1000", "10⁵", "0.2"]


def test_the_planning_plot_prints_its_log_ticks_as_text(tmp_path, monkeypatch):
    """Every *_planning.png printed '$\\mathdefault{10^{1}}$' (mathtext is off for user text)."""
    from matplotlib.figure import Figure

    seen: list[str] = []
    save = Figure.savefig

    def spy(fig, *args, **kwargs):
        fig.canvas.draw()
        for ax in fig.axes:
            seen.extend(t.get_text() for t in ax.get_yticklabels() + ax.yaxis.get_minorticklabels())
        return save(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", spy)
    _, files = build_task(EXAMPLES / "feature_table1_circle_arc.toml", tmp_path)
    assert any(f.name.endswith("_planning.png") for f in files)
    labels = [t for t in seen if t]
    assert labels and not [t for t in labels if "mathdefault" in t or "$" in t], labels
    assert any(re.fullmatch(r"10[⁻⁰¹²³⁴⁵⁶⁷⁸⁹]+|[0-9.]+", t) for t in labels)


# -- recalc in a pipe: no progress bar -----------------------------------------------------------

def test_recalc_into_a_pipe_prints_the_table_and_no_progress_bar(sphere_book):
    _, book = sphere_book
    proc = subprocess.run([*CMMWB, "recalc", str(book), "--engine", "formulas"], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""                      # the engine's tqdm bar went to stderr before
    assert proc.stdout.splitlines()[0].startswith("parameter\tvalue\tu\tunit")
    merged = subprocess.run([*CMMWB, "recalc", str(book), "--engine", "formulas"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, timeout=300)
    assert merged.stdout.splitlines()[0].startswith("parameter\tvalue"), merged.stdout[:200]
    # without --engine, the one line on stderr says which engine it chose
    default = subprocess.run([*CMMWB, "recalc", str(book)], capture_output=True, text=True, timeout=300)
    assert default.returncode == 0, default.stderr
    assert default.stderr == f"cmmwb recalc: engine {default_engine()} (the fastest installed; --engine to choose another)\n"
    assert default.stdout.splitlines()[0].startswith("parameter\tvalue\tu\tunit")


def test_the_progress_bar_draws_only_on_a_terminal(monkeypatch):
    import io

    from cmmwb.xlfuncs.execution import ProgressBar

    pipe = io.StringIO()                          # isatty() is False
    monkeypatch.setattr(sys, "stderr", pipe)
    ProgressBar("blocks", delay_s=0.0)(1, 1)
    assert pipe.getvalue() == ""
    shown = io.StringIO()
    ProgressBar("blocks", stream=shown, delay_s=0.0)(1, 1)   # a stream given explicitly still draws
    assert "100%" in shown.getvalue()


# -- TOML errors name the line ------------------------------------------------------------------

def test_key_line_finds_tables_arrays_of_tables_and_dotted_places():
    text = "\n".join(['[task]', 'kind = "budget"', '', '[mpe]', 'A_um = 3', '',
                      '[[characteristics]]', 'name = "a"', '[[characteristics]]', 'name = "b"',
                      'model = "posit"', '[[probes]]', 'id = "P1"', 'offset_mm = [0, 0]'])
    assert key_line(text, "[mpe] A_um") == 5
    assert key_line(text, "[[characteristics]] #2 key 'model'") == 11
    assert key_line(text, "[[characteristics]] #1 key 'name'") == 8
    assert key_line(text, "[[[probes]] #1] offset_mm") == 14
    assert key_line(text, "mpe.A_um") == 5
    assert key_line(text, "[mpe] B_mm") == 4            # a missing key: its table's header
    assert key_line(text, "[nothing] x") is None


def test_a_semantic_error_names_the_line_of_the_key(tmp_path):
    text = (EXAMPLES / "knuckle.toml").read_text(encoding="utf-8")
    lines = text.splitlines()
    n = next(k for k, line in enumerate(lines) if line.startswith("A_um"))
    lines[n] = "A_um = -3.0"
    task = tmp_path / "knuckle.toml"
    task.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(InputError) as err:
        build_task(task, tmp_path / "out", plots=False)
    assert f"[mpe] A_um (line {n + 1})" in str(err.value) and str(task) in str(err.value)


def test_the_cli_message_of_a_bad_characteristic_names_its_line(tmp_path):
    text = (EXAMPLES / "knuckle.toml").read_text(encoding="utf-8")
    lines = text.splitlines()
    n = [k for k, line in enumerate(lines) if line.startswith("model = ")][2]   # the third characteristic
    lines[n] = 'model = "posit"'
    task = tmp_path / "bad.toml"
    task.write_text("\n".join(lines) + "\n", encoding="utf-8")
    proc = subprocess.run([*CMMWB, "build", str(task), "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert f"[[characteristics]] #3 key 'model' (line {n + 1})" in proc.stderr, proc.stderr


# -- the knuckle: nominal positions, readable intermediate quantities --------------------------

def test_every_position_of_the_shipped_knuckle_is_nominal(tmp_path):
    """S3 = [0.01, 52, -15] (the paper's substitution) with TEDs [0, 52] put POS = 20 µm into
    Results; with the substituted TED it is 0 like S1, S2, S4."""
    results, _ = built("knuckle.toml", tmp_path)
    positions = {c["name"]: c["value_mm"] for c in results["characteristics"] if c["model"] == "position"}
    assert set(positions) == {"S1_position", "S2_position", "S3_position", "S4_position"}
    assert all(abs(v) < 1e-9 for v in positions.values()), positions


def test_scientific_formats_print_an_exact_zero_as_0():
    sections = FMT_SCI.split(";")
    assert sections[0] == "0.000E+00" and sections[2] == "0"    # -0 fell into -0.000E+00 before


@pytest.mark.libreoffice
def test_the_printed_knuckle_shows_no_negative_zero(tmp_path):
    from cmmwb.generator.workbook.pdf import print_books

    _, book = built("knuckle.toml", tmp_path)
    (pdf,) = print_books([book])
    text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True, text=True,
                          check=True).stdout
    assert "-0.000E+00" not in text and "0.000E+00" not in text


# -- the feature Results: the contract's columns, then what a person reads ----------------------

def test_feature_results_keep_the_contract_columns_and_add_readable_ones(sphere_book):
    results, book = sphere_book
    ws = openpyxl.load_workbook(book)["Results"]
    header = [c.value for c in ws[1]]
    assert header[:3] == ["parameter", "value", "u"]                 # docs/cli.md
    assert header[3:] == ["unit", "u_um", "u_urad", "fit_state"]
    fe = results["feature"]
    rows = results_rows({"Results": {c.coordinate: c.value for r in
                                     openpyxl.load_workbook(book, data_only=True)["Results"].iter_rows()
                                     for c in r if c.value is not None}})
    for r in rows:
        assert math.isclose(r["u_um"], fe["u"][r["parameter"]] * 1e3, rel_tol=1e-9)   # all lengths
        assert r["u_urad"] == "—" and r["fit_state"] == FIT_CURRENT
    assert ws["C2"].number_format == FMT_SCI and ws["E2"].number_format == "0.0000"


def test_feature_budget_headers_carry_units(sphere_book):
    _, book = sphere_book
    ws = openpyxl.load_workbook(book)["Budget"]
    header = [c.value for c in ws[1]]
    assert header[1] == "value_mm" and header[4] == "u_um" and header[5:11] == \
        [f"u_{f}_um" for f in ("R", "PQ", "S", "ET", "ER", "P")]
    assert va_sheets.with_units("u", ["µm", "1e-6", "µm"]) == "u (µm, 1e-6)"
    assert ws["B2"].number_format == "0.000000"      # 250.000000 mm, not 250.000000000


@pytest.mark.parametrize("engine", ["formulas", pytest.param("libreoffice", marks=pytest.mark.libreoffice)])
def test_an_edited_point_flags_the_results_as_stale(sphere_book, tmp_path, engine):
    """The fit is not a formula: moving one point by 1 µm leaves the fitted values as they were,
    but the Gauss-Newton step on 'H' is no longer zero and every Results row says so, in red."""
    results, book = sphere_book
    assert results["feature"]["fit"]["state"] == FIT_CURRENT
    assert results["feature"]["fit"]["gauss_newton_step_norm"] < 1e-12
    before = results_rows(recalc(book, engine))
    assert {r["fit_state"] for r in before} == {FIT_CURRENT}
    wb = openpyxl.load_workbook(book)
    ws = wb["Points"]
    ws["B2"].value = ws["B2"].value + 0.001
    edited = tmp_path / f"edited_{engine}.xlsx"
    wb.save(edited)
    after = results_rows(recalc(edited, engine))
    assert {r["fit_state"] for r in after} == {FIT_STALE}
    rules = wb["Results"].conditional_formatting
    assert any(str(cf.sqref) == f"G2:G{1 + len(after)}" for cf in rules)


# -- the diagnosis summary ------------------------------------------------------------------------

def test_without_an_excess_the_summary_gives_the_delta_chi2_of_the_targeted_test():
    """chi2/dof 1.24 on 105 lengths, the omnibus test passes, the targeted one fires: the effect
    is worth more than the whole excess, which '100 % of the excess' (or 33 % each of three)
    misrepresented."""
    from cmmwb.xlfuncs.locator import diagnose as dg
    from cmmwb.xlfuncs.locator import simulate as sm

    from tests.helpers.clouds import MPE1
    from tests.helpers.locator import iso, u_effect

    L, model = iso()
    rec = sm.simulate(L, MPE1, {"squareness_xy": 5.5 * u_effect(L, model, "squareness_xy")}, seed=7)
    d = dg.diagnose(rec, model)
    c = d.candidates["squareness_xy"]
    assert d.gate == "targeted" and d.chosen == ["squareness_xy"]
    assert c.delta_chi2 > d.chi2_before - d.dof_before
    assert "of the excess" not in d.summary
    assert "test aimed at the candidates finds a squareness error" in d.summary
    assert f"delta chi2 = {c.delta_chi2:.1f} on 1 dof" in d.summary


def test_with_an_excess_the_summary_gives_the_share_it_explains():
    from cmmwb.xlfuncs.locator import diagnose as dg
    from cmmwb.xlfuncs.locator import simulate as sm

    from tests.helpers.clouds import MPE1
    from tests.helpers.locator import iso, u_effect

    L, model = iso()
    rec = sm.simulate(L, MPE1, {"squareness_xy": 5.5 * u_effect(L, model, "squareness_xy")}, seed=10)
    d = dg.diagnose(rec, model)
    excess = d.chi2_before - d.dof_before
    share = d.candidates["squareness_xy"].delta_chi2 / excess
    assert 0 < share < 1
    assert f"{share * 100:.0f} % of the excess is explained by a squareness error" in d.summary


# -- charts: words in the legend, every series visible, the size of the page ---------------------

def _chart_xml(book: Path) -> list[str]:
    with zipfile.ZipFile(book) as z:
        return [z.read(n).decode("utf-8") for n in sorted(z.namelist()) if n.startswith("xl/charts/chart")]


def _drawing_widths_cm(book: Path) -> list[float]:
    with zipfile.ZipFile(book) as z:
        xml = "".join(z.read(n).decode() for n in z.namelist() if re.match(r"xl/drawings/drawing\d+\.xml$", n))
    return [int(cx) / 360000 for cx in re.findall(r'<ext cx="(\d+)"', xml)]


@pytest.fixture(scope="module")
def stepgauge_book(tmp_path_factory):
    return built("stepgauge_I_MPE1.toml", tmp_path_factory.mktemp("stepgauge"))


def test_chart_legends_are_words_not_column_keys(stepgauge_book):
    _, book = stepgauge_book
    xml = "".join(_chart_xml(book))
    assert "K u_S: scale and squareness" in xml and "K u_ET: location errors" in xml
    titles = re.findall(r"<ser>.*?<tx>(.*?)</tx>", xml, re.S)
    assert titles and not [t for t in titles if re.search(r"K_u_\w*_um|K_sigma_A_um", t)]


def test_coinciding_marker_series_differ_in_size(stepgauge_book):
    """LL and RR of the step gauge coincide: LibreOffice draws the first series on top, so the
    sizes grow by 3 points per series (LL small inside RR's diamond)."""
    _, book = stepgauge_book
    budget = next(x for x in _chart_xml(book) if "Expanded uncertainty" in x)
    sizes = [int(v) for v in re.findall(r'<size val="(\d+)"', budget)]
    assert sizes[:3] == [5, 8, 11]


def test_charts_on_their_own_page_are_as_wide_as_the_page(stepgauge_book):
    _, book = stepgauge_book
    wb = openpyxl.load_workbook(book)
    ws = wb["Budget"]
    chars = sum((ws.column_dimensions[c].width or 8.43) for c in
                (openpyxl.utils.get_column_letter(k) for k in range(1, ws.max_column + 1)))
    widths = _drawing_widths_cm(book)
    assert widths and max(widths) >= 0.9 * CM_PER_CHAR * chars > 24   # was a fixed 24 cm


def test_inputs_say_what_a_micrometre_per_millimetre_is(stepgauge_book):
    _, book = stepgauge_book
    text = openpyxl.load_workbook(book)["Inputs"]["G1"].value
    assert "1 µm/mm = 1000 ppm" in text and "0.001 ppm" not in text
