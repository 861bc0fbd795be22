"""The ``pointcloud`` task kind (Forbes 2025): the job (task file, computation, outputs), the
V_X sheets shared with the feature workbook, the large workbook beyond the native size and the way
back from a workbook (``reader``)."""
