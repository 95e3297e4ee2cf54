"""``rozyn compare``: methods side by side on the same seeded runs, for either car.

- ``suites``: the named cases and their bars (:func:`suite`);
- ``compare``: the runs, their statistics, tables and JSON records (:func:`compare`);
- ``command``: the command line.
"""

from rozyn_estimator.tools.compare.compare import bar_failures, case_record, compare, format_case
from rozyn_estimator.tools.compare.suites import SUITES, Bars, Case, suite

__all__ = ["SUITES", "Bars", "Case", "bar_failures", "case_record", "compare", "format_case", "suite"]
