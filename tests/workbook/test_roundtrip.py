"""The way back: a workbook a person filled in -> `cmmwb read` -> task file -> `cmmwb build`.

* build -> read -> build gives the same JSON for every shipped task (the kinds' templates and
  the papers' worked examples);
* filling a template as a user would (openpyxl edits; and a LibreOffice save of those edits),
  reading it back and rebuilding gives exactly the JSON of the same edits made in the task file;
* `build` never overwrites a workbook someone edited, unless --force, and then keeps a backup;
* cached values: with --cache all every formula cell carries the engine's value.
"""

from __future__ import annotations

import copy
import csv
import io
import json
import os
import shutil
import subprocess
import tomllib
from pathlib import Path

import numpy as np
import openpyxl
import pytest
import tomli_w

from cmmwb.generator import templates
from cmmwb.generator.cli import build_task, main
from cmmwb.generator.jobs import job
from cmmwb.generator.reader import read_to_files
from cmmwb.generator.workbook.recalc import read_cached, results_rows, soffice

from tests.helpers import EXAMPLES, close

SOURCES = templates.sources()


# -- helpers ----------------------------------------------------------------------------------------

def source_task(kind: str, source: Path | None, folder: Path) -> Path:
    """The task file of a template in ``folder`` (copied with its points table)."""
    folder.mkdir(parents=True, exist_ok=True)
    if source is None:
        mod = job(kind)
        path = folder / f"{kind}_task.toml"
        path.write_text(mod.NEW_TASK, encoding="utf-8")
        for name, text in mod.NEW_TASK_FILES.items():
            (folder / name).write_text(text, encoding="utf-8")
        return path
    doc = tomllib.loads(source.read_text(encoding="utf-8"))
    if "points" in doc and "file" in doc["points"]:
        shutil.copy(source.parent / doc["points"]["file"], folder / doc["points"]["file"])
    shutil.copy(source, folder / source.name)
    return folder / source.name


def build(task: Path, out: Path) -> tuple[dict, Path]:
    results, files = build_task(task, out, plots=False)
    return results, next(f for f in files if f.suffix == ".xlsx")


def read_and_build(book: Path, folder: Path) -> dict:
    task = folder / "read" / "task.toml"
    read_to_files(book, task)
    results, _ = build(task, folder / "rebuilt")
    return results


def without_provenance(results: dict) -> dict:
    """The results without "provenance": the task file read back is another file (its SHA-256)
    built at another time; everything computed must be identical."""
    return {k: v for k, v in results.items() if k != "provenance"}


def write_task(doc: dict, folder: Path, name: str = "direct.toml") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(tomli_w.dumps(doc), encoding="utf-8")
    return path


def named_cell(wb, name: str):
    (sheet, coord), = wb.defined_names[name].destinations
    return wb[sheet][coord.replace("$", "")]


def libreoffice_save(book: Path, folder: Path) -> Path:
    """Open and save the workbook in LibreOffice (headless conversion to .xlsx), as a user who
    edits in LibreOffice would leave it."""
    folder.mkdir(parents=True, exist_ok=True)
    profile = folder / "profile"
    r = subprocess.run([soffice(), f"-env:UserInstallation={profile.as_uri()}", "--headless", "--norestore",
                        "--convert-to", "xlsx:Calc MS Excel 2007 XML", "--outdir", str(folder / "lo"), str(book)],
                       capture_output=True, text=True, timeout=300, env={**os.environ, "HOME": str(folder)})
    out = folder / "lo" / book.name
    assert r.returncode == 0 and out.exists(), r.stderr
    return out


def csv_rows(path: Path) -> list[list[str]]:
    lines = [line for line in path.read_text(encoding="utf-8").splitlines() if not line.startswith("#")]
    return list(csv.reader(io.StringIO("\n".join(lines))))


