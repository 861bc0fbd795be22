"""What the command modules of :mod:`generator.cli` share: a subcommand with its description and
examples (:func:`add_command`); the modules import this one, never :mod:`generator.cli.program`.
"""

from __future__ import annotations

import argparse
import textwrap


def examples_epilog(*lines: str) -> str:
    return "examples:\n" + "\n".join(f"  {line}" for line in lines)


def add_command(sub, name: str, help: str, description: str, examples: tuple[str, ...]):
    """A subcommand whose --help shows its description and a few examples verbatim."""
    return sub.add_parser(name, help=help, description=textwrap.fill(description, 79),
                          epilog=examples_epilog(*examples),
                          formatter_class=argparse.RawDescriptionHelpFormatter)
