"""Field finish (issue 25), robustness: two builds into one folder with one interrupted, and
commands whose reader closed the pipe.  Real processes and real signals."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.helpers import BAD_FILES

sys.path.insert(0, str(BAD_FILES))
from make_bad_files import POINTCLOUD_CSV, POINTCLOUD_TASK  # noqa: E402


def sigint_as_at_a_terminal():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def cmmwb(*args) -> list[str]:
    return [sys.executable, "-m", "cmmwb.generator", *args]


def _tasks(tmp_path: Path, name_a: str, name_b: str) -> tuple[Path, Path]:
    (tmp_path / "small.csv").write_text(POINTCLOUD_CSV)
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    a.write_text(POINTCLOUD_TASK.replace('name = "small"', f'name = "{name_a}"'))
    b.write_text(POINTCLOUD_TASK.replace('name = "small"', f'name = "{name_b}"'))
    return a, b


def _wait_for_staging(out: Path, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and proc.poll() is None:
        if out.is_dir() and any(p.name.startswith(".cmmwb-") for p in out.iterdir()):
            return
        time.sleep(0.002)
    pytest.fail("build B never staged its files")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
@pytest.mark.parametrize("same_name", [False, True], ids=["other task", "same task"])
def test_an_interrupted_build_keeps_what_another_build_finished_in_the_same_new_folder(tmp_path, sig,
                                                                                        same_name):
    """B starts into a new folder (it creates it and stages there); A builds into the same folder
    and finishes; then B is interrupted.  A's workbook and JSON are there, unchanged, and no
    staging folder of B is left behind (or B had finished: then its outputs are complete)."""
    a, b = _tasks(tmp_path, "small", "small" if same_name else "other")
    out = tmp_path / "new" / "out"
    proc_b = subprocess.Popen(cmmwb("build", str(b), "--out", str(out)), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, preexec_fn=sigint_as_at_a_terminal)
    _wait_for_staging(out, proc_b)
    run_a = subprocess.run(cmmwb("build", str(a), "--out", str(out), "--no-plots"), capture_output=True,
                           text=True, timeout=120)
    assert run_a.returncode == 0, run_a.stderr
    finished = {n: (out / n).read_bytes() for n in ("small.xlsx", "small.json")}
    proc_b.send_signal(sig)
    _, err_b = proc_b.communicate(timeout=90)
    assert "Traceback" not in err_b, err_b
    names = sorted(p.name for p in out.iterdir())
    assert not [n for n in names if n.startswith(".cmmwb-") and n != ".cmmwb-manifest.json"], names
    if proc_b.returncode in (130, 128 + sig, -sig) and "interrupted" in err_b and "written" not in err_b:
        # B did not commit: A's files are exactly as A left them (a signal during B's commit is held
        # back until the commit is complete: then B says 'interrupted after its outputs were
        # written' and the branches below hold)
        assert {n: (out / n).read_bytes() for n in finished} == finished
    elif same_name:
        # B committed before the signal, and B and A are builds of one task: whichever committed
        # last left that task's outputs complete, and removed what the other wrote that it does
        # not write (docs/cli.md, "Outputs of a build"): A's two files, or B's three
        assert proc_b.returncode in (0, -sig) or f"written, complete, into {out}" in err_b, (proc_b.returncode, err_b)
        last = set(json.loads((out / ".cmmwb-manifest.json").read_text(encoding="utf-8"))["tasks"]["small"])
        assert last in ({"small.xlsx", "small.json"}, {"small.xlsx", "small.json", "small_distances.png"}), last
        assert last <= set(names)
        assert ("small_distances.png" in names) == ("small_distances.png" in last)
    else:   # B committed before the signal: its outputs are complete, and A's
        assert proc_b.returncode in (0, -sig) or f"written, complete, into {out}" in err_b, (proc_b.returncode, err_b)
        assert {"other.xlsx", "other.json", "other_distances.png"} <= set(names)
    assert {"small.xlsx", "small.json", ".cmmwb-manifest.json"} <= set(names)


# -- a closed pipe ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def built_book(tmp_path_factory) -> Path:
    work = tmp_path_factory.mktemp("pipe")
    (work / "small.csv").write_text(POINTCLOUD_CSV)
    (work / "small.toml").write_text(POINTCLOUD_TASK)
    r = subprocess.run(cmmwb("build", str(work / "small.toml"), "--out", str(work / "out"), "--no-plots"),
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return work / "out" / "small.xlsx"


def _with_closed_stdout(args: list[str]) -> tuple[int, str]:
    """Run cmmwb with a stdout pipe whose reader has left before anything was written
    (`cmmwb ... | true`)."""
    proc = subprocess.Popen(cmmwb(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()
    err = proc.stderr.read()
    return proc.wait(timeout=120), err


@pytest.mark.parametrize("command", ["recalc", "recalc --json", "build", "new"])
def test_a_command_whose_reader_closed_the_pipe_exits_141_without_a_word(built_book, tmp_path, command):
    args = {"recalc": ["recalc", str(built_book)],
            "recalc --json": ["recalc", str(built_book), "--json"],
            "build": ["build", str(built_book.parents[1] / "small.toml"), "--out", str(tmp_path / "b"),
                      "--no-plots"],
            "new": ["new", "feature", "--out", str(tmp_path / "n.toml")]}[command]
    code, err = _with_closed_stdout(args)
    assert code == 141, err
    assert "Traceback" not in err and "BrokenPipe" not in err and "Exception ignored" not in err, err


def test_help_into_a_closed_pipe_is_quiet():
    code, err = _with_closed_stdout(["--help"])
    assert code in (0, 141) and err == "", (code, err)
