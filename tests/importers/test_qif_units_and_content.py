"""QIF characteristics read as the file means them (issue 33): one unit reader for points and
characteristics (inch by LinearUnit factor 0.0254 or by name alone, metre, mm give the same values
and u in mm, and the u written back is in the file's own unit); what a file says that cannot be
decided is said (a negative ToleranceValue, a zone of 0 RFS); positions at MMC carry the bonus of
the diameter measured on their feature; a reference to a feature the file does not have, or a
point set id used twice, is an error naming the element; an item measured several times per part
shows every value; and the route from a file's characteristics to a task ``cmmwb build`` decides,
with the stand-in part said in the task and its outputs.

The NIST excerpt (tests/data/qif/nist_sms_plate_excerpt.qif, its source in the README there) holds
NIST's own -0.13 ToleranceValue and MAXIMUM position, in mm; the inch and metre files are the same
file with every length divided by 25.4 or 1000 and its FileUnits changed, written by the tests."""

from __future__ import annotations

import json
import re
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from cmmwb.generator.cli import main
from cmmwb.generator.errors import InputError
from cmmwb.generator.importers import qif_characteristics as qc
from cmmwb.generator.importers import qif_simulation as qs
from cmmwb.generator.importers import run_import

from tests.helpers import ROOT
from tests.helpers.files import assert_clear_failure

DATA = ROOT / "tests" / "data" / "qif"
EXCERPT = DATA / "nist_sms_plate_excerpt.qif"
SAMPLE = DATA / "QIF_PTS_SAMPLE.QIF"
NS = "{http://qifstandards.org/xsd/qif2}"
#: the elements of the excerpt that hold lengths (its five characteristics are all lengths)
LENGTHS = ("ToleranceValue", "MinValue", "MaxValue", "TargetValue", "Value", "Diameter", "AxisPoint",
           "Location")

UNITS = {
    "mm": None,
    "inch_by_factor": ("inch", "0.0254", 25.4),
    "inch_by_name": ("inch", None, 25.4),          # no UnitConversion: was read as metres
    "metre": ("meter", "1", 1000.0),
}


def in_units(tmp: Path, key: str) -> Path:
    """The excerpt with its lengths in another unit and FileUnits saying so."""
    if UNITS[key] is None:
        return EXCERPT
    name, factor, mm = UNITS[key]
    ET.register_namespace("", NS[1:-1])
    tree = ET.parse(EXCERPT)
    for el in tree.getroot().iter():
        if isinstance(el.tag, str) and el.tag.removeprefix(NS) in LENGTHS and el.text:
            el.text = " ".join(repr(float(v) / mm) for v in el.text.split())
    lu = tree.getroot().find(f"{NS}FileUnits/{NS}PrimaryUnits/{NS}LinearUnit")
    lu.find(f"{NS}UnitName").text = name
    conv = lu.find(f"{NS}UnitConversion")
    if factor is None:
        lu.remove(conv)
    else:
        conv.find(f"{NS}Factor").text = factor
    path = tmp / f"plate_{key}.qif"
    tree.write(path, encoding="utf-8", xml_declaration=True)
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("units")
    return {key: in_units(tmp, key) for key in UNITS}


def written_u(path: Path) -> dict[str, str]:
    """combinedUncertainty of the first part's values in a copy, by characteristic actual id."""
    return {a.get("id"): a.find(f"{NS}Value").get("combinedUncertainty") for a in ET.parse(path).getroot().iter()
            if isinstance(a.tag, str) and a.tag.endswith("CharacteristicActual")}


@pytest.mark.parametrize("key", [k for k in UNITS if k != "mm"])
def test_inch_metre_and_mm_files_give_the_same_values_and_u_in_mm(files, key):
    mm, other = qc.read_characteristics(files["mm"]), qc.read_characteristics(files[key])
    for a, b in zip(mm.table(), other.table()):
        for k in ("nominal", "lsl", "usl", "tolerance", "value"):
            assert (a[k] is None and b[k] is None) or b[k] == pytest.approx(a[k], rel=1e-12), (k, a, b)
    u_mm, _, _ = qs.uncertainties(mm)
    u_other, _, _ = qs.uncertainties(other)
    scale = UNITS[key][2]
    assert set(u_mm) == set(u_other) == {"14", "23", "29", "40", "177"}
    for iid in u_mm:
        assert u_other[iid] * scale == pytest.approx(u_mm[iid], rel=1e-9)      # file units -> mm


