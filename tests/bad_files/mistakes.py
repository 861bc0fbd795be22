"""A careless user's mistakes on the task surfaces of the last rounds (issue 33), made at test time.

Each case is a function ``make(tmp) -> (argv, file_name, words)`` like those of ``hostile.py``: it
writes its files into ``tmp`` and returns the ``cmmwb`` arguments, the file the message must name
and the words it must contain (the places: the key and its line, and for a name given twice both
places).  ``tests/input/test_mistakes.py`` runs each and requires one clear message, exit status 2,
no traceback and nothing written.  Before issue 33 each of these was accepted with a silent wrong
number, stopped with an internal error (exit 1), or said what was wrong without saying where.

``FAMILY`` maps each case to its family: ``names`` (two things given one name), ``tolerances``,
``edge`` (numbers at the edge of what the arithmetic holds), ``messages`` (the place named), ``qif``
(QIF units, references and the stand-in route).
"""

from __future__ import annotations

import re
from pathlib import Path

from make_bad_files import POINTCLOUD_CSV, POINTCLOUD_TASK

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE.parents[1] / "generator" / "examples"

CASES: dict[str, object] = {}
FAMILY: dict[str, str] = {}


def case(family: str):
    def register(fn):
        CASES[fn.__name__] = fn
        FAMILY[fn.__name__] = family
        return fn
    return register


# -- helpers ------------------------------------------------------------------------------------

def plate(tmp: Path, *edits: tuple[str, str], extra: str = "") -> list[str]:
    """The demo plate (generator/examples/characteristic_plate.toml) with text replaced (each old
    text must occur) and ``extra`` appended; the build's arguments."""
    toml = (EXAMPLES / "characteristic_plate.toml").read_text(encoding="utf-8")
    for old, new in edits:
        assert old in toml, old
        toml = toml.replace(old, new, 1)
    (tmp / "plate.toml").write_text(toml + extra, encoding="utf-8")
    (tmp / "characteristic_plate.csv").write_text(
        (EXAMPLES / "characteristic_plate.csv").read_text(encoding="utf-8"), encoding="utf-8")
    return ["build", str(tmp / "plate.toml"), "--out", str(tmp / "out"), "--no-plots"]


def small(tmp: Path, toml: str) -> list[str]:
    (tmp / "small.toml").write_text(toml, encoding="utf-8")
    (tmp / "small.csv").write_text(POINTCLOUD_CSV, encoding="utf-8")
    return ["build", str(tmp / "small.toml"), "--out", str(tmp / "out"), "--no-plots"]


def with_tolerance(rule: str = "iso14253", max_pfa: str | None = None, **keys) -> str:
    """The small point-cloud task with ``[decision]`` and one [[decision.tolerances]] entry for the
    distance A-B holding ``keys`` (TOML values as text)."""
    return (POINTCLOUD_TASK + f'\n[decision]\nrule = "{rule}"\n'
            + (f"max_pfa = {max_pfa}\n" if max_pfa is not None else "")
            + '\n[[decision.tolerances]]\nfrom = "A"\nto = "B"\n' + "".join(f"{k} = {v}\n" for k, v in keys.items()))


#: length recordings (docs/recordings.md 1a) of three lengths along x
LENGTHS = """id,x1,y1,z1,x2,y2,z2,reference_mm,measured_mm
L1,0,0,0,100,0,0,100,100.0003
L2,0,10,0,200,10,0,200,199.9996
L3,0,20,0,300,20,0,300,300.0008
L4,0,30,0,400,30,0,400,400.0001
"""
MACHINE = """[task]
kind = "pointcloud"
name = "machine"

[parameters]
sigma_R_um = 0.2
sigma_S_ppm = 0.7

[[probes]]
id = "P1"
offset_mm = [0.0, 0.0, -50.0]
"""


def calibrate(tmp: Path, recordings: str = LENGTHS, task: str = MACHINE) -> list[str]:
    (tmp / "rec.csv").write_text(recordings, encoding="utf-8")
    (tmp / "machine.toml").write_text(task, encoding="utf-8")
    return ["calibrate", str(tmp / "rec.csv"), "--task", str(tmp / "machine.toml"), "--out", str(tmp / "cal"),
            "--effects", "none", "--profiles", "no", "--no-workbook"]


# -- names that collide -------------------------------------------------------------------------

