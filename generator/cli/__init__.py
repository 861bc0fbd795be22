"""The ``cmmwb`` command line (thin: parsing, output folders, error reporting), one module per
command; :mod:`generator.cli.program` lists them (``COMMANDS``) and runs one.

Exit status: 0 success, 2 bad input (one message naming the file and line/key/sheet/cell),
1 an internal error (a bug: please report it with the task file).
"""

from ..build import build_task
from .program import COMMANDS, main, parser

#: ``build_task`` is :func:`generator.build.build_task`, named here for scripts that build a task
__all__ = ["COMMANDS", "build_task", "main", "parser"]