@pytest.mark.parametrize("key", [k for k in UNITS if k != "mm"])
def test_the_uncertainty_written_back_is_in_the_files_own_unit(files, key, tmp_path):
    """A QIF 3 file in inches got combinedUncertainty in mm: 25.4 times too large."""
    run_import(files["mm"], tmp_path / "mm.qif")
    run_import(files[key], tmp_path / "other.qif")
    u_mm, u_other = written_u(tmp_path / "mm.qif"), written_u(tmp_path / "other.qif")
    assert len(u_mm) == 16 and set(u_mm) == set(u_other)
    for k in u_mm:
        assert float(u_other[k]) * UNITS[key][2] == pytest.approx(float(u_mm[k]), rel=5e-3), k   # 3 digits


def test_a_qif3_file_in_inches_with_points_gets_the_same_u_written_in_inches(tmp_path):
    """The QIF 3 sample (points and characteristics) with every length divided by 25.4 and
    LinearUnit inch, factor 0.0254: the same values (lengths; the angle's values were scaled too
    and are left out), and the same u, from the file's own points (7) and from the stand-in (4),
    written in inches (before: in mm, 25.4 times too large)."""
    ns = "{http://qifstandards.org/xsd/qif3}"
    number = re.compile(r"\s*-?[\d.eE+-]+(\s+-?[\d.eE+-]+)*\s*")
    ET.register_namespace("", ns[1:-1])
    tree = ET.parse(SAMPLE)
    for el in tree.getroot().iter():
        if isinstance(el.tag, str) and el.tag.removeprefix(ns) in LENGTHS + ("Points", "ProbeRadius") \
                and el.text and number.fullmatch(el.text):
            el.text = " ".join(repr(float(v) / 25.4) for v in el.text.split())
    lu = tree.getroot().find(f"{ns}FileUnits/{ns}PrimaryUnits/{ns}LinearUnit")
    lu.find(f"{ns}UnitName").text = "inch"
    lu.find(f"{ns}UnitConversion/{ns}Factor").text = "0.0254"
    tree.write(tmp_path / "inch.qif", encoding="utf-8", xml_declaration=True)
    mm, inch = qc.read_characteristics(SAMPLE).table(), qc.read_characteristics(tmp_path / "inch.qif").table()
    lengths = [(a, b) for a, b in zip(mm, inch) if a["kind"] != "AngleBetween"]
    assert len(lengths) == len(mm) - 1
    for a, b in lengths:
        for k in ("nominal", "lsl", "usl", "tolerance", "value"):
            assert (a[k] is None and b[k] is None) or b[k] == pytest.approx(a[k], rel=1e-9, abs=1e-12), (k, a, b)
    _, report = run_import(tmp_path / "inch.qif", tmp_path / "inch_copy.qif")
    run_import(SAMPLE, tmp_path / "mm_copy.qif")

    def written(path):
        return {m.get("id"): float(m.find(f"{ns}Value").get("combinedUncertainty"))
                for m in ET.parse(path).getroot().iter()
                if isinstance(m.tag, str) and m.tag.endswith("CharacteristicMeasurement")
                and m.find(f"{ns}Value") is not None and m.find(f"{ns}Value").get("combinedUncertainty")}
    u_mm, u_inch = written(tmp_path / "mm_copy.qif"), written(tmp_path / "inch_copy.qif")
    assert len(u_mm) == 11 and set(u_inch) == set(u_mm)
    for k in u_mm:
        assert u_inch[k] * 25.4 == pytest.approx(u_mm[k], rel=6e-3), k           # 3 digits written
    assert "in the file's own units (inch, degree)" in " ".join(report)


def test_a_unit_conversion_that_is_not_a_number_names_the_file_and_the_element(tmp_path):
    bad = tmp_path / "bad.qif"
    bad.write_text(EXCERPT.read_text(encoding="utf-8").replace("<Factor>0.001</Factor>", "<Factor>milli</Factor>"),
                   encoding="utf-8")
    with pytest.raises(InputError) as err:
        qc.read_characteristics(bad)
    assert str(err.value).startswith(str(bad)) and "FileUnits/PrimaryUnits/LinearUnit/UnitConversion/Factor" in \
        str(err.value)


