"""cmmwb generator: task files in, live .xlsx workbooks and JSON results out.

Installed as ``cmmwb.generator`` (``cmmwb`` is a namespace package: no folder of its own;
``pyproject.toml`` maps ``cmmwb.generator`` to this folder).  In a checkout, ``python -m generator
...`` imports this folder as a top-level ``generator`` too; then ``generator.x`` is made the very
module ``cmmwb.generator.x`` (``xlfuncs/checkout.py``), never a second copy.
"""

__version__ = "0.1.0"

if __name__ == "generator":     # a checkout's folder, imported by its own name
    import importlib
    import importlib.util
    import os
    import sys

    # The shim is the sibling folder xlfuncs/'s (xlfuncs/checkout.py), not typed here again: its
    # __init__.py, run from beside this folder (whatever else on sys.path is called xlfuncs), makes
    # xlfuncs cmmwb.xlfuncs or says that cmmwb is not installed; then the same for generator.
    spec = importlib.util.spec_from_file_location("xlfuncs", os.path.join(os.path.dirname(__path__[0]), "xlfuncs",
                                                                          "__init__.py"))
    sys.modules["xlfuncs"] = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(sys.modules["xlfuncs"])
    except BaseException:
        del sys.modules["xlfuncs"]      # as the import system does with a module that failed
        raise
    importlib.import_module("cmmwb.xlfuncs.checkout").alias(__name__)
