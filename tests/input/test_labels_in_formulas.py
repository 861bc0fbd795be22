"""User text never inside formula text, outside the Summary and Decision sheets (issue 33; those two
sheets and their readback test are issue 32's): point ids, probe ids, groups, feature, frame and
characteristic names that hold quotes or start with ``=``, ``@``, ``+``, ``-`` are cells of text
that formulas refer to (EXACT of a probe cell, never the id pasted into a string), and the labels
the locator builds from them (``PROBE.dx``, ``PROBE.c2``, ``ID.x``) are parsed from the right, so
a probe called ``=HYPERLINK("http://b.de","x")`` is diagnosed like ``P2``."""

from __future__ import annotations

import csv
import io
import json
import re
import zipfile
from pathlib import Path

import pytest

from cmmwb.generator.cli import main
from cmmwb.generator.workbook.recalc import results_rows

from tests.helpers import ENGINES, EXAMPLES, close, recalc
from tests.helpers.locator import expected_rows

#: every hostile label holds this token, so a formula that holds user text is found by it
TOKEN = "ZQX"
PROBE = f'=HYPERLINK("http://b.de","{TOKEN}")'
MACHINE = f'''[task]
kind = "pointcloud"
name = "machine"

[parameters]
sigma_R_um = 0.2
sigma_PQ_um = 0.2

[[probes]]
id = "@{TOKEN}1"
offset_mm = [0.0, 0.0, -50.0]

[[probes]]
id = {json.dumps(PROBE)}
offset_mm = [30.0, 0.0, -50.0]
'''
IDS = (f"={TOKEN}", f'@{TOKEN}"q"', f"+cmd|' /C calc'!{TOKEN}", f"-{TOKEN}.x", f"{TOKEN}:1.dx")


def run(*args) -> int:
    return main([str(a) for a in args])


def formulas_with_user_text(book: Path, skip=("Summary", "Decision")) -> list[tuple[str, str]]:
    """(part, formula) of every formula of the workbook (cells, defined names, charts) that holds the
    token, outside the sheets ``skip``."""
    with zipfile.ZipFile(book) as z:
        wb = z.read("xl/workbook.xml").decode()
        rels = z.read("xl/_rels/workbook.xml.rels").decode()
        target = dict(re.findall(r'Id="(rId\d+)"[^>]*Target="/?(?:xl/)?([^"]+)"', rels)
                      + [(b, a) for a, b in re.findall(r'Target="/?(?:xl/)?([^"]+)"[^>]*Id="(rId\d+)"', rels)])
        skipped = {"xl/" + target[rid] for name, rid in re.findall(r'<sheet [^>]*name="([^"]+)"[^>]*r:id="(rId\d+)"', wb)
                   if name in skip}
        hits = []
        for part in z.namelist():
            if not part.endswith(".xml") or part in skipped:
                continue
            text = z.read(part).decode("utf-8")
            for f in re.findall(r"<(?:\w+:)?f\b[^>]*>(.*?)</(?:\w+:)?f>", text, flags=re.S) + \
                    re.findall(r"<definedName\b[^>]*>(.*?)</definedName>", text, flags=re.S):
                if TOKEN in f:
                    hits.append((part, f))
        return hits


def hostile_recordings(tmp: Path, effect: str) -> Path:
    """Point recordings of the spheres layout measured with the machine's two probes, the second
    one (``PROBE``) with ``effect`` planted, and every record id replaced by a hostile one."""
    (tmp / "machine.toml").write_text(MACHINE, encoding="utf-8")
    assert run("simulate", "--layout", "spheres", "--task", tmp / "machine.toml", "--effect", effect,
               "--out", tmp / "sim.csv") == 0
    lines = (tmp / "sim.csv").read_text(encoding="utf-8").splitlines()
    out, header = [], None
    for line in lines:
        if line.startswith("#"):
            out.append(line)
            continue
        row = next(csv.reader([line]))
        if header is None:
            header = row
        else:
            k = len(out)
            row[header.index("id")] = f"{IDS[k % len(IDS)]}{k}"
            row[header.index("group")] = f'="{TOKEN} {row[header.index("group")]}"'
        buf = io.StringIO()
        csv.writer(buf, lineterminator="").writerow(row)
        out.append(buf.getvalue())
    path = tmp / "rec.csv"
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hostile_diagnose")
    rec = hostile_recordings(tmp, f"probe_qualification={PROBE}:5,0,0")
    assert run("diagnose", rec, "--task", tmp / "machine.toml", "--out", tmp / "diag", "--no-plots") == 0
    ids = [r["id"] for r in csv.DictReader(line for line in rec.read_text(encoding="utf-8").splitlines()
                                           if not line.startswith("#"))]
    return json.loads((tmp / "diag" / "diagnosis.json").read_text(encoding="utf-8")), tmp / "diag" / "diagnosis.xlsx", ids


