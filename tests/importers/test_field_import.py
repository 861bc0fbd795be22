"""Field finish (issue 25), real result files with defects: a QIF nominal whose Location and
Normal are swapped (a direction of length 33) is an error naming the element, never silently
normalised; features that are in the file but cannot be imported (SinglePointSetId, a point
given only by its Location) are named as such with their type; AQDEF units: `cm` is a length,
a missing K2142 is said."""

from __future__ import annotations

from pathlib import Path

import pytest

from cmmwb.generator.cli import main
from cmmwb.generator.errors import InputError
from cmmwb.generator.importers import qif, run_import

from tests.helpers import DATA

SAMPLE = DATA / "qif" / "QIF_PTS_SAMPLE.QIF"
CIRCLE1_NOMINAL = ("""      <CircleFeatureNominal id="259">
        <FeatureDefinitionId>258</FeatureDefinitionId>
        <Location>-33.05 -4.35 -1.309995069701</Location>
        <Normal>0 0 -1</Normal>""")


def swapped_sample(tmp_path: Path) -> Path:
    """The public sample with CIRCLE1's nominal Location and Normal swapped (a defect seen in a
    real QIF 2.1 export): Normal (-33.05, -4.35, -1.31) of length 33.36."""
    text = SAMPLE.read_text()
    assert CIRCLE1_NOMINAL in text
    bad = (CIRCLE1_NOMINAL.replace("<Location>-33.05 -4.35 -1.309995069701</Location>", "<Location>0 0 -1</Location>")
           .replace("<Normal>0 0 -1</Normal>", "<Normal>-33.05 -4.35 -1.309995069701</Normal>"))
    (tmp_path / "swapped.qif").write_text(text.replace(CIRCLE1_NOMINAL, bad))
    return tmp_path / "swapped.qif"


def test_a_nominal_normal_of_length_33_is_an_error_naming_the_element(tmp_path):
    with pytest.raises(InputError) as e:
        qif.read_qif(swapped_sample(tmp_path))
    msg = str(e.value)
    assert "CircleFeatureNominal id=259" in msg
    assert "Normal (-33.05, -4.35, -1.31) has length 33.3608, not 1" in msg
    assert "are Location and Normal swapped?" in msg


