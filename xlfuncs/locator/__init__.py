"""The mismatch locator, one package (docs/recordings.md sections 2-7, docs/diagnose.md).  The entry
point is :mod:`.diagnose` (``diagnose``, ``diagnose_prepared``), which puts the parts together:

* :mod:`.recordings` the recordings (length and point records, recordings.md section 1);
* :mod:`.effects`  the candidate effects' sensitivities (recordings.md section 3);
* :mod:`.simulate` the simulator behind ``cmmwb simulate`` (layouts, planted effects);
* :mod:`.structured`, :mod:`.structured_lengths` the record covariance of large point and length
  recordings as D + U U^T (never n x n);
* :mod:`.model`  the records' linear model: probes, alignment, the record covariance C, groups;
* :mod:`.linalg` whitening, orthogonal projections, generalized least squares;
* :mod:`.search` the candidates, the likelihood-ratio tests and the forward search (effects and
  outliers), the refit;
* :mod:`.report` the answer: ``Diagnosis``, groups and records located, diagnosis.json, summary;
* :mod:`.discrepancy` the last candidate (recordings.md section 7).

The chi-square and F tails in logarithms are :mod:`xlfuncs.distributions` (shared with the GUM
modules).  Layers: recordings, effects -> structured -> structured_lengths -> model -> linalg -> search
-> report -> discrepancy -> diagnose (no module imports one to its right; simulate uses only
recordings).
"""
