"""cmmwb's own modules, whatever else is called `generator` or `xlfuncs` (issue 27).

The installation has `generator/` and `xlfuncs/` as `cmmwb.generator` and `cmmwb.xlfuncs`;
`cmmwb` is an implicit namespace package (no folder of its own, so the tree keeps its top
level). A user's `generator.py` beside a workbook (xlwings puts that folder first on `sys.path`)
or the unrelated `generator` distribution of the package index must not stand in for them. The
wheel test builds and installs a real wheel (slow: pip). A `cmmwb.py` beside the workbook does
stand in for cmmwb (as it would for a regular package `cmmwb`, measured): docs/developing.md.
"""

from __future__ import annotations

import ast
import os
import re
import shutil
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: modules that must never be imported when a cmmwb command runs
HOSTILE = {
    "generator.py": "raise ImportError('the hostile generator.py was imported')\n",
    "xlfuncs.py": "raise ImportError('the hostile xlfuncs.py was imported')\n",
}

#: run in a folder holding HOSTILE, that folder first on sys.path (as xlwings does): the command
#: line, the add-in module the workbooks name, and where each module came from
PROBE = """
import contextlib, io, json, sys
sys.path.insert(0, ".")
from cmmwb.generator.cli import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    try:
        status = main(["--version"])
    except SystemExit as e:
        status = e.code
import importlib
udf = importlib.import_module(sys.argv[1])
print(json.dumps({"status": status, "version": out.getvalue().strip(),
                  "cmmwb_file": getattr(sys.modules["cmmwb"], "__file__", None),
                  "udf": udf.__file__, "udf_version": udf.cmm_version(),
                  "top_level": sorted(m for m in sys.modules if m.split('.')[0] in ('generator', 'xlfuncs'))}))
"""


def _hostile_folder(tmp_path: Path) -> Path:
    folder = tmp_path / "workbooks"
    folder.mkdir()
    for name, text in HOSTILE.items():
        (folder / name).write_text(text)
    return folder


