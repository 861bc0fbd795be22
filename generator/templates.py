"""The workbook templates in ``workbook_templates/``: one per task kind (the commented task of
``cmmwb new KIND``) and one per worked example of the papers, each built by ``cmmwb build``.

People fill them in (Excel or LibreOffice: yellow cells only), hand them to auditors, and turn
them back into task files with ``cmmwb read``.  The files are byte-for-byte reproducible: the
zip timestamps and the document dates are fixed, so a test can regenerate every template and
compare it with the checked-in file.

    python -m generator.templates             # rewrite workbook_templates/
    python -m generator.templates --check     # exit 1 and list the stale ones
"""

from __future__ import annotations

import argparse
import re
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path

from .atomic import replacing
from .jobs import available, job

TEMPLATE_DIR = Path(__file__).resolve().parents[1] / "workbook_templates"
EXAMPLES_DIR = Path(__file__).parent / "examples"
FIXED_DATE = "2025-01-01T00:00:00Z"
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)
_DATES = re.compile(rb"(<dcterms:(?:created|modified)[^>]*>)[^<]*(</dcterms:(?:created|modified)>)")


def sources() -> dict[str, tuple[str, Path | None]]:
    """Template file name -> (kind, example task file, or None for the kind's NEW_TASK)."""
    out: dict[str, tuple[str, Path | None]] = {}
    for kind in available():
        out[f"{kind}_template.xlsx"] = (kind, None)
        for example in job(kind).EXAMPLES:
            out[f"examples/{Path(example).stem}.xlsx"] = (kind, EXAMPLES_DIR / example)
    return out


def normalise(path: Path) -> None:
    """Fixed zip timestamps and document dates: the same workbook gives the same bytes."""
    path = Path(path)
    with zipfile.ZipFile(path) as z:
        parts = [(i, z.read(i)) for i in z.infolist()]
    with replacing(path) as tmp:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as out:
            for info, data in parts:
                if info.filename == "docProps/core.xml":
                    data = _DATES.sub(rb"\g<1>" + FIXED_DATE.encode() + rb"\g<2>", data)
                zi = zipfile.ZipInfo(info.filename, date_time=_ZIP_DATE)
                zi.compress_type = zipfile.ZIP_DEFLATED
                zi.external_attr = 0o644 << 16
                out.writestr(zi, data)


def build_one(kind: str, example: Path | None, target: Path) -> Path:
    """Build one template into ``target`` (through ``cmmwb build``, no plots)."""
    from .cli import build_task

    with tempfile.TemporaryDirectory(prefix="cmmwb_tpl_") as tmp:
        tmp = Path(tmp)
        if example is None:
            mod = job(kind)
            task = tmp / "task" / f"{kind}_template.toml"
            task.parent.mkdir()
            task.write_text(mod.NEW_TASK, encoding="utf-8")
            for name, text in getattr(mod, "NEW_TASK_FILES", {}).items():
                (task.parent / name).write_text(text, encoding="utf-8")
        else:
            task = example
        results, files = build_task(task, tmp / "out", plots=False)
        book = next(f for f in files if f.suffix == ".xlsx")
        normalise(book)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(book, target)
    return target


def write_all(folder: Path = TEMPLATE_DIR) -> list[Path]:
    return [build_one(kind, ex, Path(folder) / name) for name, (kind, ex) in sources().items()]


def stale(folder: Path = TEMPLATE_DIR) -> list[str]:
    """Names of templates that are missing or differ from what the generator writes now."""
    out = []
    with tempfile.TemporaryDirectory(prefix="cmmwb_tplchk_") as tmp:
        for name, (kind, ex) in sources().items():
            fresh = build_one(kind, ex, Path(tmp) / name)
            have = Path(folder) / name
            if not have.exists() or have.read_bytes() != fresh.read_bytes():
                out.append(name)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m generator.templates", description=__doc__.split("\n\n")[0])
    p.add_argument("--check", action="store_true", help="only report stale templates (exit 1 if any)")
    p.add_argument("--out", default=str(TEMPLATE_DIR), help="folder (default: workbook_templates/)")
    args = p.parse_args(argv)
    if args.check:
        bad = stale(Path(args.out))
        for name in bad:
            print(f"stale: {name}")
        return 1 if bad else 0
    for path in write_all(Path(args.out)):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
