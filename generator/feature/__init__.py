"""The ``feature`` task kind (Forbes 2022 under the V_X of Forbes 2025): the task data, the job,
the workbook (built on the point-cloud sheets) and the way back from a workbook (``reader``)."""
