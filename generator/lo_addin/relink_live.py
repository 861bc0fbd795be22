"""Make the ``Live_addin`` formulas of a large cmmwb workbook compute in LibreOffice Calc.

LibreOffice 7.4 imports ``cmm_pair_blocks(...)`` of an ``.xlsx`` file as an unknown name
(``#NAME?``): its OOXML import does not map Excel names to a Calc add-in.  Typed into Calc (or
set over UNO) the same formula resolves to the add-in of the cmmwb extension
(``ORG.CMMWB.CALC.CMMWBADDIN.CMM_PAIR_BLOCKS``) and computes.  This script opens the workbook in
a headless LibreOffice that has the extension installed, enters every array formula of
``Live_addin`` again (same text, Calc's ``;`` separators), recalculates, and either saves the book
as ``.ods`` (which stores the add-in names, so it opens live in Calc) or writes the values as
JSON (used by the tests).

It runs in LibreOffice's Python (``/usr/bin/python3`` with ``python3-uno``), not in cmmwb's
environment::

    /usr/bin/python3 relink_live.py BOOK.xlsx --out BOOK.ods [--profile DIR] [--cache DIR]
    /usr/bin/python3 relink_live.py BOOK.xlsx --json OUT.json [--set sigma_ET_um=0.3] ...
    /usr/bin/python3 relink_live.py BOOK.ods --no-relink --json OUT.json ...

``--profile`` is the LibreOffice user profile (default: the user's own, where ``unopkg add``
installs), ``--cache`` the ``UNO_SHARED_PACKAGES_CACHE`` of a private ``unopkg add --shared``.
``--set NAME=VALUE`` changes the value of an input parameter (column B of the ``Inputs`` row
whose column A is NAME) before recalculating.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import uno
from com.sun.star.beans import PropertyValue

LIVE = "Live_addin"
INPUTS = "Inputs"


def _pv(name, value):
    p = PropertyValue()
    p.Name, p.Value = name, value
    return p


def _calc_separators(formula: str) -> str:
    """An array formula as ``getArrayFormula`` gives it, ready for ``setArrayFormula``: no
    braces, ``;`` between arguments (``,`` inside string literals is kept)."""
    if formula.startswith("{") and formula.endswith("}"):
        formula = formula[1:-1]
    parts = formula.split('"')
    return '"'.join(p.replace(",", ";") if i % 2 == 0 else p for i, p in enumerate(parts))


def live_blocks(sheet):
    """(cell range, formula) of every array formula on the sheet, row by row."""
    used = sheet.createCursor()
    used.gotoEndOfUsedArea(False)
    last_col, last_row = used.RangeAddress.EndColumn, used.RangeAddress.EndRow
    out, row = [], 1
    while row <= last_row:
        col, next_row = 0, row + 1
        while col <= last_col:
            cur = sheet.createCursorByRange(sheet.getCellByPosition(col, row))
            cur.collapseToCurrentArray()
            ra = cur.RangeAddress
            formula = cur.getArrayFormula()
            if formula and ra.StartRow == row:
                out.append((sheet.getCellRangeByPosition(ra.StartColumn, ra.StartRow, ra.EndColumn, ra.EndRow),
                            formula))
                next_row = max(next_row, ra.EndRow + 1)
            col = ra.EndColumn + 1 if formula else col + 1
        row = next_row
    return out


def relink(doc) -> int:
    """Enter every array formula of ``Live_addin`` again so that Calc binds the names to the
    add-in; returns the number of formulas."""
    sheet = doc.Sheets.getByName(LIVE)
    protected = sheet.isProtected()
    if protected:  # cmmwb protects its sheets without password; a protected range ignores setArrayFormula
        sheet.unprotect("")
        if sheet.isProtected():
            raise SystemExit(f"{LIVE}: the sheet is protected with a password; unprotect it first")
    blocks = live_blocks(sheet)
    for rng, formula in blocks:
        rng.setArrayFormula(_calc_separators(formula))
        if "cmm_" in formula.lower() and "ORG.CMMWB.CALC." not in rng.getCellByPosition(0, 0).getFormula().upper():
            raise SystemExit(f"{LIVE}: {formula[:40]}... does not resolve to the cmmwb add-in: the extension "
                             "is not installed in this LibreOffice profile (unopkg add cmmwb.oxt)")
    if protected:
        sheet.protect("")
    return len(blocks)


def set_parameter(doc, name: str, value: float) -> None:
    sheet = doc.Sheets.getByName(INPUTS)
    for r in range(0, 200):
        if sheet.getCellByPosition(0, r).getString() == name:
            sheet.getCellByPosition(1, r).setValue(value)
            return
    raise SystemExit(f"{INPUTS}: no parameter {name!r} in column A")


def _col(c: int) -> str:
    name, n = "", c + 1
    while n:
        n, k = divmod(n - 1, 26)
        name = chr(65 + k) + name
    return name


def sheet_values(sheet) -> dict:
    """{"A1": value} of the used area: numbers as float, text as str, empty cells left out,
    formula cells with an error as "Err:NNN"."""
    used = sheet.createCursor()
    used.gotoEndOfUsedArea(False)
    ra = used.RangeAddress
    data = sheet.getCellRangeByPosition(0, 0, ra.EndColumn, ra.EndRow).getDataArray()
    out = {f"{_col(c)}{r + 1}": v for r, row in enumerate(data) for c, v in enumerate(row) if v != ""}
    errors = sheet.queryFormulaCells(4)  # com.sun.star.sheet.FormulaResult.ERROR
    for addr in errors.RangeAddresses:
        for r in range(addr.StartRow, addr.EndRow + 1):
            for c in range(addr.StartColumn, addr.EndColumn + 1):
                out[f"{_col(c)}{r + 1}"] = f"Err:{sheet.getCellByPosition(c, r).getError()}"
    return out


def _connect(profile, cache, pipe):
    cmd = ["soffice", "--headless", "--norestore", "--invisible", f"--accept=pipe,name={pipe};urp;"]
    if profile:
        cmd.insert(1, f"-env:UserInstallation={Path(profile).resolve().as_uri()}")
    if cache:
        cmd.insert(1, f"-env:UNO_SHARED_PACKAGES_CACHE={Path(cache).resolve().as_uri()}")
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    local = uno.getComponentContext()
    resolver = local.ServiceManager.createInstanceWithContext("com.sun.star.bridge.UnoUrlResolver", local)
    for _ in range(240):
        try:
            ctx = resolver.resolve(f"uno:pipe,name={pipe};urp;StarOffice.ComponentContext")
            break
        except Exception:
            if proc.poll() is not None:
                raise SystemExit("LibreOffice (soffice) ended before it accepted the connection")
            time.sleep(0.25)
    else:
        proc.kill()
        raise SystemExit("LibreOffice (soffice) did not accept the connection within 60 s")
    desktop = ctx.ServiceManager.createInstanceWithContext("com.sun.star.frame.Desktop", ctx)
    return proc, desktop


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("book")
    ap.add_argument("--out", help="save the relinked book as this .ods file")
    ap.add_argument("--json", help="write {sheet: {cell: value}} after recalculation to this file")
    ap.add_argument("--profile")
    ap.add_argument("--cache")
    ap.add_argument("--no-relink", action="store_true",
                    help="only recalculate (for a book already relinked, e.g. the saved .ods)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    a = ap.parse_args(argv)
    book = Path(a.book).resolve()
    if not book.is_file():
        print(f"{book}: no such file", file=sys.stderr)
        return 2
    proc, desktop = _connect(a.profile, a.cache, f"cmmwb_relink_{os.getpid()}")
    timing = {}
    doc = None
    try:
        t0 = time.perf_counter()
        doc = desktop.loadComponentFromURL(book.as_uri(), "_blank", 0, (_pv("Hidden", True),))
        if doc is None or not doc.Sheets.hasByName(LIVE):
            raise SystemExit(f"{book.name}: no {LIVE} sheet (not a large cmmwb workbook)")
        timing["load_s"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        n = 0 if a.no_relink else relink(doc)
        for item in a.set:
            name, value = item.split("=", 1)
            set_parameter(doc, name.strip(), float(value))
        doc.calculateAll()
        timing["relink_and_recalc_s"] = time.perf_counter() - t0
        if a.json:
            values = {s.Name: sheet_values(s) for s in doc.Sheets}
            Path(a.json).write_text(json.dumps({"formulas": n, "timing": timing, "values": values}))
        if a.out:
            out = Path(a.out).resolve()
            with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
                part = Path(tmp) / out.name
                doc.storeToURL(part.as_uri(), (_pv("FilterName", "calc8"),))
                part.replace(out)
    except SystemExit:
        raise
    except Exception as e:   # UNO errors: one line for cmmwb's message, not a traceback
        raise SystemExit(f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}") from None
    finally:
        if doc is not None:     # closed on every path: LibreOffice removes its lock file
            try:
                doc.close(True)
            except Exception:
                pass
        try:
            desktop.terminate()
        except Exception:
            pass
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
    print(f"{book.name}: {n} Live_addin formulas relinked"
          + (f", saved {a.out}" if a.out else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
