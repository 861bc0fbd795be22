"""Errors raised by the numerical core.

The core knows nothing of files; the CLI adds the file and key context and exits with status 2.
"""


class ModelError(ValueError):
    """Input that the model cannot evaluate (the message says which quantity and why)."""


class DegenerateGeometryError(ModelError):
    """Geometry for which the model or its derivative is undefined (coincident points,
    collinear plane points, parallel lines, a point on a datum ...)."""


class ConvergenceError(ModelError):
    """An iterative fit did not converge."""
