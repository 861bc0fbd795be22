"""cmmwb generator: task files in, live .xlsx workbooks and JSON results out."""

__version__ = "0.1.0"
