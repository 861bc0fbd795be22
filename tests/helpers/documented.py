"""The commands the documents and the ``--help`` texts show (issue 37), read from the texts themselves:

- **displayed** commands: the lines of their own in README.md, docs/*.md and
  workbook_templates/README.md (indented four spaces, or in a fenced block) that run ``cmmwb``
  (also as ``.venv/bin/cmmwb``), and the examples of every ``--help`` (``add_command``'s
  ``examples``, the main parser's epilog);
- **inline** commands: the backticked ``cmmwb ...`` spans of the same documents.

A displayed command without placeholders is *runnable*; one with placeholders (``TASK.toml``,
``DIR``, ``[--pdf]``, ``a|b``) is a *synopsis*.  Every one of them, and every inline one, names a
real command and only options that command has (:func:`parser_problems`).
"""

from __future__ import annotations

import argparse
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

from tests.helpers import ROOT

#: the documents whose commands are shown to people
DOCUMENTS = ("README.md", "docs/*.md", "workbook_templates/README.md")
#: words the documents use for "put your own here" (with or without an extension: ``TASK.toml``)
PLACEHOLDERS = {"TASK", "BOOK", "FILE", "RECORDINGS", "REC", "COPY", "KIND", "DIR", "L", "S", "P", "NAME",
                "COMMAND", "SCHEDULER", "HOST", "A", "B", "K", "T", "T0", "T1", "N", "PROFILE", "CACHE"}
_PROGRAM = re.compile(r"^(?:[A-Z_][A-Z0-9_]*=\S+\s+)*(?:\.venv/bin/)?cmmwb(?:\s|$)")


@dataclass(frozen=True)
class Shown:
    """One command as a document or a help text shows it."""

    text: str          # the cmmwb parts of the line, ``&&``-joined, ``.venv/bin/cmmwb`` as ``cmmwb``, no comment
    where: str         # ``README.md:47``, ``cmmwb build --help``
    exit_status: int = 0   # a trailing ``# exit status N`` comment says otherwise

    @property
    def segments(self) -> list[str]:
        return [s.strip() for s in self.text.split("&&")]

    @property
    def synopsis(self) -> bool:
        return is_synopsis(self.text)


def is_synopsis(text: str) -> bool:
    """A command with placeholders, optional parts or alternatives: checked, not run."""
    if any(c in text for c in "[]|<>…") or "..." in text:
        return True
    return any(word in PLACEHOLDERS for word in re.findall(r"[A-Za-z_][A-Za-z0-9_]*", text))


def _placeholder(token: str) -> bool:
    base = re.split(r"[./]", token.strip("`'\",()"), maxsplit=1)[0]
    return base in PLACEHOLDERS


def _command_part(line: str) -> tuple[str, int] | None:
    """The cmmwb segments of a shell line (and the exit status its comment states), or None."""
    code, _, comment = line.partition("  #")
    if code.lstrip().startswith("#"):
        return None
    m = re.search(r"exit status (\d+)", comment)
    segments = [s.strip() for s in code.split("&&")]
    mine = [re.sub(r"^((?:[A-Z_][A-Z0-9_]*=\S+\s+)*)\.venv/bin/cmmwb", r"\1cmmwb", s)
            for s in segments if _PROGRAM.match(s)]
    if not mine:
        return None
    return " && ".join(mine), int(m.group(1)) if m else 0


def documents() -> list[Path]:
    return sorted({p for pattern in DOCUMENTS for p in ROOT.glob(pattern) if p.is_file()})


def displayed_in(path: Path) -> list[Shown]:
    """The displayed commands of one document: indented (4 spaces) lines and fenced blocks.  The
    cmmwb lines of one block are one chain, run in order in one folder (``new``, then ``build``,
    then ``read`` of what it built); a synopsis continued on further indented lines is joined."""
    lines = path.read_text(encoding="utf-8").splitlines()
    out: list[Shown] = []
    block: list[tuple[str, int, int]] = []     # (command, exit status, line) of the current block

    def close() -> None:
        if block:
            out.append(Shown(" && ".join(c for c, _, _ in block), f"{path.relative_to(ROOT)}:{block[0][2]}",
                             max(s for _, s, _ in block)))
            block.clear()

    fenced = False
    k = 0
    while k < len(lines):
        line = lines[k]
        if line.lstrip().startswith("```"):
            close()
            fenced = not fenced
        elif fenced or line.startswith("    "):
            part = _command_part(line.strip())
            if part is not None:
                text, status = part
                first = k + 1
                indent = len(line) - len(line.lstrip())
                while k + 1 < len(lines) and lines[k + 1].strip().startswith("[") and \
                        len(lines[k + 1]) - len(lines[k + 1].lstrip()) > indent:
                    k += 1
                    text += " " + lines[k].strip()
                block.append((text, status, first))
        elif line.strip():
            close()
        k += 1
    close()
    return out


