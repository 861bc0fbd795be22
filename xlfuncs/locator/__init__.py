"""The mismatch locator's parts (docs/recordings.md sections 2-7, docs/diagnose.md).  The entry
point is :mod:`xlfuncs.diagnose` (``diagnose``, ``diagnose_prepared``), which puts them together:

* :mod:`.stats`  chi-square and F tails in logarithms;
* :mod:`.model`  the records' linear model: probes, alignment, the record covariance C, groups;
* :mod:`.linalg` whitening, orthogonal projections, generalized least squares;
* :mod:`.search` the candidates, the likelihood-ratio tests and the forward search (effects and
  outliers), the refit;
* :mod:`.report` the answer: ``Diagnosis``, groups and records located, diagnosis.json, summary.

Layers: stats, model -> linalg -> search -> report -> xlfuncs.diagnose (no module imports one
to its right).
"""
