"""The task-kind contract: what the job module of a kind (``generator/<kind>/job.py``) provides, so
that ``build``, ``new``, ``read``, ``demo`` and the templates handle every kind alike.  The
registry of the kinds is :data:`generator.jobs.JOBS`; ``tests/layout/test_jobs.py`` checks that every
registered module satisfies :class:`TaskKind`.

The hooks only some kinds need (:meth:`TaskKind.force_exact`, :meth:`TaskKind.add_type_a`) are part
of the contract too: a kind without a use for one binds the default given here, so that the
caller never asks whether a kind has it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Protocol, Sequence, runtime_checkable

from .workbook.book import BookAdditions


@runtime_checkable
class TaskKind(Protocol):
    """A task kind's job module."""

    #: the kind's worked examples (file names in ``generator/examples/``), built by ``cmmwb demo``
    EXAMPLES: Sequence[str]
    #: the commented task file ``cmmwb new KIND`` writes; it builds as it is
    NEW_TASK: str
    #: the tables that task names (file name -> text), written beside it as ``<stem>_<name>``
    NEW_TASK_FILES: Mapping[str, str]

    def load(self, path: Path, doc: dict) -> Any:
        """The task of the TOML document ``doc`` read from ``path``, validated (every problem an
        ``InputError`` naming the file and key)."""

    def compute(self, task: Any) -> dict:
        """The results (the JSON of docs/cli.md) computed by the Python core."""

    def write_book(self, task: Any, results: dict, path: Path, additions: BookAdditions | None = None) -> None:
        """The workbook to ``path`` (``additions``: what the build adds to it, see
        :class:`generator.workbook.book.BookAdditions`)."""

    def write_plots(self, task: Any, results: dict, out_dir: Path) -> list[Path]:
        """The PNG plots into ``out_dir``; their paths."""

    def summary(self, results: dict) -> list[str]:
        """The headline results, a few lines for the terminal."""

    def force_exact(self, task: Any) -> None:
        """``cmmwb build --exact``: no approximation whatever the task says (default
        :func:`always_exact`)."""

    def add_type_a(self, results: dict) -> None:
        """After the decisions of a ``[decision]`` table: the type A inputs they carry into the
        kind's results (default :func:`no_type_a`)."""


def always_exact(task: Any) -> None:
    """The default ``force_exact``: the kind computes exactly at every size, nothing to switch."""


def no_type_a(results: dict) -> None:
    """The default ``add_type_a``: the kind's results show no type A inputs."""
