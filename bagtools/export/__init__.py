"""A topic of a bag as a table file (``bagtools export``): CSV, Parquet or NPZ, streamed message by message."""

from bagtools.export.pipeline import ExportSummary, export_topic
from bagtools.export.sinks import FORMATS
from bagtools.export.tables import ROWS

__all__ = ["FORMATS", "ROWS", "ExportSummary", "export_topic"]
