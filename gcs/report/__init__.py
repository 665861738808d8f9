"""What a run measured and the reports written from it.

* :class:`gcs.report.metrics.Series` and :func:`gcs.report.metrics.compute_metrics` - mission
  metrics from a run's time series.
* :mod:`gcs.report.safety_metrics` - offline safety metrics from ground truth.
* :func:`gcs.report.comparison.write_report` - the methods side by side, with the paper's
  Table 3 (plots in :mod:`.plots`).
* :mod:`gcs.report.sweep` - a sweep's ``runs.csv``, ``summary.md`` and ``summary.png``.
"""