@case("names")
def two_datum_frames_named_alike(tmp):
    """The second frame silently replaced the first: a position of 0.01 mm became 141 mm."""
    return plate(tmp, extra='\n[[frames]]\nname = "ABC"\nprimary = "A"\nsecondary = "C"\ntertiary = "B"\n'), \
        "plate.toml", ["[[frames]] #2 name (line", "'ABC' is given twice", "[[frames]] #1 name (line 82)"]


@case("names")
def a_flatness_and_a_distance_named_alike(tmp):
    """The flatness was decided on the distance's value."""
    return plate(tmp, ('name = "flat_A_LS"', 'name = "dist_H1_H2"')), "plate.toml", [
        "[[characteristics]] #6 name (line", "'dist_H1_H2' is given twice", "[[characteristics]] #3 name (line"]


@case("names")
def two_features_named_alike(tmp):
    return plate(tmp, ('name = "T"', 'name = "D"')), "plate.toml", [
        "[[features]] #5 name (line", "feature 'D' is given twice", "[[features]] #4 name (line"]


@case("names")
def a_characteristic_named_like_the_margin_of_a_position(tmp):
    """'pos_H1_MMC margin' is the decided quantity of the position at MMC: two decisions, one name."""
    return plate(tmp, ('name = "dia_H2"', 'name = "pos_H1_MMC margin"'),
                 ('size = "dia_H1"', 'size = "dia_H1"')), "plate.toml", [
        "[[characteristics]] #2 name (line", "margin of position 'pos_H1_MMC'"]


@case("names")
def a_datum_frame_naming_one_feature_twice(tmp):
    return plate(tmp, ('tertiary = "C"', 'tertiary = "A"')), "plate.toml", [
        "[[frames]] #1 tertiary (line", "'A' is already the primary datum of frame 'ABC'"]


@case("names")
def a_feature_listing_one_point_twice(tmp):
    return plate(tmp, ('id_prefix = "T."', 'ids = ["T.01", "T.02", "T.03", "T.02"]')), "plate.toml", [
        "[[features]] #5 ids (line", "'T.02' is listed twice"]


@case("names")
def two_probes_with_one_id(tmp):
    return small(tmp, POINTCLOUD_TASK.replace('id = "P2"', 'id = "P1"')), "small.toml", [
        "[[probes]] #2 id (line 17)", "probe id 'P1' is given twice", "[[probes]] #1 id (line 13)"]


@case("names")
def a_distance_listed_twice_the_second_time_reversed(tmp):
    toml = POINTCLOUD_TASK + '\n[[distances]]\nfrom = "A"\nto = "B"\n\n[[distances]]\nfrom = "B"\nto = "A"\n'
    return small(tmp, toml), "small.toml", ["[[distances]] #2 (line", "B→A is listed already",
                                             "[[distances]] #1 (line"]


@case("names")
def a_distance_listed_again_after_a_star(tmp):
    toml = POINTCLOUD_TASK + '\n[[distances]]\nfrom = "A"\nto = "*"\n\n[[distances]]\nfrom = "C"\nto = "A"\n'
    return small(tmp, toml), "small.toml", ["[[distances]] #2", "C→A is listed already"]


@case("names")
def two_budget_characteristics_differing_in_letter_case(tmp):
    toml = (EXAMPLES / "knuckle.toml").read_text(encoding="utf-8").replace('name = "S1_position"',
                                                                            'name = "s4_POSITION"', 1)
    (tmp / "knuckle.toml").write_text(toml, encoding="utf-8")
    return ["build", str(tmp / "knuckle.toml"), "--out", str(tmp / "out")], "knuckle.toml", [
        "[[characteristics]] #2 key 'name'", "[[characteristics]] #1 key 'name' (line"]


# -- tolerances ---------------------------------------------------------------------------------

@case("tolerances")
def a_negative_zone_width(tmp):
    """tolerance_mm = -0.01 was built and decided against a negative zone."""
    return plate(tmp, ("tolerance_mm = 0.01\n", "tolerance_mm = -0.01\n")), "plate.toml", [
        "[[characteristics]] #6 tolerance_mm (line", "cannot be negative"]


@case("tolerances")
def a_flatness_at_mmc(tmp):
    """The MMC modifier was dropped without a word."""
    return plate(tmp, ('name = "flat_A_LS"\ntype = "flatness"\n',
                       'name = "flat_A_LS"\ntype = "flatness"\nmaterial_condition = "MMC"\n')), "plate.toml", [
        "[[characteristics]] #6 material_condition (line", "a flatness takes no material_condition"]


