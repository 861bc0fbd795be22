"""The workbook templates in ``workbook_templates/``: one per task kind (the commented task of
``cmmwb new KIND``) and one per worked example of the papers, each built by ``cmmwb build``.

People fill them in (Excel or LibreOffice: yellow cells only), hand them to auditors, and turn
them back into task files with ``cmmwb read``.  The files are reproducible in content: a test
regenerates every template and compares it with the checked-in file cell by cell (formulas, text,
styles, names, validations, print setup, cached values), numbers to the relative tolerance
``REL`` (see :func:`differences`), so that a different BLAS kernel (another CPU) that sums in
another order still finds the templates current.  The zip timestamps and document dates are fixed
as well, so on one machine the bytes repeat too.

    python -m generator.templates             # rewrite workbook_templates/
    python -m generator.templates --check     # exit 1 and list the stale ones
"""

from __future__ import annotations

import argparse
import math
import re
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path

from .jobs import JOBS, job
from .workbook.atomic import replacing
from .workbook.tasksheet import TASK_SHEET

TEMPLATE_DIR = Path(__file__).resolve().parents[1] / "workbook_templates"
EXAMPLES_DIR = Path(__file__).parent / "examples"
FIXED_DATE = "2025-01-01T00:00:00Z"
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)
_DATES = re.compile(rb"(<dcterms:(?:created|modified)[^>]*>)[^<]*(</dcterms:(?:created|modified)>)")


def sources() -> dict[str, tuple[str, Path | None]]:
    """Template file name -> (kind, example task file, or None for the kind's NEW_TASK)."""
    out: dict[str, tuple[str, Path | None]] = {}
    for kind in JOBS:
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
    from .build import build_task

    with tempfile.TemporaryDirectory(prefix="cmmwb_tpl_") as tmp:
        tmp = Path(tmp)
        if example is None:
            mod = job(kind)
            task = tmp / "task" / f"{kind}_template.toml"
            task.parent.mkdir()
            task.write_text(mod.NEW_TASK, encoding="utf-8")
            for name, text in mod.NEW_TASK_FILES.items():
                (task.parent / name).write_text(text, encoding="utf-8")
        else:
            task = example
        results, files = build_task(task, tmp / "out", plots=False, built_utc=FIXED_DATE)
        book = next(f for f in files if f.suffix == ".xlsx")
        normalise(book)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(book, target)
    return target


def write_all(folder: Path = TEMPLATE_DIR) -> list[Path]:
    return [build_one(kind, ex, Path(folder) / name) for name, (kind, ex) in sources().items()]


#: Numbers in two templates agree when |a - b| <= REL * max(|a|, |b|) + REL * scale, where scale
#: is the largest |number| of the same sheet and kind (cell values, cached values).  Summation in
#: another order changes a double by a few ulps (1e-16 relative) per operation; the longest chains
#: here (m = 52 V_X blocks, Cholesky and inverses of feature normal matrices) stay below 1e-12, so
#: 1e-9 cannot be broken by a kernel change yet catches any real change of a formula or input.  The
#: ``scale`` term covers quantities that are exactly zero in theory (they come out as 1e-22 on one
#: kernel and 0.0 on another).
REL = 1e-9

_NUMBER = re.compile(r"(?<![A-Za-z_$0-9.])(\d+\.?\d*(?:[eE][-+]?\d+)?)")


def _style(c) -> tuple:
    return (c.number_format, c.font.b, c.font.i, c.font.color.rgb if c.font.color is not None else None,
            c.fill.fill_type, c.fill.fgColor.rgb, c.protection.locked, c.alignment.horizontal,
            c.alignment.wrap_text)


def _formula_text(v) -> tuple[str, list[float]]:
    """A formula as (text with its numeric literals replaced by #, the literals)."""
    text = v.text if hasattr(v, "text") else str(v)
    ref = getattr(v, "ref", None)
    nums = [float(n) for n in _NUMBER.findall(text)]
    return (f"{ref}|" if ref else "") + _NUMBER.sub("#", text), nums


