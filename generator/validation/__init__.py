"""``cmmwb validate`` (docs/validate.md): the task's U against calibrated workpieces.
:mod:`.results` the results file, :mod:`.run` the validation into a folder, :mod:`.book` its
workbook, :mod:`.sets` simulated validation sets (``cmmwb simulate --validation``)."""