@case("tolerances")
def a_zone_of_width_zero_at_rfs(tmp):
    return plate(tmp, ("tolerance_mm = 0.01\n", "tolerance_mm = 0\n")), "plate.toml", [
        "[[characteristics]] #6 tolerance_mm", "width 0"]


@case("tolerances")
def a_size_on_a_position_regardless_of_feature_size(tmp):
    return plate(tmp, ('nominal_position_mm = [70.0, 40.0]\n', 'nominal_position_mm = [70.0, 40.0]\nsize = "dia_H2"\n')), \
        "plate.toml", ["[[characteristics]] #18 size", "this one is RFS"]


@case("tolerances")
def a_position_at_mmc_without_its_size(tmp):
    return plate(tmp, ('size = "dia_H1"\n', '')), "plate.toml", [
        "[[characteristics]] #17 material_condition", "give size"]


@case("tolerances")
def a_direction_on_a_flatness(tmp):
    return plate(tmp, ('method = "MZ"\ntolerance_mm = 0.01', 'method = "MZ"\ndirection = [0, 0, 1]\ntolerance_mm = 0.01')), \
        "plate.toml", ["[[characteristics]] #7 direction", "a flatness takes no direction"]


# -- numbers at the edge ------------------------------------------------------------------------

@case("edge")
def a_measured_value_of_1e300_mm(tmp):
    return small(tmp, with_tolerance(tol_mm=0.01, measured_mm="1e300")), "small.toml", [
        "[[decision.tolerances]] #1 key 'measured_mm'", "outside the plausible range"]


@case("edge")
def a_repeatability_of_1e300_um(tmp):
    return small(tmp, with_tolerance(tol_mm=0.01, s_um="1e300", n_repeats=5)), "small.toml", [
        "[[decision.tolerances]] #1 key 's_um'", "outside the plausible range"]


@case("edge")
def a_repeatability_of_1e_minus_300_um(tmp):
    return small(tmp, with_tolerance(tol_mm=0.01, s_um="1e-300", n_repeats=5)), "small.toml", [
        "[[decision.tolerances]] #1 key 's_um'", "below 1e-06 µm"]


@case("edge")
def a_false_acceptance_of_1e_minus_17(tmp):
    """1 - 1e-17 is 1: the acceptance limit's quantile was an internal 'probability' error."""
    return small(tmp, with_tolerance("specific_risk", "1e-17", tol_mm=0.01)), "small.toml", [
        "[decision] max_pfa", "between 1e-09 and 0.5"]


@case("edge")
def a_guard_band_factor_of_1e300(tmp):
    """guarded_rejection with r = 1e300 accepted every value up to 1e297 mm beyond the limits."""
    toml = with_tolerance("guarded_rejection", tol_mm=0.01).replace('rule = "guarded_rejection"\n',
                                                                     'rule = "guarded_rejection"\nr = 1e300\n')
    return small(tmp, toml), "small.toml", ["[decision] r", "guard-band factor in [0, 10]"]


@case("edge")
def a_secondary_datum_given_as_a_list(tmp):
    return plate(tmp, ('secondary = "B"', 'secondary = ["B"]')), "plate.toml", [
        "[[frames]] #1 secondary (line", "the name of one datum feature"]


@case("edge")
def a_position_without_a_frame(tmp):
    return plate(tmp, ('frame = "ABC"\nnominal_position_mm = [70.0, 40.0]', 'nominal_position_mm = [70.0, 40.0]')), \
        "plate.toml", ["[[characteristics]] #18 frame", "a position needs its datum frame"]


@case("edge")
def a_nominal_position_of_1e300_mm(tmp):
    """Was 'a decision needs a finite value' naming no key (the position of 2e300 mm was computed)."""
    return plate(tmp, ('nominal_position_mm = [70.0, 40.0]', 'nominal_position_mm = [1e300, 40.0]')), "plate.toml", [
        "[[characteristics]] #18 nominal_position_mm (line", "x: coordinate 1e+300 mm is outside the plausible"]


@case("edge")
def an_mpe_of_nan_in_calibrate(tmp):
    return calibrate(tmp, task=MACHINE.replace("[parameters]", "[mpe]\nA_um = nan\nB_mm = 500\n\n[parameters]")), \
        "machine.toml", ["[mpe] A_um (line 6)", "finite"]


