"""The task-kind contract: what the job module of a kind (``generator/<kind>/job.py``) provides, so
that ``build``, ``new``, ``read``, ``demo`` and the templates handle every kind alike.  The
registry of the kinds is :data:`generator.jobs.JOBS`; ``tests/layout/test_jobs.py`` checks that every
registered module satisfies :class:`TaskKind`.

What the code every kind shares needs of a kind's results it takes from the kind's records
(:meth:`TaskKind.quantities`, :class:`generator.quantities.Quantity`: label, value, u, U, the
value's source, the cells that hold them) and from :attr:`TaskKind.TOLERANCE_KEYS` (how a
``[[decision.tolerances]]`` entry names a result), never by asking which kind it is.

The hooks only some kinds need (:meth:`TaskKind.force_exact`, :meth:`TaskKind.add_type_a`,
:meth:`TaskKind.verdicts`) are part of the contract too: a kind without a use for one binds the default given here, so that the
caller never asks whether a kind has it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Protocol, Sequence, runtime_checkable

from .quantities import Quantity, ToleranceKeys, Verdict
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
    #: how ``[[decision.tolerances]]`` name the kind's results (none: its own tolerances)
    TOLERANCE_KEYS: ToleranceKeys

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

    def quantities(self, task: Any, results: dict, k: float = 2.0) -> list[Quantity]:
        """One record per result a person reads and a tolerance may name
        (:class:`generator.quantities.Quantity`), in the order of the results, with the cells of
        the kind's workbook that hold it.  ``k``: the coverage factor of results that give u only
        (the ``[decision] k``)."""

    def verdicts(self, task: Any, results: dict) -> list[Verdict]:
        """Verdicts besides the decisions of the characteristics (the MPE check of a point cloud;
        default :func:`no_verdicts`)."""

    def read_book(self, cells: Any, rt: Any, points_file: str) -> None:
        """``cmmwb read``: the kind's inputs of a workbook (``cells``, a
        :class:`generator.workbook.readback.Cells`) into the task ``rt``
        (:class:`generator.workbook.readback.ReadTask`); ``points_file`` names its points table."""

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


def no_verdicts(task: Any, results: dict) -> list[Verdict]:
    """The default ``verdicts``: none besides the decisions."""
    return []
