"""cmmwb generator: task files in, live .xlsx workbooks and JSON results out.

Installed as ``cmmwb.generator`` (``cmmwb`` is a namespace package: no folder of its own;
``pyproject.toml`` maps ``cmmwb.generator`` to this folder).  In a checkout, ``python -m generator
...`` imports this folder as a top-level ``generator`` too; then ``generator.x`` is made the very
module ``cmmwb.generator.x`` (``xlfuncs/checkout.py``), never a second copy.
"""

__version__ = "0.1.0"

if __name__ == "generator":     # a checkout's folder, imported by its own name
    try:
        from cmmwb.xlfuncs.checkout import alias
    except ModuleNotFoundError as e:    # no cmmwb in this Python: the checkout is not installed
        if e.name != "cmmwb":
            raise
        raise ModuleNotFoundError(f"{__name__} is installed as cmmwb.{__name__}, and cmmwb is not installed in "
                                  "this Python: run `python -m pip install -e .` in the checkout",
                                  name=e.name) from None

    alias(__name__)
