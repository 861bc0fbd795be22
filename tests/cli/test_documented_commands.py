"""Every command the README, the docs and the ``--help`` texts show works as shown (issue 37), so that
they cannot drift from the tool again: the commands are read from the texts
(:mod:`tests.helpers.documented`), each runnable one runs in a folder of its own holding the files
it needs (:data:`WORKSHOP`), and must end with exit status 0 (or the status its comment states);
every shown command, synopsis and inline mention names only commands, options and choices the
command line has.  Then what the demo's console and index promise: a few lines ending with the
index's path, an entry for every book, the sheet it names, a rebuild command that works.
"""

from __future__ import annotations

import functools
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import openpyxl
import pytest

from cmmwb.generator.demo_index import ITEMS

from tests.helpers import ROOT
from tests.helpers.documented import (
    Shown,
    displayed_in,
    documents,
    help_examples,
    inline_in,
    out_targets,
    parser_problems,
)
from tests.helpers.qif import write_part_qif

#: the files the shown commands read, made once: the commands that make them (run in order in
#: one folder), then copies of what they made or of files of the tree
WORKSHOP = (
    "cmmwb new pointcloud --out gauge.toml",
    "cmmwb new feature --out bore.toml",
    "cmmwb new budget --out knuckle.toml",
    "cmmwb new characteristic --out plate.toml",
    "cmmwb build gauge.toml --out gauge --no-plots",
    "cmmwb build plate.toml --out plate --no-plots",
    "cmmwb simulate --layout iso10360 --repeats 1 --out iso.csv",   # 35 lengths: calibrate in seconds
    "cmmwb simulate --layout stepgauge --out stepgauge.csv",
    "cmmwb simulate --layout ballplate --out plate.csv",
    "cmmwb simulate --validation ballplate,stepgauge --out vlengths",   # validate's results and tasks
    "cmmwb simulate --validation ring --out vfeatures",
)
COPIES = {"machine.toml": "gauge.toml", "filled_in.xlsx": "gauge/my_pointcloud.xlsx",
          "filled.xlsx": "gauge/my_pointcloud.xlsx",
          "results.csv": "vlengths/results.csv", "lengths.toml": "vlengths/validation_lengths.toml",
          "fitted.toml": "vlengths/validation_lengths.toml",
          "validation_lengths_points.csv": "vlengths/validation_lengths_points.csv",
          "features.toml": "vfeatures/validation_features.toml",
          "validation_features_points.csv": "vfeatures/validation_features_points.csv"}

#: runnable commands that are not run here, and the test module that runs them instead
ELSEWHERE = {
    "cmmwb demo --out demo --pdf": "tests/workbook/test_print.py",        # every book printed by LibreOffice
    "cmmwb addin relink out/plate.xlsx --out out/plate.ods": "tests/addin/test_oxt.py",   # needs the
    "cmmwb addin relink plate.xlsx --out plate.ods": "tests/addin/test_oxt.py",           # extension in a
    "cmmwb addin relink plate.xlsx --out plate.ods --profile ~/.config/libreoffice/4":    # LibreOffice
        "tests/addin/test_oxt.py",                                                         # profile
}
LIBREOFFICE = ("--pdf", "--engine libreoffice", "addin relink")


def _shown() -> list[Shown]:
    return [s for d in documents() for s in displayed_in(d)] + help_examples()


def _runnable() -> dict[str, Shown]:
    """The runnable shown commands, once each (first place shown)."""
    out: dict[str, Shown] = {}
    for s in _shown():
        if not s.synopsis and s.text not in ELSEWHERE:
            out.setdefault(s.text, s)
    return out


RUNNABLE = _runnable()


@functools.cache
def _bin(tmp: Path) -> Path:
    """A folder with a ``cmmwb`` that runs this interpreter's cmmwb (what the console script does)."""
    folder = tmp / "bin"
    folder.mkdir()
    script = folder / "cmmwb"
    script.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m cmmwb.generator "$@"\n', encoding="utf-8")
    script.chmod(0o755)
    return folder


