"""A careless user's mistakes on the task surfaces (issue 33): every case of
tests/bad_files/mistakes.py gives one message naming the file and the place (and for a name given
twice, both places), exit status 2, no traceback, nothing written; and what the families guard
against beyond the message: a name given twice never replaces the first, the datum frame of
nearly parallel planes is refused instead of giving positions of kilometres, a recordings file
too large for the memory is refused before it is parsed."""

from __future__ import annotations

import sys

import pytest

from cmmwb.generator.cli import main
from cmmwb.generator.errors import InputError

from tests.helpers import BAD_FILES, EXAMPLES
from tests.helpers.files import assert_clear_failure

sys.path.insert(0, str(BAD_FILES))
from mistakes import CASES, FAMILY  # noqa: E402


def run_cli(capsys, *args) -> tuple[int, str, str]:
    code = main(list(args))
    cap = capsys.readouterr()
    return code, cap.out, cap.err.strip()


def test_every_family_has_its_cases():
    families = ("names", "tolerances", "edge", "messages", "qif")
    assert {f: sum(1 for v in FAMILY.values() if v == f) >= 5 for f in families} == dict.fromkeys(families, True)


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_mistake_gives_one_message_naming_the_place_and_writes_nothing(tmp_path, capsys, name):
    argv, file_name, words = CASES[name](tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    code, out, err = run_cli(capsys, *argv)
    assert_clear_failure(code, err, file_name, words)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_the_plate_itself_still_builds_with_its_frame_and_position(tmp_path, capsys):
    """The guards refuse the mistakes, not the demo: its position at MMC is 34.7 µm (docs)."""
    import json

    code, out, err = run_cli(capsys, "build", str(EXAMPLES / "characteristic_plate.toml"), "--out",
                             str(tmp_path), "--no-plots")
    assert code == 0, err
    rows = {r["name"]: r for r in json.loads((tmp_path / "characteristic_plate.json").read_text())["characteristics"]}
    assert abs(rows["pos_H1_MMC"]["value"] * 1e3 - 34.70) <= 0.005


def test_recordings_too_large_for_the_memory_are_refused_before_they_are_parsed(tmp_path, capsys, monkeypatch):
    """Ten million records were parsed for 28 s and 3.9 GB before the refusal: now the number of
    lines decides, the parser is never reached and the message names the file."""
    from cmmwb.xlfuncs import memory
    from cmmwb.xlfuncs.locator import recordings

    rows = "".join(f"R{i},0,{i},0,100,{i},0,100,100.0001\n" for i in range(120_000))
    rec = tmp_path / "rec.csv"
    rec.write_text("id,x1,y1,z1,x2,y2,z2,reference_mm,measured_mm\n" + rows, encoding="utf-8")
    monkeypatch.setattr(memory, "available_bytes", lambda: 2**30)       # 1 GiB: 120,000 records need 1.4
    monkeypatch.setattr(recordings, "parse_recordings", lambda text: pytest.fail("parsed"))
    code, out, err = run_cli(capsys, "calibrate", str(rec), "--sigma-um", "0.3", "--out", str(tmp_path / "cal"))
    assert_clear_failure(code, err, "rec.csv", ["120,000 records", "1.0 GiB are available", "at most about 65,536"])
    code, out, err = run_cli(capsys, "diagnose", str(rec), "--sigma-um", "0.3", "--out", str(tmp_path / "diag"))
    assert_clear_failure(code, err, "rec.csv", ["120,000 records"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.csv"]


def test_a_name_given_twice_is_refused_in_the_reader_not_replaced(tmp_path):
    """The namespace object itself: the first place stays, the second is the error."""
    from cmmwb.generator.taskfile import Names

    (tmp_path / "t.toml").write_text('[[frames]]\nname = "F"\n\n[[frames]]\nname = "F"\n', encoding="utf-8")
    names = Names(tmp_path / "t.toml", "datum frame")
    names.add("F", "[[frames]] #1 name")
    with pytest.raises(InputError) as err:
        names.add("F", "[[frames]] #2 name")
    assert "[[frames]] #1 name (line 2)" in str(err.value) and names.where("F") == "[[frames]] #1 name"


@pytest.mark.parametrize("where", ["[mpe]", "--mpe"])
def test_an_mpe_in_millimetres_given_to_calibrate_is_warned_about(tmp_path, capsys, where):
    """A_um = 1500 (1.5 µm written as if the unit were nm, or an MPE in mm pasted as µm): build and
    diagnose warned about it, calibrate said only 'the fitted model meets the specification'."""
    import json

    from mistakes import MACHINE, calibrate

    task = MACHINE.replace("[parameters]", "[mpe]\nA_um = 1500\nB_mm = 500\n\n[parameters]") if where == "[mpe]" \
        else MACHINE
    argv = calibrate(tmp_path, task=task) + (["--mpe", "1500,500"] if where == "--mpe" else [])
    code, out, err = run_cli(capsys, *argv)
    assert code == 0, err
    warning = "A_um = 1500 µm is larger than what coordinate measuring machines have (0.05 to 500 µm)"
    lines = [line for line in err.splitlines() if line.startswith("cmmwb: warning:")]
    assert len(lines) == 1 and warning in lines[0] and where in lines[0], err
    assert ("machine.toml" in lines[0]) == (where == "[mpe]")
    result = json.loads((tmp_path / "cal" / "calibration.json").read_text(encoding="utf-8"))
    assert [w for w in result["warnings"] if warning in w] == [lines[0].removeprefix("cmmwb: warning: ")]
    assert result["mpe_check"]["fitted"]["margin"] > 0.99      # "meets the specification": now with the warning
