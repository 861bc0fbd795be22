"""Errors raised by the numerical core.

The core knows nothing of files; the CLI adds the file and key context and exits with status 2.
"""


class ModelError(ValueError):
    """Input that the model cannot evaluate (the message says which quantity and why).

    ``item``: which entry of a list the core was given the error belongs to, as (list name,
    0-based index), e.g. ``("characteristics", 2)``, or None; the generator turns it into the
    place in the user's file (``[[characteristics]] #3``)."""

    item: tuple[str, int] | None = None


def about(err: ModelError, kind: str, index: int, prefix: str | None = None) -> ModelError:
    """``err`` marked as belonging to entry ``index`` of the list ``kind`` (a new error of its type
    when ``prefix`` is given: ``"PREFIX: message"``); an error already marked is returned as it is
    (it names its own entry)."""
    if err.item is not None:
        return err
    out = type(err)(f"{prefix}: {err}") if prefix is not None and not str(err).startswith(f"{prefix}:") else err
    out.item = (kind, index)
    return out


class DegenerateGeometryError(ModelError):
    """Geometry for which the model or its derivative is undefined (coincident points,
    collinear plane points, parallel lines, a point on a datum ...)."""


class ConvergenceError(ModelError):
    """An iterative fit did not converge."""
