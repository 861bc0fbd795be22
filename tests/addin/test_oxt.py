"""The LibreOffice Calc add-in extension: packed from the sources, with the type library that
the IDL compiles to, and a component that calls the functions of cmmwb.xlfuncs.udf."""

import ast
import zipfile
from pathlib import Path

import pytest

from cmmwb.generator import oxt
from cmmwb.generator.cli import main
from cmmwb.xlfuncs import udf


def test_build_oxt_writes_an_extension_with_manifest_type_library_component_and_core(tmp_path):
    assert main(["addin", "build-oxt", "--out", str(tmp_path / "cmmwb.oxt")]) == 0
    with zipfile.ZipFile(tmp_path / "cmmwb.oxt") as zf:
        names = set(zf.namelist())
        manifest = zf.read("META-INF/manifest.xml").decode()
        component = zf.read("cmmwb_calc.py").decode()
    assert {"META-INF/manifest.xml", "description.xml", "XCmmwb.rdb", "cmmwb_calc.py",
            "pythonpath/cmmwb/xlfuncs/udf.py", "pythonpath/cmmwb/xlfuncs/blocked.py"} <= names
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


# -- end to end: the extension installed headless computes the Live_addin sheet -------------------

LO_PYTHON = "/usr/bin/python3"  # LibreOffice's Python (python3-uno), not cmmwb's environment
RELINK = oxt.SOURCES / "relink_live.py"


def _lo_python_ready() -> bool:
    import shutil
    import subprocess
    if not (shutil.which("soffice") and shutil.which("unopkg") and Path(LO_PYTHON).exists()):
        return False
    return subprocess.run([LO_PYTHON, "-c", "import uno, numpy"], capture_output=True).returncode == 0


@pytest.fixture(scope="module")
def installed_extension(tmp_path_factory):
    """The extension installed with ``unopkg add --shared`` into a private cache and profile."""
    import subprocess
    if not _lo_python_ready():
        pytest.skip("needs soffice, unopkg and LibreOffice's Python with uno and numpy "
                    "(libreoffice-script-provider-python python3-numpy)")
    tmp = tmp_path_factory.mktemp("lo_ext")
    assert main(["addin", "build-oxt", "--out", str(tmp / "cmmwb.oxt")]) == 0
    cache, profile = tmp / "cache", tmp / "profile"
    env = [f"-env:UNO_SHARED_PACKAGES_CACHE={cache.as_uri()}", f"-env:UserInstallation={profile.as_uri()}"]
    added = subprocess.run(["unopkg", "add", "--shared", *env, str(tmp / "cmmwb.oxt")], capture_output=True,
                           text=True, timeout=300)
    assert added.returncode == 0, added.stderr
    listed = subprocess.run(["unopkg", "list", "--shared", *env], capture_output=True, text=True, timeout=300)
    assert "org.cmmwb.calc" in listed.stdout and "cmmwb_calc.py" in listed.stdout
    return cache, profile


def _relink_and_recalc(book: Path, ext, out_json: Path, *settings: str, relink: bool = True) -> dict:
    import json
    import subprocess
    cache, profile = ext
    cmd = [LO_PYTHON, str(RELINK), str(book), "--json", str(out_json), "--cache", str(cache),
           "--profile", str(profile), *(f"--set={s}" for s in settings)] + ([] if relink else ["--no-relink"])
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=590)
    assert run.returncode == 0, run.stderr
    return json.loads(out_json.read_text())