@case("edge")
def a_tertiary_datum_plane_parallel_to_the_primary_within_a_hair(tmp):
    """The plate's top face T as tertiary datum beside A: nearly parallel planes put the origin 3.9 km
    away and the positions at 3.9e6 mm, without a word."""
    return plate(tmp, ('tertiary = "C"', 'tertiary = "T"')), "plate.toml", [
        "[[frames]] #1", "datum frame ABC", "do not meet in a point", "within 1 deg"]


# -- messages that name the place ---------------------------------------------------------------

@case("messages")
def a_false_acceptance_above_one_half(tmp):
    return small(tmp, with_tolerance("specific_risk", "1.5", tol_mm=0.01)), "small.toml", [
        "[decision] max_pfa", "max_pfa = 1.5"]


@case("messages")
def a_bell_character_in_the_lab_name(tmp):
    return small(tmp, POINTCLOUD_TASK + '\n[report]\nlab = "Lab\\u0007 3"\n'), "small.toml", [
        "[report] lab (line 24)", "control character 0x07"]


@case("messages")
def a_control_character_in_a_characteristic_name(tmp):
    return plate(tmp, ('name = "dia_H2"', 'name = "dia\\u0002H2"')), "plate.toml", [
        "[[characteristics]] #2 name (line", "control character 0x02"]


@case("messages")
def a_minimum_zone_flatness_of_three_points(tmp):
    return plate(tmp, ('id_prefix = "T."', 'ids = ["T.01", "T.05", "T.09"]'),
                 ('name = "par_T_A"\ntype = "parallelism"\nfeatures = ["T"]\nframe = "ABC"',
                  'name = "flat_T"\ntype = "flatness"\nfeatures = ["T"]\nmethod = "MZ"')), "plate.toml", [
        "[[characteristics]] #16 method (line", "at least 4 points", "feature 'T' has 3"]


@case("messages")
def a_characteristic_with_its_limits_swapped(tmp):
    """Was refused naming '[[characteristics]] dia_H1', no key and no line."""
    return plate(tmp, ("lsl = 10.0\nusl = 10.05", "lsl = 10.05\nusl = 10.0")), "plate.toml", [
        "[[characteristics]] #1 lsl (line 91)", "lsl = 10.05 must be below the upper usl = 10"]


@case("messages")
def identical_calibration_records(tmp):
    """One line copied: the message named the task, not the recordings."""
    return calibrate(tmp, LENGTHS + "L5,0,10,0,200,10,0,200,199.9996\n"), "rec.csv", [
        "line 6", "'L2' (line 3) and 'L5' are one measurement"]


@case("messages")
def a_typo_in_the_mpe_of_calibrate(tmp):
    return calibrate(tmp, task=MACHINE.replace("[parameters]", "[mpe]\nA_mu = 1.5\nB_mm = 500\n\n[parameters]")), \
        "machine.toml", ["[mpe] A_mu (line 6)", "unknown key"]


@case("messages")
def a_negative_mpe_in_calibrate(tmp):
    return calibrate(tmp, task=MACHINE.replace("[parameters]", "[mpe]\nA_um = 1.5\nB_mm = -500\n\n[parameters]")), \
        "machine.toml", ["[mpe] B_mm (line 7)", "must be positive"]


# -- QIF files (the unit systems, references, the stand-in route) -----------------------------------

QIF_DATA = HERE.parent / "data" / "qif"


def qif_edit(tmp: Path, source: str, old: str, new: str, argv_tail: list[str]) -> list[str]:
    """A copy of a QIF file of tests/data/qif with one text replaced, and the import's arguments."""
    text = (QIF_DATA / source).read_text(encoding="utf-8")
    assert old in text, old
    (tmp / "part.qif").write_text(text.replace(old, new, 1), encoding="utf-8")
    return ["import", str(tmp / "part.qif"), *argv_tail]


@case("qif")
def a_qif_unit_factor_that_is_not_a_number(tmp):
    return qif_edit(tmp, "nist_sms_plate_excerpt.qif", "<Factor>0.001</Factor>", "<Factor>0,001</Factor>",
                    ["--out", str(tmp / "copy.qif")]), "part.qif", [
        "FileUnits/PrimaryUnits/LinearUnit/UnitConversion/Factor", "not a list of numbers"]


