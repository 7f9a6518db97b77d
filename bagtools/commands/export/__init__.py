"""A topic of a bag as a table file (``bagtools export``): CSV, Parquet or NPZ, streamed message by message."""

from bagtools.commands.export.pipeline import ExportSummary, export_topic
from bagtools.commands.export.sinks import FORMATS
from bagtools.commands.export.tables import ROWS

__all__ = ["FORMATS", "ROWS", "ExportSummary", "export_topic"]
