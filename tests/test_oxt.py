"""The LibreOffice Calc add-in extension: packed from the sources, with the type library that
the IDL compiles to, and a component that calls the functions of xlfuncs.udf."""

import ast
import zipfile

import pytest

from generator import oxt
from generator.cli import main
from xlfuncs import udf


def test_build_oxt_writes_an_extension_with_manifest_type_library_component_and_core(tmp_path):
    assert main(["addin", "build-oxt", "--out", str(tmp_path / "cmmwb.oxt")]) == 0
    with zipfile.ZipFile(tmp_path / "cmmwb.oxt") as zf:
        names = set(zf.namelist())
        manifest = zf.read("META-INF/manifest.xml").decode()
        component = zf.read("cmmwb_calc.py").decode()
    assert {"META-INF/manifest.xml", "description.xml", "XCmmwb.rdb", "cmmwb_calc.py",
            "pythonpath/xlfuncs/udf.py", "pythonpath/xlfuncs/blocked.py"} <= names
    assert "uno-typelibrary;type=RDB" in manifest and "uno-component;type=Python" in manifest
    assert "@VERSION@" not in component


def test_component_offers_every_function_of_the_xlwings_add_in():
    tree = ast.parse((oxt.SOURCES / oxt.COMPONENT).read_text())
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "CmmwbAddIn")
    methods = {n.name for n in cls.body if isinstance(n, ast.FunctionDef)}
    assert {name.upper() for name in udf.UDFS} <= methods


def test_shipped_type_library_is_what_unoidl_write_makes_of_the_idl(tmp_path):
    if oxt.unoidl_write() is None:
        pytest.skip("unoidl-write (libreoffice-dev) not installed")
    fresh = oxt.rebuild_type_library(tmp_path / "XCmmwb.rdb")
    assert fresh.read_bytes() == (oxt.SOURCES / oxt.TYPE_LIBRARY).read_bytes()


def test_existing_oxt_is_kept_without_force(tmp_path, capsys):
    (tmp_path / "cmmwb.oxt").write_bytes(b"old")
    assert main(["addin", "build-oxt", "--out", str(tmp_path / "cmmwb.oxt")]) == 2
    assert (tmp_path / "cmmwb.oxt").read_bytes() == b"old"
    assert "exists already" in capsys.readouterr().err
