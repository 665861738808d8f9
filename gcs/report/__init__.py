"""What a run measured and the reports written from it.

* :class:`gcs.report.metrics.Series` and :func:`gcs.report.metrics.compute_metrics` - mission
  metrics from a run's time series.
* :mod:`gcs.report.safety_metrics` - offline safety metrics from ground truth.
* :mod:`gcs.report.verdict` - a run's safety verdict: every broken assumption as a timed event,
  one word for the run, and `gcs mission run`'s exit status.
* :mod:`gcs.report.safety_table` - the comparison report's safety and tracking table.
* :func:`gcs.report.comparison.write_report` - the methods side by side, with the paper's
  Table 3 (plots in :mod:`.plots`).
* :mod:`gcs.report.sweep` - a sweep's ``runs.csv``, ``summary.md`` and ``summary.png``.
"""
