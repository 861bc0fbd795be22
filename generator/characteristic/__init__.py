"""The ``characteristic`` task kind: characteristics of a drawing (size, distance, angle, form,
orientation, position at MMC/LMC) from least-squares features fitted in one task, under the
V_X of Forbes 2025 (xlfuncs.characteristics): the job and the workbook."""