def inline_in(path: Path) -> list[Shown]:
    """The backticked ``cmmwb ...`` spans of one document (a span may wrap onto the next line); not
    the fenced blocks (:func:`displayed_in` reads those), nor a line the program prints (``cmmwb
    recalc: engine gnumeric ...``: a command word followed by a colon)."""
    text = re.sub(r"^```.*?^```", lambda m: "\n" * m.group(0).count("\n"),
                  path.read_text(encoding="utf-8"), flags=re.S | re.M)
    out = []
    for m in re.finditer(r"`([^`]+)`", text):
        span = " ".join(m.group(1).split())
        if _PROGRAM.match(span) and not re.match(r"^\S*cmmwb(?: [a-z][\w-]*)*:", span):
            line = text.count("\n", 0, m.start()) + 1
            out.append(Shown(re.sub(r"^\.venv/bin/cmmwb", "cmmwb", span), f"{path.relative_to(ROOT)}:{line}"))
    return out


def parsers() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """Every parser of the command line by its command path: ``()`` the program, ``("build",)``,
    ``("addin", "relink")``."""
    from cmmwb.generator.cli.program import parser

    out: dict[tuple[str, ...], argparse.ArgumentParser] = {}

    def walk(p: argparse.ArgumentParser, path: tuple[str, ...]) -> None:
        out[path] = p
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, path + (name,))

    walk(parser(), ())
    return out


def help_examples() -> list[Shown]:
    """The examples of every ``--help`` (the lines under ``examples:`` of each epilog)."""
    out = []
    for path, p in parsers().items():
        epilog = p.epilog or ""
        if "examples:" not in epilog:
            continue
        for line in epilog.split("examples:", 1)[1].splitlines():
            if not line.startswith("  "):
                if line.strip():
                    break
                continue
            part = _command_part(line.strip())
            if part is not None:
                out.append(Shown(part[0], " ".join(("cmmwb",) + path + ("--help",)), part[1]))
    return out


def parser_problems(shown: Shown) -> list[str]:
    """What in a shown command the command line does not have: an unknown command, an option the
    command lacks, a literal value outside an option's choices."""
    all_parsers = parsers()
    problems = []
    for segment in shown.segments:
        segment = segment.split(" | ", 1)[0]     # what cmmwb's output is piped into is not cmmwb's
        try:
            tokens = shlex.split(segment, comments=True)
        except ValueError as e:
            problems.append(f"{segment!r}: {e}")
            continue
        while tokens and re.match(r"^[A-Z_][A-Z0-9_]*=", tokens[0]):
            tokens = tokens[1:]              # an environment variable set for the command
        assert tokens and tokens[0] == "cmmwb", segment
        path: tuple[str, ...] = ()
        rest = tokens[1:]
        while rest and path + (rest[0],) in all_parsers:
            path += (rest[0],)
            rest = rest[1:]
        p = all_parsers[path]
        options = {s: a for a in p._actions for s in a.option_strings}
        positionals = [a for a in p._actions if not a.option_strings and a.choices
                       and not isinstance(a, argparse._SubParsersAction)]
        if any(isinstance(a, argparse._SubParsersAction) for a in p._actions) and rest and \
                not rest[0].startswith("-") and not _placeholder(rest[0]):
            problems.append(f"{segment!r}: no command {' '.join(('cmmwb',) + path + (rest[0],))!r}")
            continue
        for k, token in enumerate(rest):
            bare = token.strip("[]")
            if bare.startswith("-") and bare not in ("-", "--"):
                name, _, value = bare.partition("=")
                action = options.get(name)
                if action is None:
                    problems.append(f"{segment!r}: 'cmmwb {' '.join(path)}' has no option {name}")
                    continue
                if action.choices and action.nargs != 0:
                    value = value or (rest[k + 1].strip("[]") if k + 1 < len(rest) else "")
                    for choice in value.split("|"):
                        if choice and not _placeholder(choice) and choice not in action.choices:
                            problems.append(f"{segment!r}: {name} has no choice {choice!r} "
                                            f"(choices: {', '.join(map(str, action.choices))})")
            elif positionals and k == 0 and not _placeholder(bare):
                for choice in bare.split("|"):
                    if choice not in positionals[0].choices:
                        problems.append(f"{segment!r}: {choice!r} is not one of "
                                        f"{', '.join(positionals[0].choices)}")
    return problems


def out_targets(shown: Shown) -> set[str]:
    """The first path component of every ``--out`` of a command (what it writes)."""
    out = set()
    for segment in shown.segments:
        tokens = shlex.split(segment, comments=True)
        for k, token in enumerate(tokens):
            if token == "--out" and k + 1 < len(tokens):
                out.add(tokens[k + 1].split("/", 1)[0])
            elif token.startswith("--out="):
                out.add(token[6:].split("/", 1)[0])
    return out
