"""The task kinds and their job modules (the contract: :class:`generator.taskkind.TaskKind`)."""

from __future__ import annotations

from .budget import job as budget
from .characteristic import job as characteristic
from .feature import job as feature
from .pointcloud import job as pointcloud
from .taskkind import TaskKind

#: kind name (``[task] kind``) -> its job module, in the order ``cmmwb demo`` builds them
JOBS: dict[str, TaskKind] = {
    "pointcloud": pointcloud,
    "budget": budget,
    "feature": feature,
    "characteristic": characteristic,
}


def job(kind: str) -> TaskKind:
    """The job module of a task kind."""
    return JOBS[kind]