@pytest.mark.libreoffice
@pytest.mark.parametrize("extra_points", [130, 1880])  # m = 250 and the m = 2000 book of the docs
def test_live_addin_sheet_follows_an_edited_input_in_libreoffice(tmp_path, installed_extension, extra_points):
    import openpyxl

    from cmmwb.generator.cli import build_task
    from cmmwb.generator.pointcloud import large_book
    from cmmwb.generator.pointcloud.vx_sheets import NATIVE_MAX_POINTS

    from tests.helpers import close
    from tests.helpers.addin import evaluate_addin_formulas
    from tests.helpers.tasks import write_large_task

    m = NATIVE_MAX_POINTS + extra_points
    build_task(write_large_task(tmp_path, m, "plate"), tmp_path / "out", plots=False)
    book = tmp_path / "out" / "plate.xlsx"
    inputs = openpyxl.load_workbook(book)["Inputs"]
    row = next(r for r in range(1, 40) if inputs.cell(r, 1).value == "sigma_ET_um")
    sigma_before = inputs.cell(row, 2).value
    sigma_after = 1.75 * sigma_before

    got = _relink_and_recalc(book, installed_extension, tmp_path / "values.json", f"sigma_ET_um={sigma_after!r}")
    values = got["values"]
    assert got["formulas"] == 4  # pair blocks of ET, ER, P and the distances
    assert values["Inputs"][f"B{row}"] == sigma_after
    live = values[large_book.LIVE]
    # every Live_addin cell is what the Python core gives for the edited inputs
    expected = evaluate_addin_formulas(book, values)
    assert len(expected) == m * 36      # 27 pair-block cells, d, u and the seven components (W last)
    for cell, e in expected.items():
        assert close(live.get(cell), e, rel=1e-9, floor=1e-15), f"{cell}: {live.get(cell)!r} != {e!r}"
    # and the edit took effect: V_ET scales with sigma_ET^2 (GP_blocks holds the build-time blocks)
    gp = values[large_book.GP]
    for r in range(2, m + 2):
        for col in "CDEFGHIJK":
            assert close(live[f"{col}{r}"], gp[f"{col}{r}"] * 1.75 ** 2, rel=1e-9, floor=1e-15), f"{col}{r}"


def _small_large_book(folder: Path) -> Path:
    from cmmwb.generator.cli import build_task
    from cmmwb.generator.pointcloud.vx_sheets import NATIVE_MAX_POINTS

    from tests.helpers.tasks import write_large_task
    build_task(write_large_task(folder, NATIVE_MAX_POINTS + 10, "plate"), folder / "out", plots=False)
    return folder / "out" / "plate.xlsx"


@pytest.mark.libreoffice
def test_relink_saves_an_ods_whose_live_addin_computes_on_opening(tmp_path, installed_extension):
    from cmmwb.generator.pointcloud import large_book

    from tests.helpers import close
    from tests.helpers.addin import evaluate_addin_formulas
    cache, profile = installed_extension
    book = _small_large_book(tmp_path)
    ods = tmp_path / "plate.ods"
    assert main(["addin", "relink", str(book), "--out", str(ods), "--profile", str(profile),
                 "--cache", str(cache)]) == 0
    with zipfile.ZipFile(ods) as zf:
        content = zf.read("content.xml").decode()
    assert content.count('formula="of:=ORG.CMMWB.CALC.CMMWBADDIN.') == 4 and 'of:=cmm_' not in content
    # opened as saved (no relinking), the add-in cells compute the core's numbers
    values = _relink_and_recalc(ods, installed_extension, tmp_path / "values.json", relink=False)["values"]
    expected = evaluate_addin_formulas(book, values)
    live = values[large_book.LIVE]
    assert expected and all(close(live.get(k), e, rel=1e-9, floor=1e-15) for k, e in expected.items())


@pytest.mark.libreoffice
def test_relink_without_the_extension_names_the_problem_and_writes_nothing(tmp_path, capsys):
    if not _lo_python_ready():
        pytest.skip("needs LibreOffice's Python with uno and numpy")
    book = _small_large_book(tmp_path)
    ods = tmp_path / "plate.ods"
    assert main(["addin", "relink", str(book), "--out", str(ods), "--profile", str(tmp_path / "empty")]) == 2
    assert not ods.exists()
    err = capsys.readouterr().err
    assert "plate.xlsx" in err and "extension is not installed" in err