def _run(command: str, cwd: Path, tmp: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PATH=f"{_bin(tmp)}{os.pathsep}{os.environ.get('PATH', '')}", HOME=str(tmp / "home"),
               CMMWB_DEBUG="")
    return subprocess.run(command, shell=True, cwd=cwd, env=env, capture_output=True, text=True, timeout=900)


@pytest.fixture(scope="module")
def workshop(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("documented")
    shop = tmp / "workshop"
    shop.mkdir()
    (tmp / "home").mkdir()
    for command in WORKSHOP:
        p = _run(command, shop, tmp)
        assert p.returncode == 0, (command, p.stderr)
    for name, source in COPIES.items():
        shutil.copy2(shop / source, shop / name)
    write_part_qif(shop / "part.qif")
    (shop / "workbook_templates").mkdir()
    shutil.copy2(ROOT / "workbook_templates" / "pointcloud_template.xlsx", shop / "workbook_templates")
    return shop


_results: dict[str, tuple[subprocess.CompletedProcess, Path]] = {}


def run_shown(text: str, workshop: Path) -> tuple[subprocess.CompletedProcess, Path]:
    """Run a shown command once in a copy of the workshop without the files it writes itself
    (its ``--out`` targets); its result and folder (kept for the other tests of this module)."""
    if text not in _results:
        tmp = workshop.parent
        folder = tmp / f"run{len(_results)}"
        skip = out_targets(RUNNABLE[text])
        shutil.copytree(workshop, folder, ignore=lambda d, names: [n for n in names if Path(d) == workshop
                                                                  and n in skip])
        _results[text] = (_run(text, folder, tmp), folder)
    return _results[text]


def _params():
    for text, s in RUNNABLE.items():
        marks = [pytest.mark.libreoffice] if any(k in text for k in LIBREOFFICE) else []
        yield pytest.param(text, marks=marks, id=text)


@pytest.mark.parametrize("text", list(_params()))
def test_every_shown_command_runs_as_shown(text, workshop):
    shown = RUNNABLE[text]
    p, _ = run_shown(text, workshop)
    assert p.returncode == shown.exit_status, f"{shown.where}: {text}\n{p.stdout[-2000:]}\n{p.stderr[-2000:]}"
    if shown.exit_status == 0:
        assert "Traceback" not in p.stderr and "internal error" not in p.stderr, p.stderr


def test_every_shown_command_names_real_commands_options_and_choices():
    shown = _shown() + [s for d in documents() for s in inline_in(d)]
    assert len(shown) > 100
    problems = [f"{s.where}: {problem}" for s in shown for problem in parser_problems(s)]
    assert not problems, "\n".join(problems)


def test_the_commands_run_elsewhere_are_still_shown_and_run_there():
    shown = {s.text for s in _shown()}
    for text, module in ELSEWHERE.items():
        assert text in shown, f"{text!r} is no longer shown: remove it from ELSEWHERE"
        assert (ROOT / module).is_file()
    source = (ROOT / "tests/workbook/test_print.py").read_text(encoding="utf-8")
    assert '"demo", "--out"' in source and '"--pdf"' in source
    assert '"relink"' in (ROOT / "tests/addin/test_oxt.py").read_text(encoding="utf-8")


def test_the_readme_reads_in_a_few_minutes_and_keeps_the_two_ci_commands():
    """Under 150 lines; `.ci/run` evaluates its two indented command lines from the repository's
    root (the first builds the environment and runs the demo shown above)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) < 150
    assert [k for k, line in enumerate(lines) if line.startswith("    python3 -m venv ")][:1]
    assert [k for k, line in enumerate(lines) if line.startswith('    .venv/bin/python -m pip install -q -e ".[test]"')]
    first = next(line for line in lines if line.startswith("    python3 -m venv "))
    assert first.strip().endswith("cmmwb demo --out cmmwb-demo")
    # what it does comes before how to install it
    assert text.index("coordinate measuring machine") < text.index("python3 -m venv")


# ---- the demo: its console, its index ------------------------------------------------------------

DEMO = "cmmwb demo --out cmmwb-demo"


@pytest.fixture(scope="module")
def demo(workshop):
    assert DEMO in RUNNABLE, "the README's demo command changed: update DEMO"
    p, folder = run_shown(DEMO, workshop)
    assert p.returncode == 0, p.stderr
    return p, folder / "cmmwb-demo"


def _books(out: Path) -> set[str]:
    return {b.relative_to(out).as_posix() for b in out.rglob("*.xlsx")}


def test_the_demo_says_a_few_lines_ending_with_its_index(demo):
    p, out = demo
    lines = p.stdout.splitlines()
    assert len(lines) <= 8, p.stdout
    assert lines[-1].strip() == str(Path("cmmwb-demo") / "index.html")
    assert (out / "index.html").is_file() and (out / "index.md").is_file()
    assert "Does this part conform" in p.stdout and "characteristic_plate.xlsx, sheet Summary" in p.stdout
    assert "every number is a formula" not in p.stdout     # grey cells are core values


def test_every_demo_book_has_its_index_entry_and_every_entry_its_book_and_sheet(demo):
    _, out = demo
    books = _books(out)
    described = {it.book for it in ITEMS}
    assert not books - described, f"books without an entry in generator/demo_index.py ITEMS: {books - described}"
    assert not described - books, f"entries of books the demo does not write: {described - books}"
    assert len(described) == len(ITEMS)
    for it in ITEMS:
        sheets = openpyxl.load_workbook(out / it.book, read_only=True).sheetnames
        assert it.first_sheet in sheets, (it.book, it.first_sheet, sheets)
        for sheet in re.findall(r"`(\w+)`", it.look_for):
            assert sheet in sheets, (it.book, sheet)
    page = (out / "index.md").read_text(encoding="utf-8")
    html = (out / "index.html").read_text(encoding="utf-8")
    for it in ITEMS:
        assert f"`{it.book}`" in page and f'href="{it.book}"' in html
    assert _unclosed_tags(html) == []


def _unclosed_tags(page: str) -> list[str]:
    """The elements of an HTML page left open or closed out of order (none on a page a browser
    shows as written)."""
    from html.parser import HTMLParser

    void = {"meta", "br", "img", "link", "hr", "input"}
    stack: list[str] = []
    wrong: list[str] = []

    class Tags(HTMLParser):
        def handle_starttag(self, tag, attrs):
            if tag not in void:
                stack.append(tag)

        def handle_endtag(self, tag):
            if not stack or stack.pop() != tag:
                wrong.append(tag)

    Tags().feed(page)
    return wrong + stack


def test_the_index_says_what_the_books_show(demo):
    """The words of the index that rest on numbers hold for the books the demo wrote."""
    _, out = demo
    mpe2 = json.loads((out / "pointcloud" / "stepgauge_I_MPE2.json").read_text(encoding="utf-8"))
    assert mpe2["mpe_check"]["C_max"] > 1 and not mpe2["mpe_check"]["conforms"]      # "C_max exceeds 1"
    plate = json.loads((out / "characteristic" / "characteristic_plate.json").read_text(encoding="utf-8"))
    assert {d["outcome"] for d in plate["decisions"]} == {"conforms", "does not conform", "cannot be decided"}
    aliased = json.loads((out / "diagnose" / "aliased" / "diagnosis.json").read_text(encoding="utf-8"))
    assert [e["name"] for e in aliased["effects"]] == ["scale_x"]
    assert any(x["name"] == "EBX" and x["aliased_with"] == "scale_x" for x in aliased["not_identifiable"])
    start, fitted = (json.loads((out / "validate" / step / "validation.json").read_text(encoding="utf-8"))
                     for step in ("validate_start", "validate_fitted"))
    assert not start["verdict"]["holds"] and "calibrate" in start["verdict"]["next_step"]   # "does not hold"
    assert fitted["verdict"]["holds"]                                                        # "holds"


#: a number of a rebuilt book's JSON that must come back the same
REBUILT = {"budget/knuckle.xlsx": ("budget/knuckle.json", lambda d: d["characteristics"][0]["u_um"]),
           "diagnose/concealed/diagnosis.xlsx": ("diagnose/concealed/diagnosis.json",
                                                 lambda d: d["effects"][0]["estimate"]),
           "validate/calibrate/calibration.xlsx": ("validate/calibrate/calibration.json",
                                                   lambda d: d["fitted_parameters"]["sigma_ET_um"]),
           "validate/validate_start/validation.xlsx": ("validate/validate_start/validation.json",
                                                       lambda d: d["count"]["within"])}


@pytest.mark.parametrize("book", list(REBUILT))
def test_the_index_rebuild_commands_work_in_the_demo_folder(demo, book, workshop):
    _, out = demo
    page = (out / "index.md").read_text(encoding="utf-8")
    row = next(line for line in page.splitlines() if line.startswith(f"| `{book}` |"))
    command = re.findall(r"`([^`]+)`", row)[-1]
    assert command.startswith("cmmwb ")
    path, number = REBUILT[book]
    before = number(json.loads((out / path).read_text(encoding="utf-8")))
    p = _run(command, out, workshop.parent)
    assert p.returncode == 0, (command, p.stderr)
    after = number(json.loads((out / path).read_text(encoding="utf-8")))
    assert after == pytest.approx(before, rel=1e-9)


def test_the_conformity_doc_quotes_the_demo_statement(demo):
    """docs/conformity.md's example statement is the one the demo's knuckle prints and stores."""
    _, out = demo
    doc = (ROOT / "docs" / "conformity.md").read_text(encoding="utf-8")
    quoted = re.search(r"`(S1_S2_distance = [^`]+)`", " ".join(doc.split())).group(1)
    knuckle = json.loads((out / "budget" / "knuckle.json").read_text(encoding="utf-8"))
    statement = next(d["statement"] for d in knuckle["decisions"] if d["characteristic"] == "S1_S2_distance")
    assert quoted == statement


# ---- what the commands print -------------------------------------------------------------------

def test_every_printed_uncertainty_has_its_unit(workshop):
    """In everything the shown commands printed, a u, U or ± is followed by its unit (or says that
    its quantity has none: the U of C_max, a ratio)."""
    for text in RUNNABLE:
        if not any(k in text for k in LIBREOFFICE):
            run_shown(text, workshop)
    bare = []
    for text, (p, _) in _results.items():
        for m in re.finditer(r"(\b[uU]\w* = |± )([-+]?\d[\d.]*(?:e[-+]?\d+)?)(?![\d.])\s*(\S*)", p.stdout):
            if not m.group(3).startswith(("µ", "mm", "deg", "ppm", "nm", "(dimensionless")):
                bare.append(f"{text}: ...{m.group(0)}")
    assert not bare, "\n".join(bare)


def test_a_command_shows_each_quantity_in_one_unit(workshop):
    """A characteristic's value is printed in the unit of its JSON wherever the console shows it
    (once `flatness_A: 3.3000 µm`, then `flatness_A = 0.00330 mm`)."""
    mixed = []
    for text in RUNNABLE:
        if any(k in text for k in LIBREOFFICE):
            continue
        p, _ = run_shown(text, workshop)
        units: dict[str, set[str]] = {}
        for m in re.finditer(r"^\s*([A-Za-z]\w*)(?: margin)?(?::| =) ([-+]?\d[\d.]*) (µm|mm|deg|µrad)\b", p.stdout,
                             re.MULTILINE):
            units.setdefault(m.group(1), set()).add(m.group(3))
        mixed += [f"{text}: {name} in {sorted(u)}" for name, u in units.items() if len(u) > 1]
    assert not mixed, "\n".join(mixed)
    p, _ = run_shown("cmmwb new characteristic --out plate.toml && cmmwb build plate.toml --out plate && "
                     "cmmwb read plate/my_part.xlsx --out plate2.toml", workshop)
    assert re.search(r"^\s*flatness_A: \d\.\d+ mm, u = [\d.]+ µm$", p.stdout, re.MULTILINE), p.stdout


def test_the_new_tasks_are_all_named_my_something(workshop):
    """`cmmwb new KIND` starts every kind from a task named for the user (my_*), not after an example."""
    import tomllib

    for name in ("gauge.toml", "bore.toml", "knuckle.toml", "plate.toml"):
        doc = tomllib.loads((workshop / name).read_text(encoding="utf-8"))
        assert doc["task"]["name"].startswith("my_"), (name, doc["task"]["name"])


def test_the_verbose_demo_lists_each_book_and_still_ends_with_the_index(tmp_path, monkeypatch, capsys):
    """--verbose: every book's headline results (here the knuckle alone, to keep it quick)."""
    from cmmwb.generator.budget import job as budget
    from cmmwb.generator.cli import demo as demo_cli
    from cmmwb.generator.cli import main
    from cmmwb.generator.diagnosis import run as diagnosis
    from cmmwb.generator.validation import loop

    monkeypatch.setattr(demo_cli, "JOBS", {"budget": budget})
    monkeypatch.setattr(diagnosis, "demo", lambda out_dir, verbose=True, force=False: [])
    monkeypatch.setattr(loop, "demo", lambda out_dir, verbose=True, force=False: [])
    assert main(["demo", "--out", str(tmp_path / "d"), "--verbose"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert any(line.startswith("[budget] knuckle") for line in out)
    assert any("S1_S2_distance = 90.0120 mm, U = 4.6 µm" in line for line in out)
    assert out[-1].strip() == str(tmp_path / "d" / "index.html")
    page = (tmp_path / "d" / "index.md").read_text(encoding="utf-8")
    assert "`budget/knuckle.xlsx`" in page and "cmmwb build budget/knuckle.toml --out budget" in page


def test_a_demo_over_an_edited_task_file_refuses_unless_forced(tmp_path, monkeypatch, capsys):
    """The task files beside the books are the person's to edit: a second demo does not overwrite
    an edited one (exit status 2, the file named), and with --force keeps it as NAME.bak."""
    from cmmwb.generator.budget import job as budget
    from cmmwb.generator.cli import demo as demo_cli
    from cmmwb.generator.cli import main
    from cmmwb.generator.diagnosis import run as diagnosis
    from cmmwb.generator.validation import loop

    monkeypatch.setattr(demo_cli, "JOBS", {"budget": budget})
    monkeypatch.setattr(diagnosis, "demo", lambda out_dir, verbose=True, force=False: [])
    monkeypatch.setattr(loop, "demo", lambda out_dir, verbose=True, force=False: [])
    out = tmp_path / "d"
    assert main(["demo", "--out", str(out)]) == 0
    task = out / "budget" / "knuckle.toml"
    task.write_text(task.read_text(encoding="utf-8").replace("k = 2", "k = 3", 1), encoding="utf-8")
    capsys.readouterr()
    assert main(["demo", "--out", str(out)]) == 2
    assert "knuckle.toml" in capsys.readouterr().err and "k = 3" in task.read_text(encoding="utf-8")
    assert main(["demo", "--out", str(out), "--force"]) == 0
    assert "k = 3" in (out / "budget" / "knuckle.toml.bak").read_text(encoding="utf-8")
    assert "k = 3" not in task.read_text(encoding="utf-8")