def content(path: Path) -> dict:
    """What a template holds, as comparable plain values (see :func:`differences`)."""
    import openpyxl

    wb = openpyxl.load_workbook(path)
    cached = openpyxl.load_workbook(path, data_only=True)
    out: dict = {"sheets": wb.sheetnames,
                 "names": {n: str(d.attr_text) for n, d in wb.defined_names.items()}}
    for ws in wb.worksheets:
        cells, numbers, values = {}, {}, {}
        for row in ws.iter_rows():
            for c in row:
                v = c.value
                if v is None and not c.has_style:
                    continue
                if isinstance(v, bool) or isinstance(v, str) and not v.startswith("=") or v is None:
                    cells[c.coordinate] = ("v", v, _style(c))
                elif isinstance(v, (int, float)):
                    cells[c.coordinate] = ("n", None, _style(c))
                    numbers[c.coordinate] = [float(v)]
                else:
                    text, nums = _formula_text(v)
                    cells[c.coordinate] = ("f", text, _style(c))
                    numbers[c.coordinate] = nums
        for row in cached[ws.title].iter_rows():
            for c in row:
                if isinstance(c.value, (int, float)) and not isinstance(c.value, bool):
                    values[c.coordinate] = float(c.value)
                elif c.value is not None:
                    values[c.coordinate] = c.value
        if ws.title == TASK_SHEET:
            _join_task_json(cells, numbers, values)
        out[ws.title] = {
            "cells": cells, "numbers": numbers, "cached": values,
            "state": ws.sheet_state, "merged": sorted(str(r) for r in ws.merged_cells.ranges),
            "widths": {k: d.width for k, d in ws.column_dimensions.items() if d.width},
            "validations": sorted((str(dv.sqref), dv.type, dv.operator, _formula_text(dv.formula1 or "")[0],
                                   _formula_text(dv.formula2 or "")[0]) for dv in ws.data_validations.dataValidation),
            "protected": bool(ws.protection.sheet),
            "print": (ws.page_setup.orientation, ws.page_setup.fitToWidth, ws.page_setup.fitToHeight,
                      str(ws.print_title_rows), str(ws.print_area) if ws.print_area else None),
            "charts": len(ws._charts), "comments": sorted(c.coordinate for r in ws.iter_rows()
                                                            for c in r if c.comment is not None),
        }
    return out


def _join_task_json(cells: dict, numbers: dict, values: dict) -> None:
    """The hidden ``_task`` sheet holds one JSON text cut into cells A2, A3 ... at fixed lengths.
    Its input snapshot carries numbers a kernel may change in the last bits (a tolerance limit
    around a fitted value, say), and a number with one digit more moves every cut after it: the
    chunks are joined into one text (pseudo-cell ``A2:JSON``) whose numbers are compared like a
    formula's literals, to the relative tolerance :data:`REL`, and the rest exactly."""
    chunks = sorted((int(k[1:]), k) for k, v in cells.items()
                    if k.startswith("A") and k[1:].isdigit() and int(k[1:]) >= 2 and v[0] == "v"
                    and isinstance(v[1], str))
    if not chunks:
        return
    text = "".join(cells[k][1] for _, k in chunks)
    style = cells[chunks[0][1]][2]
    for _, k in chunks:
        cells.pop(k)
        values.pop(k, None)
    cells["A2:JSON"] = ("v", _NUMBER.sub("#", text), style)
    numbers["A2:JSON"] = [float(n) for n in _NUMBER.findall(text)]


def _numbers_agree(a: float, b: float, scale: float) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        return abs(a - b) <= REL * max(abs(a), abs(b)) + REL * scale
    return a == b


def differences(have: Path, fresh: Path, most: int = 5) -> list[str]:
    """How two templates differ in content (at most ``most`` lines); [] when they agree."""
    a, b = content(have), content(fresh)
    out: list[str] = []
    for key in ("sheets", "names"):
        if a[key] != b[key]:
            out.append(f"{key} differ")
    for sheet in b["sheets"]:
        if sheet not in a:
            continue
        sa, sb = a[sheet], b[sheet]
        for key in ("cells", "state", "merged", "widths", "validations", "protected", "print", "charts",
                    "comments"):
            if sa[key] != sb[key]:
                diff = ([k for k in set(sa[key]) | set(sb[key]) if sa[key].get(k) != sb[key].get(k)][:3]
                        if isinstance(sa[key], dict) else "")
                out.append(f"{sheet}: {key} differ {diff}".rstrip())
        for key in ("numbers", "cached"):
            flat = [abs(x) for v in sb[key].values() for x in (v if isinstance(v, list) else [v])
                    if isinstance(x, float) and math.isfinite(x)]
            scale = max(flat, default=0.0)
            for coord in sorted(set(sa[key]) | set(sb[key])):
                x, y = sa[key].get(coord), sb[key].get(coord)
                xs, ys = (x if isinstance(x, list) else [x]), (y if isinstance(y, list) else [y])
                if len(xs) != len(ys) or not all(_numbers_agree(p, q, scale) for p, q in zip(xs, ys)):
                    out.append(f"{sheet}!{coord}: {key} {x!r} != {y!r}")
                    break
    return out[:most]


def stale(folder: Path = TEMPLATE_DIR) -> list[str]:
    """Names of templates that are missing or differ in content from what the generator writes
    now (see :func:`differences`), each with the first difference."""
    out = []
    with tempfile.TemporaryDirectory(prefix="cmmwb_tplchk_") as tmp:
        for name, (kind, ex) in sources().items():
            fresh = build_one(kind, ex, Path(tmp) / name)
            have = Path(folder) / name
            if not have.exists():
                out.append(f"{name} (missing)")
                continue
            if have.read_bytes() == fresh.read_bytes():
                continue
            diff = differences(have, fresh)
            if diff:
                out.append(f"{name} ({'; '.join(diff)})")
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
