"""The diagnosis and calibration books on paper (issue 32): printed by LibreOffice (the code
behind `--pdf`), every page's smallest text measured from the PDF's own text operators
(`tests.helpers.pdftext.font_sizes`): the report page (`Summary`) at 8 pt and more, every other
page at 7.5 pt and more (the charts' tick labels, 10 pt on a page printed at 75 %); before issue
32 the calibration book printed at 1.4-5.1 pt on 8 of its 12 pages, the diagnosis Records at 3.7
pt."""

from __future__ import annotations

import shutil

import pytest

from cmmwb.generator.calibration.run import parse_mpe, run_calibrate
from cmmwb.generator.diagnosis.run import DEMO_PROBES, load_model, run_diagnose, task_toml
from cmmwb.generator.taskfile import read_toml
from cmmwb.generator.workbook.pdf import print_books
from cmmwb.generator.workbook.recalc import soffice
from cmmwb.xlfuncs.locator import simulate as sm
from cmmwb.xlfuncs.locator.recordings import write_recordings
from cmmwb.xlfuncs.model import MPE1

from tests.helpers.pdftext import font_sizes, sheet_of_pages

pytestmark = pytest.mark.libreoffice

REPORT_PT = 8.0
PAGE_PT = 7.5


@pytest.fixture(scope="module")
def printed(tmp_path_factory):
    """{book: [(sheet, smallest text in pt)]} of a diagnosis (the demo's concealed squareness) and
    a calibration (an ISO 10360-2 test with an indicated squareness and a tight MPE)."""
    if soffice() is None or shutil.which("pdftotext") is None:
        pytest.skip("needs LibreOffice and pdftotext")
    tmp = tmp_path_factory.mktemp("printed")
    (tmp / "task.toml").write_text(task_toml(MPE1, DEMO_PROBES, "machine", "MPE1 machine"))
    model, label = load_model(str(tmp / "task.toml"), None)
    concealed = sm.simulate(sm.iso10360(DEMO_PROBES), MPE1, {"squareness_xy": 9.0}, seed=3, temperature_C=20.0)
    write_recordings(concealed, tmp / "concealed.csv")
    run_diagnose(tmp / "concealed.csv", model, tmp / "diag", plots=False, task_path=tmp / "task.toml",
                 task_label=label)
    iso = sm.simulate(sm.iso10360(DEMO_PROBES), MPE1, {"squareness_xy": 4.0}, seed=1, temperature_C=20.0)
    write_recordings(iso, tmp / "iso.csv")
    mpe = parse_mpe("0.8,400", read_toml(tmp / "task.toml"), model.probes)
    run_calibrate([tmp / "iso.csv"], model, tmp / "cal", task_path=tmp / "task.toml", task_label=label, mpe=mpe)
    books = [tmp / "diag" / "diagnosis.xlsx", tmp / "cal" / "calibration.xlsx"]
    out = {}
    for pdf in print_books(books):
        out[pdf.stem] = [(sheet, min(sizes)) for sheet, sizes in zip(sheet_of_pages(pdf), font_sizes(pdf)) if sizes]
    return out


@pytest.mark.parametrize("book", ["diagnosis", "calibration"])
def test_the_report_page_prints_at_8_pt_and_more(printed, book):
    pages = [(s, pt) for s, pt in printed[book] if s == "Summary"]
    assert pages, f"{book}: no report page printed"
    assert all(pt >= REPORT_PT - 1e-6 for _, pt in pages), pages


@pytest.mark.parametrize("book", ["diagnosis", "calibration"])
def test_every_page_prints_at_7_5_pt_and_more(printed, book):
    small = [(k + 1, s, round(pt, 2)) for k, (s, pt) in enumerate(printed[book]) if pt < PAGE_PT - 1e-6]
    assert not small, f"{book}: pages with text below {PAGE_PT} pt (page, sheet, pt): {small}"