def test_a_probe_named_like_a_formula_is_located_like_any_probe(diagnosed):
    """The planted 5 µm qualification error of the probe =HYPERLINK("http://b.de","ZQX") (before
    issue 33: ValueError splitting 'http://b.de").dx' at '.d', exit 1)."""
    result = diagnosed[0]
    e = next(e for e in result["effects"] if e["name"] == "probe_qualification")
    pp = {p["probe"]: p for p in e["per_probe"]}
    assert set(pp) == {PROBE}
    assert abs(e["estimate"][0] - 5.0) < 4 * e["u"][0]


@pytest.mark.parametrize("engine", ENGINES)
def test_its_workbook_recomputes_the_json_with_the_labels_as_text(diagnosed, engine):
    result, book, given = diagnosed
    values = recalc(book, engine)
    rows = {r["quantity"]: r for r in results_rows(values)}
    exp, unc = expected_rows(result)
    assert set(rows) == set(exp)
    for q, v in exp.items():
        assert close(rows[q]["value"], v), f"{engine}: {q} {rows[q]['value']!r} != {v!r}"
        if q in unc:
            assert close(rows[q]["u"], unc[q]), f"{engine}: u({q})"
    errors = [(s, c, v) for s, cells in values.items() for c, v in cells.items()
              if isinstance(v, str) and v.startswith("#")]
    assert not errors, errors[:5]
    ids = {v for v in values["Points"].values() if isinstance(v, str) and TOKEN in v}
    assert set(given) <= ids and len(given) == 104            # every id as it was given, as text
    assert PROBE in ids and any(v.startswith(f'="{TOKEN} sphere') for v in ids)    # probe and group too


def test_no_formula_of_the_diagnosis_holds_user_text(diagnosed):
    assert formulas_with_user_text(diagnosed[1]) == []


def test_probe_lobing_of_a_probe_whose_id_holds_dots(tmp_path):
    """PROBE.c2 was split at the first dot: the id's own 'b.de' broke it."""
    rec = hostile_recordings(tmp_path, f"probe_lobing={PROBE}:3,0,0,0,0,0")
    assert run("diagnose", rec, "--task", tmp_path / "machine.toml", "--out", tmp_path / "d", "--no-plots") == 0
    result = json.loads((tmp_path / "d" / "diagnosis.json").read_text(encoding="utf-8"))
    e = next(e for e in result["effects"] if e["name"] == "probe_lobing")
    assert abs(e["estimate"][6] - 3.0) < 4 * e["u"][6]         # c2 of the second probe (P1's six first)
    assert formulas_with_user_text(tmp_path / "d" / "diagnosis.xlsx") == []


def hostile_characteristic_task(tmp: Path) -> Path:
    """The demo plate with formula-like feature, frame and characteristic names and point ids."""
    names = {"H1": f'=H1"{TOKEN}"', "ABC": f"@{TOKEN} ABC", "dia_H1": f'dia "{TOKEN} H1"',
             "pos_H1_MMC": f"+cmd|' /C calc'!{TOKEN}"}
    toml = (EXAMPLES / "characteristic_plate.toml").read_text(encoding="utf-8")
    for old, new in names.items():
        toml = re.sub(rf'"{re.escape(old)}"', json.dumps(new), toml)
    toml = toml.replace('id_prefix = "H1."', f'id_prefix = "={TOKEN}H1."')
    (tmp / "plate.toml").write_text(toml, encoding="utf-8")
    pts = (EXAMPLES / "characteristic_plate.csv").read_text(encoding="utf-8")
    (tmp / "characteristic_plate.csv").write_text(re.sub(r"(?m)^H1\.", f"={TOKEN}H1.", pts), encoding="utf-8")
    return tmp / "plate.toml"