def _probe(python: str, folder: Path, env: dict | None = None) -> dict:
    import json

    r = subprocess.run([python, "-c", PROBE, "cmmwb.xlfuncs.udf"], cwd=folder, capture_output=True,
                       text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def _only_cmmwb(result: dict) -> None:
    assert result["status"] == 0
    assert re.fullmatch(r"cmmwb \d+\.\d+\.\d+", result["version"]), result["version"]
    assert result["udf_version"] == result["version"]
    assert result["top_level"] == []        # no `generator`, no `xlfuncs` imported: only cmmwb.*
    assert result["cmmwb_file"] is None     # cmmwb is a namespace package: no file of its own


def test_the_editable_install_ignores_a_hostile_generator_and_xlfuncs_beside_the_workbook(tmp_path):
    folder = _hostile_folder(tmp_path)
    result = _probe(sys.executable, folder)
    _only_cmmwb(result)
    assert Path(result["udf"]) == ROOT / "xlfuncs" / "udf.py"


def test_the_console_script_runs_beside_a_hostile_generator(tmp_path):
    folder = _hostile_folder(tmp_path)
    script = Path(sys.executable).with_name("cmmwb")
    r = subprocess.run([str(script), "new", "pointcloud", "--out", "task.toml"], cwd=folder,
                       capture_output=True, text=True, timeout=120,
                       env={**os.environ, "PYTHONPATH": str(folder)})
    assert r.returncode == 0, r.stderr
    assert (folder / "task.toml").is_file()


def test_python_dash_m_cmmwb_generator_runs_beside_a_hostile_generator(tmp_path):
    """`python -m cmmwb.generator`, what the tests' subprocesses run, works from any folder."""
    folder = _hostile_folder(tmp_path)
    r = subprocess.run([sys.executable, "-m", "cmmwb.generator", "--version"], cwd=folder,
                       capture_output=True, text=True, timeout=120,
                       env={**os.environ, "PYTHONPATH": str(folder)})
    assert r.returncode == 0, r.stderr
    assert re.fullmatch(r"cmmwb \d+\.\d+\.\d+", r.stdout.strip()), r.stdout


def test_python_dash_m_generator_in_a_checkout_runs_each_module_once():
    """`python -m generator` (cwd = the checkout) is the command line, and `generator.x` is the
    module `cmmwb.generator.x` itself, not a second copy (xlfuncs/checkout.py)."""
    r = subprocess.run([sys.executable, "-m", "generator", "--version"], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.startswith("cmmwb "), r.stderr
    code = ("import generator.errors, cmmwb.generator.errors, xlfuncs.udf, cmmwb.xlfuncs.udf, sys\n"
            "assert generator.errors is cmmwb.generator.errors\n"
            "assert generator.errors.InputError is cmmwb.generator.errors.InputError\n"
            "assert xlfuncs.udf is cmmwb.xlfuncs.udf\n"
            "assert sys.modules['generator.errors'].__spec__.name == 'cmmwb.generator.errors'\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


def test_the_shim_itself_is_one_module_in_a_checkout():
    """xlfuncs/__init__.py takes the shim from its own folder (``xlfuncs.checkout`` loaded before the
    alias): that early copy is dropped, and the later ``xlfuncs.checkout`` is the installed module."""
    code = ("import generator, xlfuncs.checkout, cmmwb.xlfuncs.checkout, sys\n"
            "assert xlfuncs.checkout is cmmwb.xlfuncs.checkout\n"
            "copies = [n for n, m in sys.modules.items() if n.split('.')[0] in ('generator', 'xlfuncs')\n"
            "          and not m.__name__.startswith('cmmwb.')]\n"
            "assert copies == [], copies\n"
            "assert sorted(f.short for f in sys.meta_path if type(f).__name__ == '_AliasFinder') == "
            "['generator', 'xlfuncs']\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr


def test_python_dash_m_generator_from_a_checkout_on_the_path_ignores_a_hostile_xlfuncs(tmp_path):
    """The checkout on PYTHONPATH, a user's ``xlfuncs.py`` in the working folder (first on sys.path):
    ``generator/__init__.py`` takes the shim from its sibling folder xlfuncs/, not from sys.path."""
    folder = tmp_path / "workbooks"
    folder.mkdir()
    (folder / "xlfuncs.py").write_text(HOSTILE["xlfuncs.py"])
    r = subprocess.run([sys.executable, "-m", "generator", "--version"], cwd=folder, capture_output=True,
                       text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0, r.stderr
    assert re.fullmatch(r"cmmwb \d+\.\d+\.\d+", r.stdout.strip()), r.stdout


def test_python_dash_m_generator_in_a_checkout_without_cmmwb_says_to_install_it():
    """``-S``: no site-packages, so neither cmmwb nor its dependencies; the shim (standard library
    only, xlfuncs/checkout.py) still runs and names the command that installs the checkout."""
    for module in ("generator", "xlfuncs.udf"):
        r = subprocess.run([sys.executable, "-S", "-m", module, "--help"], cwd=ROOT, capture_output=True,
                           text=True, timeout=120)
        assert r.returncode == 1
        last = r.stderr.strip().splitlines()[-1]
        assert last.startswith("ModuleNotFoundError: this checkout's generator/ and xlfuncs/ are installed as "
                               "cmmwb.generator and cmmwb.xlfuncs, and cmmwb is not installed"), r.stderr
        assert "`python -m pip install -e .`" in last


def _absolute_imports_of_bare_top_level(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            names = [node.module or ""]
        else:
            continue
        out += [f"{path.relative_to(ROOT)}:{node.lineno}: {n}" for n in names
                if n.partition(".")[0] in ("generator", "xlfuncs")]
    return out


def test_every_import_of_the_project_is_cmmwb_prefixed_or_relative():
    """`from xlfuncs import ...` works in a checkout and fails for a user (and would load a second
    copy of the module): code, tests and bench say `cmmwb.xlfuncs` (or import relatively)."""
    bad = []
    for folder in ("generator", "xlfuncs", "tests", "bench"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            bad += _absolute_imports_of_bare_top_level(path)
    assert not bad, "\n".join(bad)


def test_workbooks_name_the_add_in_module_by_its_installed_name(tmp_path):
    from cmmwb.generator.pointcloud.large_book import write_xlwings_conf
    from cmmwb.generator.workbook.book import Book

    book = Book("pointcloud", "t", "t")
    write_xlwings_conf(book)
    ws = book.wb["xlwings.conf"]
    assert [c.value for c in ws[1]] == ["UDF Modules", "cmmwb.xlfuncs.udf"]


def test_a_wheel_in_a_fresh_environment_ignores_a_hostile_generator_and_xlfuncs(tmp_path):
    """`pip wheel` of the checkout (setuptools from pip's index, as for `pip install -e .`),
    installed by pip into a new virtual environment (its dependencies: this environment's
    site-packages, after its own, through a .pth file); then the same probe and the console
    script, beside the hostile modules."""
    source = tmp_path / "source"     # a clean copy: no build/ of the checkout with stale files
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, source / name)
    for name in ("generator", "xlfuncs"):
        shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__"))
    wheels = tmp_path / "wheels"
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q",
                        "-w", str(wheels), str(source)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    (wheel,) = wheels.glob("cmmwb-*.whl")
    env_dir = tmp_path / "venv"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    python = env_dir / "bin" / "python"
    r = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
                        "--no-index", "-q", str(wheel)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                               capture_output=True, text=True, check=True).stdout.strip())
    here = next(p for p in sys.path if p.endswith("site-packages") and Path(p).is_dir())
    (site / "zz_dependencies.pth").write_text(here + "\n")     # lines of a .pth: plain path entries
    assert (site / "cmmwb" / "xlfuncs" / "locator" / "__init__.py").is_file()
    assert (site / "cmmwb" / "generator" / "lo_addin" / "cmmwb_calc.py").is_file()
    assert (site / "cmmwb" / "generator" / "examples" / "knuckle.toml").is_file()
    assert not (site / "generator").exists() and not (site / "xlfuncs").exists()
    assert sorted(p.name for p in (site / "cmmwb").iterdir()) == ["generator", "xlfuncs"]   # a namespace
    folder = _hostile_folder(tmp_path)
    clean = {"PATH": os.environ.get("PATH", ""), "HOME": str(tmp_path)}
    result = _probe(str(python), folder, env=clean)
    _only_cmmwb(result)
    assert Path(result["udf"]) == site / "cmmwb" / "xlfuncs" / "udf.py"
    r = subprocess.run([str(env_dir / "bin" / "cmmwb"), "new", "budget", "--out", "knuckle.toml"], cwd=folder,
                       capture_output=True, text=True, timeout=120, env={**clean, "PYTHONPATH": str(folder)})
    assert r.returncode == 0, r.stderr
    assert (folder / "knuckle.toml").is_file()
