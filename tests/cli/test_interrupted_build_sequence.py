"""The data-loss sequence of issue 33, with real processes and a real signal: a slow build into a
folder that does not exist yet stages its files there; a fast build into the same folder finishes
and reports its workbook and JSON; then the slow build gets Ctrl-C (SIGINT).  It ends with 130 and
the fast build's files are still there, byte for byte, with the manifest naming them."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.helpers.tasks import write_random_task


def sigint_as_at_a_terminal():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def cmmwb(*args) -> list[str]:
    return [sys.executable, "-m", "cmmwb.generator", *map(str, args)]


def staged(out: Path) -> bool:
    """The slow build's staging files have appeared in ``out``."""
    return out.is_dir() and any(p.is_dir() and p.name.startswith(".cmmwb-") for p in out.iterdir())


@pytest.mark.parametrize("wait_s", [0.0, 1.5], ids=["at once", "after 1.5 s"])
def test_ctrl_c_to_a_slow_build_keeps_what_a_fast_build_finished_in_its_new_folder(tmp_path, wait_s):
    slow = write_random_task(tmp_path, seed=1, m=60, name="slow")
    fast = write_random_task(tmp_path, seed=2, m=5, name="fast")
    out = tmp_path / "D"
    assert not out.exists()
    proc = subprocess.Popen(cmmwb("build", slow, "--out", out), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=sigint_as_at_a_terminal)
    deadline = time.monotonic() + 120
    while not staged(out) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)
    assert staged(out), "the slow build never staged its files"
    run = subprocess.run(cmmwb("build", fast, "--out", out, "--no-plots"), capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    assert f"-> {out / 'fast.xlsx'}" in run.stdout and f"-> {out / 'fast.json'}" in run.stdout
    finished = {n: (out / n).read_bytes() for n in ("fast.xlsx", "fast.json")}
    time.sleep(wait_s)
    if proc.poll() is not None:
        pytest.skip("the slow build finished before the signal (a fast machine): nothing to interrupt")
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and err.strip() == "cmmwb: interrupted", (proc.returncode, err)
    assert {n: (out / n).read_bytes() for n in finished} == finished
    names = sorted(p.name for p in out.iterdir())
    assert names == [".cmmwb-manifest.json", "fast.json", "fast.xlsx"], names     # nothing of the slow build
    manifest = json.loads((out / ".cmmwb-manifest.json").read_text(encoding="utf-8"))
    assert manifest["tasks"] == {"fast": ["fast.json", "fast.xlsx"]}


def test_a_ctrl_c_during_the_commit_says_the_outputs_were_written(tmp_path, capsys, monkeypatch):
    """Ctrl-C while a build moves its outputs into DIR is held back until they are all there; the
    build then ends with 130, and says that its outputs were written (it said only 'interrupted',
    as if nothing had been: a two-process test read it so and failed when the signal came then)."""
    import os

    from cmmwb.generator.cli import main
    from cmmwb.generator.workbook import atomic

    commit = atomic.Staging._commit

    def commit_with_ctrl_c(self):
        os.kill(os.getpid(), signal.SIGINT)      # arrives in the middle of the commit
        commit(self)

    monkeypatch.setattr(atomic.Staging, "_commit", commit_with_ctrl_c)
    fast = write_random_task(tmp_path, seed=2, m=5, name="fast")
    out = tmp_path / "D"
    assert main(["build", str(fast), "--out", str(out), "--no-plots"]) == 130
    assert capsys.readouterr().err.strip() == f"cmmwb: interrupted after its outputs were written, complete, into {out}"
    assert sorted(p.name for p in out.iterdir()) == [".cmmwb-manifest.json", "fast.json", "fast.xlsx"]
