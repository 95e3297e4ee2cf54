"""``rozyn trial`` and the simulated trials every tool runs, for either car.

- ``spec``: :class:`TrialSpec`, a trial's conditions (the vehicle picks the car);
- ``run``: one seeded run through the estimator (:func:`run_trial`), trials in parallel;
- ``summary``: statistics over seeds (:func:`summarise`);
- ``drives``: nested drives (the estimate after each measurement time of one drive);
- ``limit``: the full car's infinite-data limit (``--limit``);
- ``report`` and ``command``: the readable report and the command line.
"""

from rozyn_estimator.tools.trial.run import TrialResult, parallel_map, parse_seeds, run_trial, run_trials
from rozyn_estimator.tools.trial.spec import TrialSpec
from rozyn_estimator.tools.trial.summary import Summary, summarise

__all__ = ["Summary", "TrialResult", "TrialSpec", "parallel_map", "parse_seeds", "run_trial", "run_trials",
           "summarise"]
