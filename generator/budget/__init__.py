"""The ``budget`` task kind (Wojtyła, Płowucha et al. 2023): the task data, the job, the workbook
and the way back from a workbook (``reader``)."""
