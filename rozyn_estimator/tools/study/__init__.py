"""``rozyn study``: the thesis' Monte-Carlo grids (chapter 5); the package's public surface.

Modules, by concern (each imports its siblings directly, never this package; the two cars,
``--model``, are :mod:`rozyn_estimator.tools.cars`'):

- :mod:`~rozyn_estimator.tools.study.settings`: the grid, :class:`StudySettings`, the grid
  options' syntax and the names of the files a study writes;
- :mod:`~rozyn_estimator.tools.study.results`: trial rows and ``results.csv``;
- :mod:`~rozyn_estimator.tools.study.directory`: the output directory and ``study.json``;
- :mod:`~rozyn_estimator.tools.study.work`: chunks of trials on local processes or Dask;
- :mod:`~rozyn_estimator.tools.study.summary`: per-cell statistics (spread, bias, the
  published std's coverage) and their tables;
- :mod:`~rozyn_estimator.tools.study.precision`: the shortest drive for 1 % (2σ);
- :mod:`~rozyn_estimator.tools.study.correlations`: the correlation figures' data;
- :mod:`~rozyn_estimator.tools.study.outputs`: tables and figures from the results;
- :mod:`~rozyn_estimator.tools.study.plots`: the figures (matplotlib; not imported here);
- :mod:`~rozyn_estimator.tools.study.command`: the command line (``HELP``, ``DESCRIPTION``,
  ``add_arguments``, ``run``).
"""

from rozyn_estimator.tools.study.command import DESCRIPTION, HELP, add_arguments, run
from rozyn_estimator.tools.study.directory import load_manifest
from rozyn_estimator.tools.study.precision import ShortestDrive, shortest_drives
from rozyn_estimator.tools.study.results import TrialRow, read_results
from rozyn_estimator.tools.study.settings import (
    FIGURES,
    MANIFEST,
    RESULTS,
    SUMMARY_CSV,
    SUMMARY_MD,
    Cell,
    StudySettings,
    parse_grid,
)
from rozyn_estimator.tools.study.summary import CellSummary, summarise_cells
from rozyn_estimator.tools.study.work import bench_trials_per_second, plan_chunks, run_chunk

__all__ = [
    "DESCRIPTION",
    "FIGURES",
    "HELP",
    "MANIFEST",
    "RESULTS",
    "SUMMARY_CSV",
    "SUMMARY_MD",
    "Cell",
    "CellSummary",
    "ShortestDrive",
    "StudySettings",
    "TrialRow",
    "add_arguments",
    "bench_trials_per_second",
    "load_manifest",
    "parse_grid",
    "plan_chunks",
    "read_results",
    "run",
    "run_chunk",
    "shortest_drives",
    "summarise_cells",
]