def test_importing_recordings_from_the_swapped_file_exits_2_and_writes_nothing(tmp_path, capsys):
    src = swapped_sample(tmp_path)
    out = tmp_path / "out"
    assert main(["import", str(src), "--out", str(out / "rec.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "swapped.qif" in err and "id=259" in err, err
    assert not out.exists()


def test_a_measured_direction_that_is_not_unit_length_is_an_error_too(tmp_path):
    text = SAMPLE.read_text().replace(
        "<Normal>-3.07699999999909e-009 0.999785979180705 -0.0206880601719939</Normal>",
        "<Normal>0 2 0</Normal>", 1)
    (tmp_path / "m.qif").write_text(text)
    with pytest.raises(InputError, match=r"LineFeatureMeasurement id=255: Normal \(0, 2, 0\) has length 2, not 1"):
        qif.read_qif(tmp_path / "m.qif")


def test_directions_rounded_in_the_file_are_still_accepted():
    doc = qif.read_qif(SAMPLE)   # e.g. (-0.642787609678657, 1.8e-11, 0.766044443125592)
    assert {f.name for f in doc.features} >= {"CIRCLE1", "CYL_1", "DATUMA"}


@pytest.mark.parametrize("name,words", [
    ("DATUMC", ["feature DATUMC is in the file (a line feature, id 255) but not supported", "SinglePointSetId"]),
    ("POINT3", ["feature POINT3 is in the file (a point feature, id 776) but not supported",
                "no PointList", "only its Location"]),
    ("CPLANE", ["(a plane feature, id 838) but not supported"]),
])
def test_a_feature_in_the_file_that_cannot_be_imported_says_so_and_its_type(tmp_path, capsys, name, words):
    assert main(["import", str(SAMPLE), "--feature", name, "--out", str(tmp_path / "t.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "QIF_PTS_SAMPLE.QIF, --feature" in err, err
    for w in words:
        assert w in err, err
    assert "no feature named" not in err
    assert not any(tmp_path.iterdir())


def test_a_feature_that_is_not_in_the_file_lists_what_is_and_what_is_not_importable():
    doc = qif.read_qif(SAMPLE)
    with pytest.raises(InputError, match=r"no feature named or numbered 'NOPE'; the file has: DATUMA \(plane, "
                                         r"id 11\).*; not importable: DATUMC \(line\), POINT3 \(point\)"):
        doc.feature("NOPE")


def test_the_import_report_names_the_point_given_by_its_location_only(tmp_path):
    _, report = run_import(SAMPLE, tmp_path / "rec.csv")
    assert any("PointFeatureMeasurement id=776 (POINT3)" in line and "no PointList" in line for line in report)


# -- AQDEF units --------------------------------------------------------------------------------------

def _aqdef(tmp_path: Path, unit_line_2: str) -> str:
    (tmp_path / "g.dfq").write_text(
        "K0100 2\nK2001/1 L1\nK2002/1 Length 2 cm\nK2004/1 0\nK2101/1 2,000\nK2142/1 cm\n"
        f"K2001/2 L2\nK2002/2 Length 40\nK2004/2 0\nK2101/2 40,000\n{unit_line_2}"
        "2.0001\x0f40.0021\n", encoding="cp1252")
    with pytest.raises(InputError) as e:
        run_import(tmp_path / "g.dfq", tmp_path / "rec.csv")
    assert not (tmp_path / "rec.csv").exists()
    return str(e.value)


def test_aqdef_cm_is_a_length_unit(tmp_path):
    msg = _aqdef(tmp_path, "K2142/2 mm\n")
    assert "2 characteristics (2 variable ones in length units)" in msg
    assert "Length 2 cm (1 values, nominal 2,000 cm)" in msg


def test_aqdef_a_missing_unit_is_said_not_assumed(tmp_path):
    msg = _aqdef(tmp_path, "")
    assert "(1 variable ones in length units; 1 without a unit (no K2142 field: not assumed to be mm))" in msg
    assert "Length 40 (1 values, nominal 40,000, no unit: K2142 missing)" in msg


def test_aqdef_length_units():
    from cmmwb.generator.importers.aqdef import is_length_unit

    assert all(is_length_unit(u) for u in ("mm", "cm", "CM", "µm", "um", "m", "inch", "in", "nm"))
    assert not any(is_length_unit(u) for u in (None, "", "deg", "°", "N", "%"))


@pytest.mark.parametrize("old,new,words", [
    ('<RangePointSetId range="3 8">', '<RangePointSetId range="3 80000">',
     ["feature DATUMA takes points 3-80000 of point set 12, which holds", "PlaneFeature id=11"]),
    ('<RangePointSetId range="3 8">', '<RangePointSetId range="8">',
     ["PlaneFeatureMeasurement id=11/RangePointSetId", "range '8' is not two whole numbers"]),
    ('<RangePointSetId range="3 8">', '<RangePointSetId range="8 3">', ["range '8 3': expected 1 <= first <= last"]),
    ("<ProbeRadius>", "<ProbeRadius>r=", ["ProbeRadius", "not a list of numbers"]),
])
def test_malformed_point_references_and_radii_name_the_element(tmp_path, capsys, old, new, words):
    text = SAMPLE.read_text()
    assert old in text
    (tmp_path / "bad.qif").write_text(text.replace(old, new, 1))
    code = main(["import", str(tmp_path / "bad.qif"), "--feature", "DATUMA", "--normals", "from-feature",
                 "--out", str(tmp_path / "out" / "t.toml")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "internal error" not in err, err
    for w in words:
        assert w in err, err
    assert not (tmp_path / "out").exists()