def test_a_unit_name_contradicting_its_factor_is_refused(tmp_path):
    bad = tmp_path / "bad.qif"
    bad.write_text(EXCERPT.read_text(encoding="utf-8").replace("<UnitName>mm</UnitName>", "<UnitName>inch</UnitName>"),
                   encoding="utf-8")
    with pytest.raises(InputError, match="UnitName 'inch' but UnitConversion/Factor 0.001"):
        qc.read_characteristics(bad)


# -- what the file says that cannot be decided, and the bonus ----------------------------------------

def test_a_negative_tolerance_value_and_an_mmc_position_are_said_in_the_report(tmp_path):
    files, report = run_import(EXCERPT, tmp_path / "copy.qif")
    perp = next(r for r in report if r.startswith("PERPENDICULARITY1 "))
    assert "ToleranceValue -0.13 is negative" in perp and "not decided" in perp
    pos = next(r for r in report if r.startswith("POSITION1 "))
    assert "at MMC, bonus from DIAMETER4 (hole)" in pos


def test_an_item_measured_several_times_per_part_shows_every_value(tmp_path):
    """DIAMETER4 is a pattern of four holes: the report showed the last value only."""
    _, report = run_import(EXCERPT, tmp_path / "copy.qif")
    dia = next(r for r in report if r.startswith("DIAMETER4 "))
    assert "part 183 (4 measurements): 4.486 PASS, 4.481 PASS, 4.481 PASS, 4.482 PASS" in dia


def test_the_copy_says_where_each_uncertainty_comes_from(tmp_path):
    run_import(EXCERPT, tmp_path / "copy.qif")
    text = (tmp_path / "copy.qif").read_text(encoding="utf-8")
    assert text.count("<!-- cmmwb: combinedUncertainty from a simulated stand-in part") == 16
    assert "5 from a simulated stand-in part" in text.split("<QPId>")[0]
    assert qc.read_characteristics(tmp_path / "copy.qif").table() == qc.read_characteristics(EXCERPT).table()