@case("qif")
def a_qif_file_in_inches_whose_factor_says_millimetres(tmp):
    return qif_edit(tmp, "nist_sms_plate_excerpt.qif", "<UnitName>mm</UnitName>", "<UnitName>inch</UnitName>",
                    ["--out", str(tmp / "copy.qif")]), "part.qif", ["UnitName 'inch' but UnitConversion/Factor 0.001"]


@case("qif")
def a_qif_length_unit_without_a_factor_and_unknown(tmp):
    return qif_edit(tmp, "nist_sms_plate_excerpt.qif", "<UnitName>mm</UnitName>\n        <UnitConversion>\n"
                    "          <Factor>0.001</Factor>\n        </UnitConversion>",
                    "<UnitName>thou</UnitName>", ["--stand-in", "--out", str(tmp / "t.toml")]), "part.qif", [
        "FileUnits/PrimaryUnits/LinearUnit", "length unit 'thou' without UnitConversion/Factor"]


@case("qif")
def a_qif_measured_value_of_a_feature_the_file_does_not_have(tmp):
    return qif_edit(tmp, "nist_sms_plate_excerpt.qif", "<Id>34</Id>", "<Id>9999</Id>",
                    ["--out", str(tmp / "copy.qif")]), "part.qif", ["DiameterCharacteristicActual id=35", "measured feature 9999"]


@case("qif")
def a_qif_point_set_id_used_twice(tmp):
    text = (QIF_DATA / "QIF_PTS_SAMPLE.QIF").read_text(encoding="utf-8")
    first, second = re.findall(r'<MeasuredPointSet id="(\d+)"', text)[:2]
    return qif_edit(tmp, "QIF_PTS_SAMPLE.QIF", f'<MeasuredPointSet id="{second}"', f'<MeasuredPointSet id="{first}"',
                    ["--out", str(tmp / "t.toml"), "--feature", "CIRCLE1"]), "part.qif", [
        f"point set id {first} is used twice"]


@case("qif")
def a_stand_in_part_that_the_file_does_not_have(tmp):
    return qif_edit(tmp, "nist_sms_plate_excerpt.qif", "<!--", "<!--",
                    ["--stand-in", "--part", "17", "--out", str(tmp / "t.toml")]), "part.qif", [
        "--part", "no part '17'"]


@case("qif")
def a_stand_in_task_asked_for_as_recordings(tmp):
    return qif_edit(tmp, "nist_sms_plate_excerpt.qif", "<!--", "<!--",
                    ["--stand-in", "--out", str(tmp / "t.csv")]), "t.csv", ["--out must end in .toml"]


@case("qif")
def a_qif_measured_value_id_used_twice(tmp):
    """The position's measured value took the diameter's id 35: the copy's u went to one of them."""
    return qif_edit(tmp, "nist_sms_plate_excerpt.qif", '<PositionCharacteristicActual id="41">',
                    '<PositionCharacteristicActual id="35">', ["--out", str(tmp / "copy.qif")]), "part.qif", [
        "PositionCharacteristicActual id=35 (the second)", "id 35 is used twice",
        "also DiameterCharacteristicActual id=35, the first"]


@case("qif")
def two_qif_parts_with_one_id(tmp):
    """--part 183 took the first of two parts with that id without a word."""
    return qif_edit(tmp, "nist_sms_plate_excerpt.qif", '<MeasurementResults id="238">', '<MeasurementResults id="183">',
                    ["--stand-in", "--part", "183", "--out", str(tmp / "t.toml")]), "part.qif", [
        "MeasurementResults id=183 (the second)", "id 183 is used twice"]


@case("qif")
def a_qif_characteristic_item_id_used_twice(tmp):
    return qif_edit(tmp, "nist_sms_plate_excerpt.qif", '<DiameterCharacteristicItem id="23">',
                    '<DiameterCharacteristicItem id="14">', ["--out", str(tmp / "copy.qif")]), "part.qif", [
        "DiameterCharacteristicItem id=14 (the second)", "also FlatnessCharacteristicItem id=14, the first"]


@case("qif")
def a_qif_measured_value_of_1e300(tmp):
    """Was written into the stand-in task, which build then refused naming the task, not the QIF."""
    return qif_edit(tmp, "nist_sms_plate_excerpt.qif", "<Value>0.008</Value>", "<Value>1e300</Value>",
                    ["--stand-in", "--out", str(tmp / "t.toml")]), "part.qif", [
        "MeasurementResults id=183/PerpendicularityCharacteristicActual id=30", "Value 1e300",
        "outside the plausible machine range"]
