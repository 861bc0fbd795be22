"""What ties an output to its inputs (docs/conformity.md, Traceability): the SHA-256 of the task
file and of every file it reads (``file`` keys of the task, e.g. ``[points] file``) or that a
command reads besides (the recordings of ``diagnose`` and ``calibrate``), the time (UTC;
``SOURCE_DATE_EPOCH``, the reproducible-builds convention, fixes it) and the cmmwb version."""

from __future__ import annotations

import datetime as _dt
import os
from pathlib import Path
from typing import Sequence

from .. import __version__
from .atomic import sha256


def _files_of(doc, out: list[str]) -> None:
    if isinstance(doc, dict):
        for k, v in doc.items():
            if k == "file" and isinstance(v, str):
                out.append(v)
            else:
                _files_of(v, out)
    elif isinstance(doc, list):
        for v in doc:
            _files_of(v, out)


def build_time_utc() -> str:
    """Now (UTC, ISO 8601, seconds), or ``SOURCE_DATE_EPOCH`` when set."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    if epoch and epoch.strip().isdigit():
        t = _dt.datetime.fromtimestamp(int(epoch), _dt.timezone.utc)
    else:
        t = _dt.datetime.now(_dt.timezone.utc)
    return t.replace(microsecond=0).isoformat().replace("+00:00", "Z")


def provenance(task_path: Path | None, doc: dict | None, built_utc: str | None = None,
               read: Sequence[Path] = ()) -> dict:
    """``{"task_file": {"name", "sha256"}, "input_files": [{"name", "sha256"}], "built_utc",
    "cmmwb_version"}``: the task file (None: a command run without one, ``task_file`` null), the
    files it names and the files ``read`` besides (recordings)."""
    names: list[str] = []
    _files_of(doc or {}, names)
    inputs = []
    if task_path is not None:
        task_path = Path(task_path)
        for name in dict.fromkeys(names):
            p = task_path.parent / name
            if p.is_file():
                inputs.append({"name": name, "sha256": sha256(p)})
    for p in read:
        inputs.append({"name": Path(p).name, "sha256": sha256(Path(p))})
    return {"task_file": None if task_path is None else {"name": task_path.name, "sha256": sha256(task_path)},
            "input_files": inputs, "built_utc": built_utc or build_time_utc(), "cmmwb_version": __version__}
