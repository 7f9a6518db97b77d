"""Fleet mode (``bagtools batch``): one command over many bags on Dask, with a table of the results.

:func:`plan_batch` checks the arguments and reads what earlier runs finished,
:func:`run_batch` runs the rest on an embedded ``distributed.LocalCluster`` or
an existing Dask cluster (:class:`ClusterSpec`), and :func:`write_fleet`
writes ``fleet.csv``, ``fleet.parquet`` and ``fleet.png``. Each bag's job
(:data:`JOBS`) is the single command's library calls, writing
``DIR/<bag>/`` exactly as the command writes its ``--out``.
"""

from bagtools.batch.bags import find_bags, output_names
from bagtools.batch.fleet import FLEET_FILES, write_fleet
from bagtools.batch.jobs import JOBS, Column, Job, JobOutput, get_job
from bagtools.batch.plan import BatchPlan, plan_batch, row_columns
from bagtools.batch.runner import BatchRun, ClusterSpec, run_batch
from bagtools.batch.task import COMMON_COLUMNS, FAILED, MARKER, OK, SKIPPED, BagTask, run_task

__all__ = [
    "COMMON_COLUMNS", "FAILED", "FLEET_FILES", "JOBS", "MARKER", "OK", "SKIPPED", "BagTask", "BatchPlan", "BatchRun",
    "ClusterSpec", "Column", "Job", "JobOutput", "find_bags", "get_job", "output_names", "plan_batch", "row_columns",
    "run_batch", "run_task", "write_fleet",
]