def hostile_pointcloud_task(tmp: Path) -> Path:
    rows = ["id,x,y,z,nx,ny,nz,probe"] + [
        f'"{IDS[k]}{k}",{100 * k},{7 * k},{3 * k},1,0,0,"{PROBE if k % 2 else f"@{TOKEN}1"}"'.replace(
            PROBE, PROBE.replace('"', '""')) for k in range(len(IDS))]
    (tmp / "cloud.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    (tmp / "cloud.toml").write_text(MACHINE.replace('name = "machine"', 'name = "cloud"')
                                    + f'\n[points]\nfile = "cloud.csv"\n\n[[distances]]\nfrom = "{IDS[0]}0"\n'
                                    f'to = "*"\ngroup = {json.dumps("=" + TOKEN + chr(34))}\n', encoding="utf-8")
    return tmp / "cloud.toml"


def hostile_feature_task(tmp: Path) -> Path:
    """The milled face of the feature examples with formula-like point and probe ids."""
    pts = (EXAMPLES / "feature_plane_face.csv").read_text(encoding="utf-8")
    pts = re.sub(r"(?m)^F(\d+),", lambda m: f'"=F{m.group(1)}""{TOKEN}""",', pts)
    pts = re.sub(r",P2$", f',@{TOKEN}2', pts, flags=re.M)
    (tmp / "feature_plane_face.csv").write_text(pts, encoding="utf-8")
    toml = (EXAMPLES / "feature_plane_face.toml").read_text(encoding="utf-8")
    toml = toml.replace('id = "P2"', f'id = "@{TOKEN}2"').replace("weights = { F13 = 0.5 }",
                                                                   f"weights = {{ {json.dumps(f'=F13{chr(34)}{TOKEN}{chr(34)}')} = 0.5 }}")
    (tmp / "face.toml").write_text(toml, encoding="utf-8")
    return tmp / "face.toml"


@pytest.mark.parametrize("make", [hostile_pointcloud_task, hostile_characteristic_task, hostile_feature_task])
def test_no_formula_of_a_built_book_holds_user_text_outside_summary_and_decision(tmp_path, make):
    task = make(tmp_path)
    assert run("build", task, "--out", tmp_path / "out", "--no-plots") == 0
    books = list((tmp_path / "out").glob("*.xlsx"))
    assert len(books) == 1
    assert formulas_with_user_text(books[0]) == []


def test_no_formula_of_the_calibration_holds_user_text(diagnosed, tmp_path):
    """The same recordings calibrated: records, residuals and the fitted task's probes by their ids."""
    rec = diagnosed[1].parent.parent / "rec.csv"
    assert run("calibrate", rec, "--task", rec.parent / "machine.toml", "--out", tmp_path / "cal",
               "--effects", "probe_qualification", "--profiles", "no") == 0
    assert formulas_with_user_text(tmp_path / "cal" / "calibration.xlsx") == []
    fitted = (tmp_path / "cal" / "fitted.toml").read_text(encoding="utf-8")
    assert json.dumps(PROBE) in fitted


def test_extra_columns_of_recordings_named_like_formulas_or_like_cmmwb_columns(tmp_path):
    """An extra column headed =HYPERLINK("http://ZQX") stopped diagnose with KeyError:
    '=HYPERLINK("http' (its name was parsed as an effect's column 'name:label'); one headed
    residual_um took the key of the derived column.  Both are the user's columns, shown as given
    (the second marked as the recordings'), their cells text, the refit unchanged."""
    assert run("simulate", "--layout", "iso10360", "--sigma-um", "0.3", "--out", tmp_path / "sim.csv") == 0
    lines, out, header = (tmp_path / "sim.csv").read_text(encoding="utf-8").splitlines(), [], False
    for line in lines:
        if not line.startswith("#") and not header:
            line, header = line + f',"=HYPERLINK(""http://{TOKEN}"")",residual_um', True
        elif not line.startswith("#"):
            line += f",@SUM({TOKEN}),note"
        out.append(line)
    (tmp_path / "rec.csv").write_text("\n".join(out) + "\n", encoding="utf-8")
    assert run("diagnose", tmp_path / "rec.csv", "--sigma-um", "0.3", "--out", tmp_path / "d", "--no-plots") == 0
    book = tmp_path / "d" / "diagnosis.xlsx"
    result = json.loads((tmp_path / "d" / "diagnosis.json").read_text(encoding="utf-8"))
    values = recalc(book, "formulas")
    heads = [v for k, v in values["Records"].items() if re.fullmatch(r"[A-Z]+1", k)]
    assert f'=HYPERLINK("http://{TOKEN}")' in heads and "residual_um (recordings)" in heads
    assert heads.count("residual_um") == 1
    rows = {r["quantity"]: r for r in results_rows(values)}
    exp, _ = expected_rows(result)
    assert all(close(rows[q]["value"], v) for q, v in exp.items())
    assert formulas_with_user_text(book) == []
