"""Traceable outputs: every output names its inputs (SHA-256), the build time and the cmmwb
version; the optional [report] fields; the Summary sheet, the inspection report; and outputs that stay
consistent (a build removes what its task's previous build wrote and this one does not write)."""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import subprocess
import tomllib
from pathlib import Path

import openpyxl
import pytest
import tomli_w

from cmmwb.generator import __version__
from cmmwb.generator.build import build_task
from cmmwb.generator.errors import InputError
from cmmwb.generator.workbook.atomic import Staging

from tests.helpers import EXAMPLES, ROOT


def sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def copy_task(tmp: Path, name: str, edit=None) -> Path:
    doc = tomllib.loads((EXAMPLES / name).read_text(encoding="utf-8"))
    if edit is not None:
        edit(doc)
    for f in EXAMPLES.glob("*.csv"):
        shutil.copyfile(f, tmp / f.name)
    task = tmp / name
    task.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return task


REPORT = {"lab": "Dimensional lab, room 2", "operator": "A. Auditor", "cmm": "CMM-07 (Zeiss Prismo)",
          "artefact": "steering knuckle SN 4711", "job_id": "J-2026-0815", "notes": ["first article", "20 °C"]}


@pytest.fixture(scope="module")
def plane(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("plane")
    task = copy_task(tmp, "feature_plane_face.toml", lambda d: d.update(report=REPORT))
    results, files = build_task(task, tmp / "out", plots=False)
    return task, results, files


def test_json_names_the_task_file_and_the_points_file_by_sha256(plane):
    task, results, _ = plane
    prov = results["provenance"]
    assert prov["task_file"] == {"name": task.name, "sha256": sha(task)}
    assert prov["input_files"] == [{"name": "feature_plane_face.csv", "sha256": sha(task.parent / "feature_plane_face.csv")}]
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", prov["built_utc"])
    assert prov["cmmwb_version"] == __version__


def test_report_fields_in_the_json_and_on_the_summary_sheet(plane):
    _, results, files = plane
    assert results["report"] == REPORT
    on_disk = json.loads(next(f for f in files if f.suffix == ".json").read_text(encoding="utf-8"))
    assert on_disk["report"] == REPORT and on_disk["provenance"] == results["provenance"]
    ws = openpyxl.load_workbook(next(f for f in files if f.suffix == ".xlsx"))["Summary"]
    text = "\n".join(str(c.value) for row in ws.iter_rows() for c in row if c.value is not None)
    for value in ("Dimensional lab, room 2", "A. Auditor", "CMM-07 (Zeiss Prismo)", "steering knuckle SN 4711",
                  "J-2026-0815", "first article", results["provenance"]["task_file"]["sha256"],
                  results["provenance"]["built_utc"]):
        assert value in text


def test_the_summary_prints_to_the_page_width_with_its_table_header_repeated(plane):
    """As many pages as it needs (issue 32: the one-page squeeze printed at a tenth of the sheet),
    scaled to the page width only, the row of column headers repeated on every page."""
    _, _, files = plane
    ws = openpyxl.load_workbook(next(f for f in files if f.suffix == ".xlsx"))["Summary"]
    assert ws.page_setup.fitToWidth == 1 and ws.page_setup.fitToHeight == 0
    assert ws.sheet_properties.pageSetUpPr.fitToPage and ws.page_setup.orientation == "landscape"
    first, last = (int(x) for x in ws.print_title_rows.replace("$", "").split(":"))
    assert first == last and ws.cell(first, 1).value == "characteristic" and ws.cell(first, 2).value == "nominal"
    assert ws.print_area is not None


def test_build_time_is_fixed_by_source_date_epoch(tmp_path, monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1735689600")
    task = copy_task(tmp_path, "feature_plane_face.toml")
    results, _ = build_task(task, tmp_path / "out", plots=False)
    assert results["provenance"]["built_utc"] == "2025-01-01T00:00:00Z"


@pytest.mark.parametrize("report, where", [
    ({"lab": 3}, "[report] lab"),
    ({"operator": "x", "badge": "7"}, "[report]"),
    ({"notes": ["ok", 1]}, "[report] notes"),
])
def test_bad_report_fields_name_the_key(tmp_path, report, where):
    task = copy_task(tmp_path, "feature_plane_face.toml", lambda d: d.update(report=report))
    with pytest.raises(InputError) as e:
        build_task(task, tmp_path / "out", plots=False)
    assert where in str(e.value)


# -- outputs stay consistent -----------------------------------------------------------------------

def manifest(out: Path) -> dict:
    return json.loads((out / Staging.MANIFEST).read_text(encoding="utf-8"))


def test_a_build_without_plots_removes_the_previous_builds_plots(tmp_path):
    task = copy_task(tmp_path, "feature_plane_face.toml")
    out = tmp_path / "out"
    _, first = build_task(task, out, plots=True)
    pngs = [f for f in first if f.suffix == ".png"]
    assert pngs and all(p.exists() for p in pngs)
    _, second = build_task(task, out, plots=False, force=True)
    assert not any(p.exists() for p in pngs)
    m = manifest(out)
    assert set(m["files"]) == {f.name for f in second} == set(m["tasks"]["plane_face"])
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == sorted(m["files"])


def test_an_edited_stale_file_is_kept_as_a_backup_not_deleted(tmp_path):
    task = copy_task(tmp_path, "feature_plane_face.toml")
    out = tmp_path / "out"
    _, first = build_task(task, out, plots=True)
    png = next(f for f in first if f.suffix == ".png")
    png.write_bytes(b"edited by someone")
    with pytest.raises(InputError, match="changed since cmmwb wrote it"):
        build_task(task, out, plots=False)
    assert png.read_bytes() == b"edited by someone"
    build_task(task, out, plots=False, force=True)
    assert not png.exists() and (out / (png.name + ".bak")).read_bytes() == b"edited by someone"


def test_other_tasks_outputs_in_the_same_folder_are_left_alone(tmp_path):
    out = tmp_path / "out"
    plane = copy_task(tmp_path, "feature_plane_face.toml")
    bore = copy_task(tmp_path, "feature_cylinder_bore.toml")
    _, bore_files = build_task(bore, out, plots=True)
    build_task(plane, out, plots=True)
    build_task(plane, out, plots=False, force=True)
    assert all(f.exists() for f in bore_files)
    assert set(manifest(out)["tasks"]) == {"plane_face", "cylinder_bore"}


@pytest.mark.libreoffice
def test_build_pdf_then_build_without_pdf_leaves_no_old_pdf(tmp_path):
    """The issue's case: `build --pdf`, then `build --force` without --pdf (through the CLI)."""
    task = copy_task(tmp_path, "knuckle.toml")
    out = tmp_path / "out"
    cmd = [str(ROOT / ".venv" / "bin" / "cmmwb"), "build", str(task), "--out", str(out)]
    subprocess.run(cmd + ["--pdf", "--no-plots"], check=True, capture_output=True)
    pdf = out / "knuckle.pdf"
    assert pdf.exists() and "knuckle.pdf" in manifest(out)["files"]
    subprocess.run(cmd + ["--force", "--no-plots"], check=True, capture_output=True)
    assert not pdf.exists()
    m = manifest(out)
    assert set(m["files"]) == {"knuckle.xlsx", "knuckle.json"} == {p.name for p in out.iterdir() if not p.name.startswith(".")}


@pytest.mark.libreoffice
def test_the_summary_pages_of_the_pdf(tmp_path):
    """Printed by LibreOffice, the Summary sheet (footer: its name) holds the report: header,
    report fields, each result's statement with the coverage probability of its k, the rule's
    outcome and the conformity statement; a page after the first starts with the table's header."""
    if shutil.which("pdftotext") is None:
        pytest.skip("pdftotext (poppler-utils) not installed")
    task = copy_task(tmp_path, "knuckle.toml", lambda d: d.update(report=REPORT))
    _, files = build_task(task, tmp_path / "out", plots=False, pdf=True)
    pdf = next(f for f in files if f.suffix == ".pdf")
    pages = int(re.search(r"Pages:\s+(\d+)", subprocess.run(["pdfinfo", str(pdf)], capture_output=True,
                                                            text=True).stdout).group(1))
    summary_pages = []
    for p in range(1, pages + 1):
        text = subprocess.run(["pdftotext", "-f", str(p), "-l", str(p), "-layout", str(pdf), "-"],
                              capture_output=True, text=True).stdout
        if "Summary — knuckle" in text or re.search(r"^\s*Summary\s+page", text, re.M):
            summary_pages.append((p, text))
    assert len(summary_pages) >= 1 and summary_pages[-1][0] == pages, [p for p, _ in summary_pages]
    text = "\n".join(t for _, t in summary_pages)
    assert "S3_position = 0.041 mm, U = 11 µm (k = 2, coverage probability ≈ 95.45 %)" in text
    assert "S1_S2_distance = 90.0120 mm, U = 4.6 µm (k = 2.04, coverage probability ≈ 95.45 %)" in text
    assert "cannot be decided" in text and "neither proven" in text and "A. Auditor" in text
    for _, page in summary_pages[1:]:
        assert page.lstrip().startswith("characteristic") and "conformity" in page.splitlines()[0]
