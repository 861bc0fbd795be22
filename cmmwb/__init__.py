"""cmmwb: task-specific uncertainty of CMM measurements, spreadsheet first.

The distribution installs one top-level package, ``cmmwb``, and the two folders of the source
tree inside it (``pyproject.toml``, ``[tool.setuptools] package-dir``):

``cmmwb.generator``  <- ``generator/``  task files in, live .xlsx workbooks and JSON out
``cmmwb.xlfuncs``    <- ``xlfuncs/``    the numerical core (numpy only)

So neither can be confused with another ``generator`` or ``xlfuncs`` (a distribution of that
name on the package index, a user's ``generator.py`` beside a workbook, which xlwings puts on
``sys.path``).  Every import of the project is ``cmmwb.``-prefixed or relative
(``tests/test_layout.py``); the console script ``cmmwb`` and ``python -m cmmwb`` run
``cmmwb.generator.cli.main``.  This file imports nothing: the LibreOffice add-in ships it beside
``xlfuncs`` (``generator/oxt.py``).
"""
