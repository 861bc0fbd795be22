"""``cmmwb addin build-oxt``: pack the LibreOffice Calc add-in (``generator/lo_addin``) into an
installable extension (``.oxt``, a zip) from the sources of this installation.

Contents of the extension:

``META-INF/manifest.xml``  registers the type library and the Python UNO component
``description.xml``        identifier ``org.cmmwb.calc`` and the cmmwb version
``XCmmwb.rdb``             type library of the interface ``org.cmmwb.calc.XCmmwb``, generated from
                           ``XCmmwb.idl`` by LibreOffice's ``unoidl-write`` (shipped with the
                           sources, so packing needs no SDK; :func:`rebuild_type_library` remakes it)
``cmmwb_calc.py``          the component: Calc functions calling ``cmmwb.xlfuncs.udf``
``CalcAddIns.xcu``         the functions' names, descriptions and Excel (compatibility) names as
                           configuration data: Calc reads it at start-up, so the ``.xlsx`` import
                           maps ``cmm_pair_blocks(...)`` to the add-in (without it the compatibility
                           names come too late and the cells show #NAME?)
``pythonpath/cmmwb/``      the numerical core as ``cmmwb.xlfuncs`` (every module of its package
                           tree; ``cmmwb`` is a namespace package, no ``__init__.py``), copied
                           from this installation; LibreOffice adds ``pythonpath`` beside a component to
                           ``sys.path``, and the component imports ``cmmwb.xlfuncs.udf``, the
                           module the xlwings add-in names

Install with ``unopkg add cmmwb.oxt`` (see docs/addins.md).  LibreOffice's Python must have
numpy (Debian: ``python3-numpy``).
"""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

from cmmwb import xlfuncs

from . import __version__
from .workbook.atomic import replacing

SOURCES = Path(__file__).parent / "lo_addin"
COMPONENT = "cmmwb_calc.py"
TYPE_LIBRARY = "XCmmwb.rdb"
IMPLEMENTATION = "org.cmmwb.calc.CmmwbAddIn"

MANIFEST = """<?xml version="1.0" encoding="UTF-8"?>
<manifest:manifest xmlns:manifest="http://openoffice.org/2001/manifest">
  <manifest:file-entry manifest:media-type="application/vnd.sun.star.uno-typelibrary;type=RDB"
                       manifest:full-path="{rdb}"/>
  <manifest:file-entry manifest:media-type="application/vnd.sun.star.uno-component;type=Python"
                       manifest:full-path="{component}"/>
  <manifest:file-entry manifest:media-type="application/vnd.sun.star.configuration-data"
                       manifest:full-path="CalcAddIns.xcu"/>
</manifest:manifest>
"""


def functions() -> dict:
    """``FUNCTIONS`` of the component (name -> (argument names, description)), read without
    importing it (it needs LibreOffice's ``uno``)."""
    import ast

    tree = ast.parse((SOURCES / COMPONENT).read_text())
    for node in tree.body:
        if isinstance(node, ast.AnnAssign | ast.Assign):
            target = node.target if isinstance(node, ast.AnnAssign) else node.targets[0]
            if getattr(target, "id", None) == "FUNCTIONS":
                return ast.literal_eval(node.value)
    raise RuntimeError(f"no FUNCTIONS in {COMPONENT}")


def calc_addins_xcu() -> str:
    """Configuration data ``org.openoffice.Office.CalcAddIns`` describing every function, with
    its Excel name (upper case; Calc compares names without case) as ``CompatibilityName``."""
    from xml.sax.saxutils import escape, quoteattr

    def prop(name: str, value: str, lang: bool = True) -> str:
        attr = ' xml:lang="en-US"' if lang else ""
        return f'<prop oor:name="{name}"><value{attr}>{escape(value)}</value></prop>'

    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           '<oor:component-data xmlns:oor="http://openoffice.org/2001/registry" '
           'xmlns:xs="http://www.w3.org/2001/XMLSchema" oor:name="CalcAddIns" oor:package="org.openoffice.Office">',
           '<node oor:name="AddInInfo">',
           f'<node oor:name={quoteattr(IMPLEMENTATION)} oor:op="replace">',
           '<node oor:name="AddInFunctions">']
    for name, (args, description) in functions().items():
        out.append(f'<node oor:name={quoteattr(name.upper())} oor:op="replace">')
        out += [prop("DisplayName", name), prop("Description", description),
                prop("Category", "Add-In", lang=False), prop("CompatibilityName", name.upper())]
        out.append('<node oor:name="Parameters">')
        for arg in args:
            out.append(f'<node oor:name={quoteattr(arg)} oor:op="replace">'
                       f'{prop("DisplayName", arg)}{prop("Description", arg)}</node>')
        out.append("</node></node>")
    out += ["</node></node></node>", "</oor:component-data>", ""]
    return "\n".join(out)


def oxt_bytes() -> bytes:
    """The extension as the bytes of a zip file (same sources give the same files)."""
    import io

    buf = io.BytesIO()
    fixed = (2020, 1, 1, 0, 0, 0)

    def add(name: str, data: bytes) -> None:
        info = zipfile.ZipInfo(name, fixed)
        info.compress_type = zipfile.ZIP_DEFLATED
        info.external_attr = 0o644 << 16
        zf.writestr(info, data)

    with zipfile.ZipFile(buf, "w") as zf:
        add("META-INF/manifest.xml", MANIFEST.format(rdb=TYPE_LIBRARY, component=COMPONENT).encode())
        add("description.xml", (SOURCES / "description.xml").read_text().replace("@VERSION@", __version__).encode())
        add(TYPE_LIBRARY, (SOURCES / TYPE_LIBRARY).read_bytes())
        add("CalcAddIns.xcu", calc_addins_xcu().encode())
        add(COMPONENT, (SOURCES / COMPONENT).read_text().replace("@VERSION@", __version__).encode())
        core = Path(xlfuncs.__file__).parent
        for f in sorted(core.rglob("*.py")):          # with its subpackages (features/, partial/, ...)
            add(f"pythonpath/cmmwb/xlfuncs/{f.relative_to(core).as_posix()}", f.read_bytes())
    return buf.getvalue()


def build_oxt(out: Path) -> Path:
    """Write the extension to ``out`` (atomically)."""
    out = Path(out)
    with replacing(out) as tmp:
        tmp.write_bytes(oxt_bytes())
    return out


def unoidl_write() -> str | None:
    """LibreOffice SDK's ``unoidl-write`` (Debian package ``libreoffice-dev``), or None."""
    for cand in (shutil.which("unoidl-write"), "/usr/lib/libreoffice/sdk/bin/unoidl-write"):
        if cand and Path(cand).exists():
            return cand
    return None


def rebuild_type_library(out: Path, program_dir: Path = Path("/usr/lib/libreoffice/program")) -> Path:
    """Compile ``XCmmwb.idl`` into a type library at ``out`` with ``unoidl-write`` (needs the
    SDK; the shipped ``XCmmwb.rdb`` is its output)."""
    exe = unoidl_write()
    if exe is None:
        raise RuntimeError("unoidl-write not found (Debian: apt-get install libreoffice-dev)")
    subprocess.run([exe, str(program_dir / "types.rdb"), str(SOURCES / "XCmmwb.idl"), str(out)],
                   check=True, capture_output=True, text=True)
    return Path(out)
