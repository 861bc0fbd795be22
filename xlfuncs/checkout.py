"""One copy of each module when a checkout imports ``generator`` or ``xlfuncs`` by its folder name.

The installation has no top-level ``generator`` or ``xlfuncs``: ``cmmwb`` is a namespace package
(no folder of its own) holding ``cmmwb.generator`` <- ``generator/`` and ``cmmwb.xlfuncs`` <-
``xlfuncs/`` (``pyproject.toml``, ``package-dir``).  In a source checkout (the working directory
on ``sys.path``), ``python -m generator`` and ``python -m generator.templates --check`` find the
folder ``generator/`` as a top-level package too.  Its modules import one another relatively and
the core as ``cmmwb.xlfuncs``, and the job modules are imported as ``cmmwb.generator.*``: without
this shim the same file would run twice, as ``generator.x`` and as ``cmmwb.generator.x``, with two
``InputError`` classes and two copies of every module-level state.  :func:`alias` makes
``generator`` and every ``generator.x`` the very module object ``cmmwb.generator[.x]`` (and the
same for ``xlfuncs``).  Installed packages never run it.  Standard library only.

The shim's one home is here.  ``xlfuncs/__init__.py``, imported as ``xlfuncs``, takes
:func:`alias` from this file relatively (``from .checkout import alias``: the checkout's own
file, so that a Python without cmmwb installed gets the message to install it rather than
"No module named 'cmmwb'"), and ``generator/__init__.py``, imported as ``generator``, runs its
sibling folder's ``xlfuncs/__init__.py`` by location (not whatever ``xlfuncs`` sys.path finds
first), then calls the same function for ``generator``.  The copy of this file loaded as
``xlfuncs.checkout`` before the alias existed is dropped from ``sys.modules`` by :func:`alias`,
so that ``xlfuncs.checkout`` too is ``cmmwb.xlfuncs.checkout``.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys


class _AliasLoader(importlib.abc.Loader):
    """Loads ``<short>.x`` as the module ``cmmwb.<short>.x`` (imported once, under its real name)."""

    def __init__(self, real: str):
        self.real = real

    def create_module(self, spec):
        module = importlib.import_module(self.real)
        self.real_spec = module.__spec__    # the import system sets __spec__ to the alias's next
        return module

    def exec_module(self, module):
        module.__spec__ = self.real_spec    # already executed under its real name: keep that

    def get_code(self, fullname):
        """For ``python -m generator.x``: runpy runs the real module's code as ``__main__``."""
        return importlib.util.find_spec(self.real).loader.get_code(self.real)

    def is_package(self, fullname):
        return importlib.util.find_spec(self.real).submodule_search_locations is not None


class _AliasFinder(importlib.abc.MetaPathFinder):
    def __init__(self, short: str):
        self.short = short      # compared by value: each copy of this file has its own class

    def find_spec(self, fullname, path=None, target=None):
        if not fullname.startswith(self.short + "."):
            return None
        real = "cmmwb." + fullname
        found = importlib.util.find_spec(real)
        if found is None:
            return None
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader(real), origin=found.origin,
                                              is_package=found.submodule_search_locations is not None)


def alias(short: str) -> None:
    """Make the top-level package ``short`` (being imported from a checkout) ``cmmwb.<short>``."""
    try:
        real = importlib.import_module("cmmwb." + short)
    except ModuleNotFoundError as e:
        if e.name not in ("cmmwb", "cmmwb." + short):
            raise
        raise ModuleNotFoundError("this checkout's generator/ and xlfuncs/ are installed as cmmwb.generator and "
                                  "cmmwb.xlfuncs, and cmmwb is not installed in this Python: run "
                                  "`python -m pip install -e .` in the checkout", name=e.name) from None
    if not any(type(f).__name__ == "_AliasFinder" and f.short == short for f in sys.meta_path):
        sys.meta_path.insert(0, _AliasFinder(short))
    sys.modules[short] = real
    for name in [n for n in sys.modules if n.startswith(short + ".")]:
        if not getattr(sys.modules[name], "__name__", "").startswith("cmmwb."):    # loaded before the alias
            del sys.modules[name]