@pytest.mark.libreoffice
def test_live_addin_of_a_feature_workbook_computes_in_libreoffice(tmp_path, installed_extension):
    """The large feature workbook (120-point bore, protected sheets, optional arguments): every
    Live_addin cell after an edit of sigma_ET_um equals the core for the edited inputs."""
    import openpyxl

    from cmmwb.generator.cli import build_task
    from cmmwb.generator.pointcloud import large_book

    from tests.helpers import close
    from tests.helpers.addin import evaluate_live
    from tests.helpers.tasks import write_bore_task

    build_task(write_bore_task(tmp_path), tmp_path / "out", plots=False)
    book = tmp_path / "out" / "bore120.xlsx"
    inputs = openpyxl.load_workbook(book)["Inputs"]
    row = next(r for r in range(1, 40) if inputs.cell(r, 1).value == "sigma_ET_um")
    sigma_after = 1.75 * inputs.cell(row, 2).value

    got = _relink_and_recalc(book, installed_extension, tmp_path / "values.json", f"sigma_ET_um={sigma_after!r}")
    values = got["values"]
    assert values["Inputs"][f"B{row}"] == sigma_after
    live = values[large_book.LIVE]
    expected = evaluate_live(book, values)
    numbers = [abs(e) for e in expected.values() if isinstance(e, float)]
    floor = 1e-15 * max(numbers)  # structural zeros: rounding noise of the largest entry
    assert len(numbers) > 100
    for cell, e in expected.items():
        if isinstance(e, str):
            assert live.get(cell) == e, cell
        else:
            assert close(live.get(cell), float(e), rel=1e-9, floor=floor), f"{cell}: {live.get(cell)!r} != {e!r}"


# -- relink: the input checked before LibreOffice starts, one message, nothing left behind ---------

@pytest.fixture(scope="module")
def large_book(tmp_path_factory):
    return _small_large_book(tmp_path_factory.mktemp("large"))


def _relink_refused(capsys, book: Path, out: Path, *words: str) -> None:
    import tempfile

    from tests.helpers.files import assert_clear_failure

    before = sorted(p.name for p in book.parent.iterdir())
    with tempfile.TemporaryDirectory() as profile:          # an empty profile: no extension installed
        code = main(["addin", "relink", str(book), "--out", str(out), "--profile", profile])
    assert_clear_failure(code, capsys.readouterr().err.strip(), book.name if "folder" not in words[0] else out.name,
                         list(words))
    assert sorted(p.name for p in book.parent.iterdir()) == before      # no .~lock.*#, no output
    assert not out.exists()


@pytest.mark.foreign_books   # a macro workbook and a CSV named .xlsx: hostile files on purpose
def test_relink_runs_the_workbook_guard_first(tmp_path, capsys, large_book):
    """A macro workbook was relinked by LibreOffice without a word."""
    book = tmp_path / "plate.xlsx"
    with zipfile.ZipFile(large_book) as src, zipfile.ZipFile(book, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            dst.writestr(info, src.read(info))
        dst.writestr("xl/vbaProject.bin", b"\xd0\xcf\x11\xe0 macros")
    _relink_refused(capsys, book, tmp_path / "plate.ods", "vbaProject")


@pytest.mark.foreign_books
def test_relink_of_a_csv_named_xlsx(tmp_path, capsys):
    book = tmp_path / "points.xlsx"
    book.write_text("id,x,y,z\nA,0,0,0\n", encoding="utf-8")
    _relink_refused(capsys, book, tmp_path / "points.ods", "not an .xlsx file")


def test_relink_of_a_book_without_live_addin(tmp_path, capsys):
    """A workbook of native size has nothing to relink (was an 11-line UNO traceback)."""
    from cmmwb.generator.cli import build_task

    from tests.helpers.tasks import write_random_task
    build_task(write_random_task(tmp_path, seed=3), tmp_path / "out", plots=False)
    _relink_refused(capsys, tmp_path / "out" / "random_3.xlsx", tmp_path / "r.ods", "has no Live_addin sheet")


def test_relink_into_a_folder_that_does_not_exist(tmp_path, capsys, large_book):
    book = tmp_path / "plate.xlsx"
    book.write_bytes(large_book.read_bytes())
    _relink_refused(capsys, book, tmp_path / "missing" / "plate.ods", "folder does not exist")


@pytest.mark.libreoffice
def test_relink_failing_in_libreoffice_leaves_no_lock_file_beside_the_book(tmp_path, capsys, large_book):
    """LibreOffice works on a private copy: its .~lock.plate.xlsx# never appears beside the user's
    book, and its failure is one line (the extension is not installed in an empty profile)."""
    if not _lo_python_ready():
        pytest.skip("needs LibreOffice's Python with uno and numpy")
    book = tmp_path / "plate.xlsx"
    book.write_bytes(large_book.read_bytes())
    _relink_refused(capsys, book, tmp_path / "plate.ods", "extension is not installed")