def test_a_zone_of_width_zero_regardless_of_feature_size_is_said_and_not_decided(tmp_path):
    """FLATNESS1's ToleranceValue 0.5 made 0 (RFS): nothing could conform, and the file's PASS was
    turned into 'does not conform' without a word.  Now the report and the stand-in task say it,
    and the built task decides the other characteristics but not this one."""
    zero = _without(EXCERPT, tmp_path, "<ToleranceValue>0.5</ToleranceValue>", "<ToleranceValue>0</ToleranceValue>")
    _, report = run_import(zero, tmp_path / "copy.qif")
    flat = next(r for r in report if r.startswith("FLATNESS1 "))
    assert "ToleranceValue 0 regardless of feature size" in flat and "not decided" in flat
    _, report = run_import(zero, tmp_path / "plate.toml", stand_in=True)
    assert main(["build", str(tmp_path / "plate.toml"), "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    results = json.loads((tmp_path / "out" / "plate.json").read_text(encoding="utf-8"))
    assert any(n.startswith("FLATNESS1: ToleranceValue 0 regardless of feature size") for n in results["notes"])
    decided = {d["characteristic"] for d in results["decisions"]}
    assert "FLATNESS1" not in decided and "DS002" in decided and "POSITION1 margin" in decided


def _mmc_without_bonus(tmp: Path, how: str) -> Path:
    """The excerpt with POSITION1's bonus made impossible: ``no_side`` drops the InternalExternal of
    its hole (is the MMC size the smallest or the largest diameter?); ``no_size`` moves the
    position's measurements onto the flatness's feature, where no diameter is measured."""
    text = EXCERPT.read_text(encoding="utf-8")
    if how == "no_side":
        assert text.count("<InternalExternal>INTERNAL</InternalExternal>") == 1
        text = text.replace("<InternalExternal>INTERNAL</InternalExternal>", "")
    else:
        moved = {"34": "11", "190": "185"}         # part 183 / 238: the hole -> the face of FLATNESS1
        text, n = re.subn(r'(<PositionCharacteristicActual id="\d+">.*?<FeatureActualIds n="1">\s*<Id>)(\d+)(</Id>)',
                          lambda m: m.group(1) + moved[m.group(2)] + m.group(3), text, flags=re.S)
        assert n == 2
    out = tmp / f"plate_{how}.qif"
    out.write_text(text, encoding="utf-8")
    return out


@pytest.mark.parametrize("how, why", [
    ("no_side", "does not say whether the feature is a hole or a pin"),
    ("no_size", "the file has no diameter of its feature (33) to take the bonus from"),
])
def test_an_mmc_position_whose_bonus_cannot_be_taken_says_why_and_is_not_decided(tmp_path, how, why):
    """A position at MMC without a size to take its bonus from was decided as RFS (against 0.25
    mm without the bonus) without a word."""
    src = _mmc_without_bonus(tmp_path, how)
    _, report = run_import(src, tmp_path / "copy.qif")
    pos = next(r for r in report if r.startswith("POSITION1 "))
    assert why in pos and "not decided at MMC" in pos and "bonus from DIAMETER4" not in pos
    run_import(src, tmp_path / "plate.toml", stand_in=True)
    assert main(["build", str(tmp_path / "plate.toml"), "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    results = json.loads((tmp_path / "out" / "plate.json").read_text(encoding="utf-8"))
    note = next(n for n in results["notes"] if n.startswith("POSITION1: "))
    assert why in note and "not decided" in note
    p = next(c for c in results["characteristics"] if c["name"] == "POSITION1")
    assert p["material_condition"] == "RFS" and p["tolerance_mm"] is None
    assert p["value"] == pytest.approx(0.035777087639955, rel=1e-12)        # the file's value of part 183
    assert not any(d["characteristic"].startswith("POSITION1") for d in results["decisions"])


def _without(path: Path, tmp: Path, old: str, new: str) -> Path:
    text = path.read_text(encoding="utf-8")
    assert old in text
    out = tmp / path.name
    out.write_text(text.replace(old, new, 1), encoding="utf-8")
    return out


def test_a_measured_feature_the_file_does_not_have_is_an_error(tmp_path):
    """The position's measured feature 34 renamed 9999: its u came from the stand-in silently."""
    bad = _without(EXCERPT, tmp_path, "<CharacteristicItemId>40</CharacteristicItemId>\n              <FeatureActualIds n=\"1\">\n"
                   "                <Id>34</Id>", "<CharacteristicItemId>40</CharacteristicItemId>\n              "
                   "<FeatureActualIds n=\"1\">\n                <Id>9999</Id>")
    with pytest.raises(InputError) as err:
        qc.read_characteristics(bad)
    assert "PositionCharacteristicActual id=41" in str(err.value) and "9999" in str(err.value)


def test_a_characteristic_of_a_feature_item_the_file_does_not_have_is_an_error(tmp_path):
    text = SAMPLE.read_text(encoding="utf-8")
    m = re.search(r"(<FlatnessCharacteristicItem id=\"(\d+)\">.*?<FeatureItemIds n=\"1\">\s*<Id>)(\d+)(</Id>)", text, re.S)
    bad = tmp_path / "sample.qif"
    bad.write_text(text[:m.start(3)] + "9999" + text[m.end(3):], encoding="utf-8")
    with pytest.raises(InputError) as err:
        qc.read_characteristics(bad)
    assert f"CharacteristicItem id={m.group(2)}" in str(err.value) and "feature 9999" in str(err.value)


def test_a_point_set_id_used_twice_is_an_error_naming_both(tmp_path, capsys):
    """The second set silently replaced the first: a feature got the other's points."""
    text = SAMPLE.read_text(encoding="utf-8")
    ids = re.findall(r'<MeasuredPointSet id="(\d+)"', text)
    bad = tmp_path / "sample.qif"
    bad.write_text(text.replace(f'<MeasuredPointSet id="{ids[1]}"', f'<MeasuredPointSet id="{ids[0]}"', 1),
                   encoding="utf-8")
    code = main(["import", str(bad), "--out", str(tmp_path / "t.toml"), "--feature", "CIRCLE1"])
    assert_clear_failure(code, capsys.readouterr().err.strip(), "sample.qif",
                         [f"MeasuredPointSet id={ids[0]} (the second)", f"point set id {ids[0]} is used twice"])
    code = main(["import", str(bad), "--out", str(tmp_path / "c.qif")])
    assert_clear_failure(code, capsys.readouterr().err.strip(), "sample.qif", ["used twice"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sample.qif"]


# -- the route to a task ---------------------------------------------------------------------------

def test_a_characteristics_only_file_names_the_routes_it_has(tmp_path, capsys):
    code = main(["import", str(EXCERPT), "--out", str(tmp_path / "t.toml")])
    assert_clear_failure(code, capsys.readouterr().err.strip(), "nist_sms_plate_excerpt.qif",
                         ["no measured points", "--out COPY.qif", "--stand-in --out TASK.toml"])


@pytest.mark.parametrize("topic", [[], ["import"], ["build"], ["new"]])
def test_every_help_names_the_characteristics_route(capsys, topic):
    """The help of cmmwb, import, and of the two commands a task is started (new) and decided
    (build) with."""
    with pytest.raises(SystemExit):
        main([*topic, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "characteristics" in text
    if topic == ["import"]:
        assert "--out COPY.qif" in text and "--stand-in" in text and "--part" in text
    elif topic:
        assert "cmmwb import results.qif --stand-in --out plate.toml" in text


@pytest.fixture(scope="module")
def stand_in(tmp_path_factory):
    """The excerpt in inches, part 238, as a task on the stand-in part, built."""
    tmp = tmp_path_factory.mktemp("stand_in")
    src = in_units(tmp, "inch_by_factor")
    files, report = run_import(src, tmp / "plate.toml", stand_in=True, part="238")
    assert main(["build", str(tmp / "plate.toml"), "--out", str(tmp / "out"), "--no-plots"]) == 0
    return tmp, files, report, json.loads((tmp / "out" / "plate.json").read_text(encoding="utf-8"))


def test_the_stand_in_task_says_what_it_is_in_the_task_and_the_outputs(stand_in):
    tmp, files, report, results = stand_in
    toml = (tmp / "plate.toml").read_text(encoding="utf-8")
    assert "SIMULATED STAND-IN PART" in toml and results["notes"][0].startswith("STAND-IN PART:")
    assert "part 238" in results["notes"][1]
    assert all(c["value_source"] == "measured" for c in results["characteristics"])
    assert any("stand-in part" in r for r in report)


def test_the_stand_in_task_decides_the_files_values_in_mm_with_the_bonus(stand_in):
    """Part 238 (in inches in the file): DIAMETER4 4.493, 4.489, 4.487, 4.487 mm; POSITION1 at MMC
    with the bonus of the hole measured on its feature, 4.489 - 3.992 mm; PERPENDICULARITY1 of
    ToleranceValue -0.13 not decided."""
    _, _, _, results = stand_in
    c = {r["name"]: r for r in results["characteristics"]}
    assert [round(c[f"DIAMETER4 #{k}"]["value"], 9) for k in (1, 2, 3, 4)] == [4.493, 4.489, 4.487, 4.487]
    p = c["POSITION1"]
    assert p["material_condition"] == "MMC" and p["value"] == pytest.approx(0.036055512754615, rel=1e-12)
    assert p["bonus_mm"] == pytest.approx(4.489 - 3.992, abs=1e-12)
    assert p["zone_mm"] == pytest.approx(0.25 + 4.489 - 3.992, abs=1e-12)
    decided = {d["characteristic"]: d for d in results["decisions"]}
    assert "POSITION1 margin" in decided and "PERPENDICULARITY1" not in decided
    assert c["PERPENDICULARITY1"]["tolerance_mm"] is None
    assert decided["POSITION1 margin"]["u_um"] == pytest.approx(p["u_margin_um"])
    assert {d["outcome"] for d in results["decisions"]} == {"conforms"}           # the file: all PASS


def test_the_stand_in_u_equals_the_annotated_copys(stand_in, tmp_path):
    """One stand-in part: the task's u of each characteristic is the copy's (mm file, 3 digits)."""
    _, _, _, results = stand_in
    run_import(EXCERPT, tmp_path / "copy.qif")
    doc = qc.read_characteristics(EXCERPT)
    u, _, _ = qs.uncertainties(doc)
    by_name = {it.name: u[it.id] * 1e3 for it in doc.items}                 # µm
    for r in results["characteristics"]:
        assert r["u"] == pytest.approx(by_name[r["name"].split(" #")[0]], rel=1e-9), r["name"]


def test_a_part_the_file_does_not_have_is_named_with_the_ones_it_has(tmp_path, capsys):
    code = main(["import", str(EXCERPT), "--stand-in", "--part", "999", "--out", str(tmp_path / "t.toml")])
    assert_clear_failure(code, capsys.readouterr().err.strip(), "nist_sms_plate_excerpt.qif",
                         ["--part", "no part '999'", "183, 238"])
