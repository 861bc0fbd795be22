"""cmmwb generator: task files in, live .xlsx workbooks and JSON results out.

Installed as ``cmmwb.generator`` (``cmmwb`` is a namespace package: no folder of its own;
``pyproject.toml`` maps ``cmmwb.generator`` to this folder).  In a checkout, ``python -m generator
...`` imports this folder as a top-level ``generator`` too; then ``generator.x`` is made the very
module ``cmmwb.generator.x`` (``xlfuncs/checkout.py``), never a second copy.
"""

__version__ = "0.1.0"

if __name__ == "generator":     # a checkout's folder, imported by its own name
    import importlib

    # the shim is the sibling xlfuncs/'s (its __init__.py runs first, then checkout.alias), not typed here again
    importlib.import_module("xlfuncs.checkout").alias(__name__)