def write_csv(path: Path, rows: list[list]) -> None:
    with open(path, "w", encoding="utf-8", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows(rows)


# -- build -> read -> build ----------------------------------------------------------------------------

@pytest.mark.parametrize("name", sorted(SOURCES))
def test_build_read_build_is_the_identity(tmp_path, name):
    kind, source = SOURCES[name]
    task = source_task(kind, source, tmp_path / "task")
    first, book = build(task, tmp_path / "built")
    assert without_provenance(read_and_build(book, tmp_path)) == without_provenance(first)


def test_read_writes_a_task_file_a_person_can_edit(tmp_path, capsys):
    book = templates.TEMPLATE_DIR / "examples" / "stepgauge_I_MPE1.xlsx"
    out = tmp_path / "mine.toml"
    assert main(["read", str(book), "--out", str(out)]) == 0
    printed = capsys.readouterr().out.split()
    assert printed == [str(out), str(tmp_path / "mine_points.csv")]
    text = out.read_text(encoding="utf-8")
    assert text.startswith("# cmmwb") and 'file = "mine_points.csv"' in text
    assert "offset_mm = [0.0, 0.0, -20.0]" in text           # short arrays on one line
    assert csv_rows(tmp_path / "mine_points.csv")[0] == ["id", "x", "y", "z", "nx", "ny", "nz", "probe"]
    # an existing task file is not overwritten without --force
    assert main(["read", str(book), "--out", str(out)]) == 2
    assert "exists already" in capsys.readouterr().err
    assert main(["read", str(book), "--out", str(out), "--force"]) == 0


# -- filling templates as a user would ----------------------------------------------------------------

def fill_pointcloud(wb) -> None:
    named_cell(wb, "sigma_R_um").value = 0.25
    named_cell(wb, "A_um").value = 1.2
    named_cell(wb, "probe1_pz_mm").value = -30
    named_cell(wb, "probe1_sigma_PQ_um").value = 0.15      # a per-probe override instead of =sigma_PQ_um
    ws = wb["Points"]
    assert ws["A3"].value == "G1R"
    ws["B3"].value = 100.5
    # one more point, added as a new row at the end of the table (structural change)
    for col, v in zip("ABCDEFGH", ["G3", 50, 60, 0, 0, 1, 0, "P1"]):
        ws[f"{col}6"].value = v


def direct_pointcloud(folder: Path) -> Path:
    task = source_task("pointcloud", None, folder)
    doc = tomllib.loads(task.read_text(encoding="utf-8"))
    doc["parameters"]["sigma_R_um"] = 0.25
    doc["mpe"]["A_um"] = 1.2
    doc["probes"][0]["offset_mm"][2] = -30.0
    doc["probes"][0]["sigma_PQ_um"] = 0.15
    rows = csv_rows(folder / "points.csv")
    rows[2][1] = "100.5"
    rows.append(["G3", "50", "60", "0", "0", "1", "0", "P1"])
    write_csv(folder / "points.csv", rows)
    return write_task(doc, folder)


def fill_budget(wb) -> None:
    named_cell(wb, "A_um").value = 2.5
    named_cell(wb, "S4_y_mm").value = 90.5
    named_cell(wb, "S1_position_ted1_mm").value = 45.004
    named_cell(wb, "tol1_measured_mm").value = 0.02         # the Decision sheet: a measured value
    named_cell(wb, "tol3_lsl_mm").value = 89.985            # and a limit of a "90 ± 0.02" tolerance
    named_cell(wb, "tol3_usl_mm").value = 90.03


def direct_budget(folder: Path) -> Path:
    doc = tomllib.loads(source_task("budget", None, folder).read_text(encoding="utf-8"))
    doc["mpe"]["A_um"] = 2.5
    doc["points"]["S4"][1] = 90.5
    doc["characteristics"][1]["ted_mm"][0] = 45.004
    doc["decision"]["tolerances"][0]["measured_mm"] = 0.02
    tol3 = doc["decision"]["tolerances"][2]
    del tol3["tol_mm"]
    tol3.update(lsl_mm=89.985, usl_mm=90.03)
    return write_task(doc, folder)


def fill_feature(wb) -> None:
    named_cell(wb, "sigma_ET_um").value = 0.3
    named_cell(wb, "probe1_px_mm").value = 5
    ws = wb["Local"]
    assert ws["A4"].value == "X3"
    ws["B4"].value = 0.5                                   # weight of point X3
    ws = wb["Planning"]
    top = next(r for r in range(1, 40) if ws.cell(row=r, column=1).value == "arc_deg")
    assert ws.cell(row=top + 1, column=1).value == 360
    ws.cell(row=top + 1, column=1).value = 300             # first planning row: 300 deg


def direct_feature(folder: Path) -> Path:
    doc = tomllib.loads(source_task("feature", None, folder).read_text(encoding="utf-8"))
    doc["parameters"]["sigma_ET_um"] = 0.3
    doc["probes"][0]["offset_mm"][0] = 5.0
    doc["feature"]["weights"] = {"X3": 0.5}
    doc["planning"]["values"][0] = 300
    return write_task(doc, folder)


FILLS = {"pointcloud": (fill_pointcloud, direct_pointcloud), "budget": (fill_budget, direct_budget),
         "feature": (fill_feature, direct_feature)}
LO = pytest.mark.libreoffice


# the LibreOffice-saved copy is LibreOffice's file, not cmmwb's: the Open XML check leaves it alone
@pytest.mark.parametrize("via", ["openpyxl", pytest.param("libreoffice", marks=[LO, pytest.mark.foreign_books])])
@pytest.mark.parametrize("kind", list(FILLS))
def test_a_filled_template_reads_back_to_the_same_results(tmp_path, kind, via):
    fill, direct = FILLS[kind]
    wb = openpyxl.load_workbook(templates.TEMPLATE_DIR / f"{kind}_template.xlsx")
    fill(wb)
    book = tmp_path / "filled.xlsx"
    wb.save(book)
    if via == "libreoffice":
        book = libreoffice_save(book, tmp_path / "office")
    rebuilt = read_and_build(book, tmp_path)
    expected, _ = build(direct(tmp_path / "direct"), tmp_path / "direct_out")
    assert without_provenance(rebuilt) == without_provenance(expected)


def test_moving_a_sampled_point_turns_the_sampling_into_a_points_table(tmp_path):
    """A feature built from a [sampling] strategy whose points were edited is read back as a
    [points] table; the results are those of the same table written by hand."""
    from cmmwb.generator.taskfile import read_toml

    example = EXAMPLES / "feature_table8_sphere_six.toml"
    _, book = build(example, tmp_path / "built")
    wb = openpyxl.load_workbook(book)
    wb["Points"]["D3"].value = wb["Points"]["D3"].value + 0.002   # z of the second point, +2 µm
    wb.save(tmp_path / "moved.xlsx")
    read_to_files(tmp_path / "moved.xlsx", tmp_path / "read" / "t.toml")
    doc = tomllib.loads((tmp_path / "read" / "t.toml").read_text(encoding="utf-8"))
    assert "sampling" not in doc and doc["points"] == {"file": "t_points.csv"}
    rebuilt, _ = build(tmp_path / "read" / "t.toml", tmp_path / "rebuilt")

    mod = job("feature")
    task = mod.load(example, read_toml(example))
    X = task.cloud.X_mm.copy()
    X[1, 2] = float(np.float64(X[1, 2]) + 0.002)
    rows = [["id", "x", "y", "z", "nx", "ny", "nz", "probe"]]
    for i, lab in enumerate(task.cloud.labels):
        rows.append([lab, *(repr(float(v)) for v in X[i]), *(repr(float(v)) for v in task.cloud.N[i]),
                     task.cloud.probes[0].id])
    direct = tmp_path / "direct"
    direct.mkdir()
    write_csv(direct / "pts.csv", rows)
    ddoc = copy.deepcopy(read_toml(example))
    sampling = ddoc.pop("sampling")
    ddoc["points"] = {"file": "pts.csv"}
    if "planning" in ddoc:
        ddoc["planning"].setdefault("pattern", sampling["pattern"])
    expected, _ = build(write_task(ddoc, direct), tmp_path / "direct_out")
    assert rebuilt["feature"] == expected["feature"]


def test_a_point_table_edit_of_a_csv_feature(tmp_path):
    """plane_face reads its points from a CSV: an edited coordinate and weight come back."""
    source = source_task("feature", EXAMPLES / "feature_plane_face.toml", tmp_path / "task")
    _, book = build(source, tmp_path / "built")
    wb = openpyxl.load_workbook(book)
    ws = wb["Points"]
    label = ws["A4"].value
    ws["D4"].value = 0.004
    local = wb["Local"]
    assert local["A4"].value == label
    local["B4"].value = 0.25
    wb.save(tmp_path / "edited.xlsx")
    rebuilt = read_and_build(tmp_path / "edited.xlsx", tmp_path)

    doc = tomllib.loads(source.read_text(encoding="utf-8"))
    rows = csv_rows(source.parent / doc["points"]["file"])
    row = next(r for r in rows if r[0] == label)
    row[3] = "0.004"
    write_csv(source.parent / doc["points"]["file"], rows)
    doc["feature"]["weights"] = {**doc["feature"].get("weights", {}), label: 0.25}
    expected, _ = build(write_task(doc, source.parent), tmp_path / "direct_out")
    assert without_provenance(rebuilt) == without_provenance(expected)


# -- build never overwrites a workbook someone edited ---------------------------------------------------

@pytest.fixture
def small_task(tmp_path):
    return source_task("pointcloud", None, tmp_path / "task")


def test_rebuilding_into_the_same_folder_replaces_what_cmmwb_wrote(tmp_path, small_task):
    out = tmp_path / "out"
    build(small_task, out)
    build(small_task, out)                               # unchanged outputs: replaced silently
    assert not list(out.glob("*.bak"))
    manifest = json.loads((out / ".cmmwb-manifest.json").read_text())
    assert set(manifest["files"]) == {"my_pointcloud.xlsx", "my_pointcloud.json"}


def test_an_edited_workbook_is_not_overwritten_without_force(tmp_path, small_task, capsys):
    out = tmp_path / "out"
    _, book = build(small_task, out)
    wb = openpyxl.load_workbook(book)
    named_cell(wb, "sigma_R_um").value = 0.3
    wb.save(book)
    edited = book.read_bytes()
    code = main(["build", str(small_task), "--out", str(out), "--no-plots"])
    err = capsys.readouterr().err
    assert code == 2 and "my_pointcloud.xlsx" in err and "--force" in err and len(err.strip().splitlines()) == 1
    assert book.read_bytes() == edited                   # untouched
    assert not list(out.glob("*.bak")) and not [p for p in out.iterdir() if p.is_dir()]
    # --force replaces it and keeps the edited one as a backup
    assert main(["build", str(small_task), "--out", str(out), "--no-plots", "--force"]) == 0
    assert (out / "my_pointcloud.xlsx.bak").read_bytes() == edited
    assert "backup" in capsys.readouterr().err
    # a second forced build after another edit keeps both backups
    wb.save(book)
    assert main(["build", str(small_task), "--out", str(out), "--no-plots", "--force"]) == 0
    assert len(list(out.glob("my_pointcloud.xlsx*.bak"))) == 2


def test_a_file_cmmwb_did_not_write_is_not_overwritten(tmp_path, small_task, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "my_pointcloud.json").write_text("{}")
    assert main(["build", str(small_task), "--out", str(out), "--no-plots"]) == 2
    assert "my_pointcloud.json" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["my_pointcloud.json"]


# -- cached values -------------------------------------------------------------------------------------

def test_cache_all_gives_every_formula_cell_a_value(tmp_path, small_task):
    """--cache all: every formula cell, and every cell of every array formula, carries the value
    the `formulas` engine computed; V_X equals the core's, Results the JSON (1e-9)."""
    from cmmwb.xlfuncs import pointcloud as pc

    mod = job("pointcloud")
    results, files = build_task(small_task, tmp_path / "out", plots=False, cache="all")
    book = next(f for f in files if f.suffix == ".xlsx")
    cached = read_cached(book)
    wb = openpyxl.load_workbook(book)
    formula_cells = [(ws.title, c.coordinate) for ws in wb.worksheets for row in ws.iter_rows() for c in row
                     if c.data_type == "f" or type(c.value).__name__ == "ArrayFormula"]
    assert formula_cells and all(coord in cached[sheet] for sheet, coord in formula_cells)
    from cmmwb.generator.taskfile import read_toml

    task = mod.load(small_task, read_toml(small_task))
    VX = sum(pc.V_X_components(task.cloud, task.params).values())
    m = task.cloud.m
    for i in range(3 * m):
        for j in range(3 * m):
            coord = f"{openpyxl.utils.get_column_letter(2 + j)}{2 + i}"
            assert close(cached["V_X"][coord], float(VX[i, j]), floor=1e-15), coord
    rows = results_rows(cached)
    assert len(rows) == len(results["distances"])
    for d, row in zip(results["distances"], rows):
        assert close(row["u_um"], d["u_um"]) and close(row["U_um"], d["U_um"])


def test_labels_that_look_like_formulas_come_back_in_the_task_file_not_a_csv(tmp_path):
    """A CSV opened in a spreadsheet would turn `=SUM(A1)` into a formula: `read` keeps such
    points in the task file (`[points] rows`), and the rebuild gives the same results."""
    from tests.helpers.tasks import write_random_task

    task = write_random_task(tmp_path, 5, m=5, probes=2, labels=["=SUM(A1)", "+1", "-2", "@x", "Q5"], mpe=False)
    first, book = build(task, tmp_path / "b1")
    again = read_and_build(book, tmp_path / "read")
    assert again["distances"] == first["distances"]
    doc = tomllib.loads((tmp_path / "read" / "read" / "task.toml").read_text(encoding="utf-8"))
    assert [r["id"] for r in doc["points"]["rows"]] == ["=SUM(A1)", "+1", "-2", "@x", "Q5"]
    assert not list((tmp_path / "read" / "read").glob("*.csv"))


# -- the part's temperature (the factor W, docs/workpiece.md) -------------------------------------------

def test_switching_W_on_in_a_workbook_reads_back_as_a_workpiece_table(tmp_path):
    """A point-cloud book built without [workpiece] has the part's inputs with W off; typing the
    part's values and workpiece_enabled = 1 reads back as [workpiece] (enabled = true) and rebuilds
    to the results of that task file."""
    kind, source = SOURCES["examples/stepgauge_I_MPE1.xlsx"]
    task = source_task(kind, source, tmp_path / "task")
    _, book = build(task, tmp_path / "built")
    wb = openpyxl.load_workbook(book)
    edits = {"workpiece_enabled": 1, "workpiece_alpha_ppm_per_K": 11.5, "workpiece_u_alpha_ppm_per_K": 1.0,
             "workpiece_T_degC": 22.0, "workpiece_u_T_K": 0.2}
    for name, value in edits.items():
        named_cell(wb, name).value = value
    wb.save(tmp_path / "edited.xlsx")
    back = tmp_path / "read" / "task.toml"
    read_to_files(tmp_path / "edited.xlsx", back)
    doc = tomllib.loads(back.read_text(encoding="utf-8"))
    assert doc["workpiece"] == {"enabled": True, "alpha_ppm_per_K": 11.5, "T_degC": 22.0,
                                "u_alpha_ppm_per_K": 1.0, "u_T_K": 0.2}
    direct = tomllib.loads(task.read_text(encoding="utf-8"))
    direct["workpiece"] = {"alpha_ppm_per_K": 11.5, "u_alpha_ppm_per_K": 1.0, "T_degC": 22.0, "u_T_K": 0.2}
    shutil.copy(task.parent / direct["points"]["file"], tmp_path / direct["points"]["file"])
    want, _ = build(write_task(direct, tmp_path), tmp_path / "direct")
    got, _ = build(back, tmp_path / "rebuilt")
    assert without_provenance(got) == without_provenance(want)
    assert got["distances"][-1]["components_um"]["W"] > 0


def test_a_budget_with_the_part_temperature_reads_back_to_itself(tmp_path):
    source = EXAMPLES / "knuckle.toml"
    doc = tomllib.loads(source.read_text(encoding="utf-8"))
    doc["workpiece"] = {"material": "aluminium", "u_alpha_ppm_per_K": 1.0, "T_readings_degC": [23.3, 23.7],
                        "u_T_K": 0.3, "corrected": False}
    first, book = build(write_task(doc, tmp_path / "task", "knuckle.toml"), tmp_path / "built")
    again = read_and_build(book, tmp_path)
    # the same warning (the uncorrected expansion), naming the task file it was read from
    assert [w.split(", ", 1)[1] for w in again.pop("warnings")] == [w.split(", ", 1)[1] for w in first.pop("warnings")]
    assert without_provenance(again) == without_provenance(first)
    back = tomllib.loads((tmp_path / "read" / "task.toml").read_text(encoding="utf-8"))
    assert back["workpiece"] == doc["workpiece"]
