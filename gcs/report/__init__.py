"""What a run measured and the reports written from it.

* :class:`gcs.report.metrics.Series` and :func:`gcs.report.metrics.compute_metrics` - mission
  metrics from a run's time series.
* :mod:`gcs.report.safety_metrics` - offline safety metrics from ground truth.
* :mod:`gcs.report.pair_barriers` - the true barrier of every pair and step, summarised
  (least value, counts, onsets below 0) in one compiled pass without the whole array.
* :mod:`gcs.report.verdict` - a run's safety verdict: every broken assumption as a timed event,
  one word for the run, and `gcs mission run`'s exit status.
* :mod:`gcs.report.safety_table` - the comparison report's safety and tracking table.
* :func:`gcs.report.comparison.write_report` - the methods side by side, with the paper's
  Table 3 (plots in :mod:`.plots`).
* :mod:`gcs.report.figures` - the report's figures, each captioned with its time window and
  where to see it in the run's record.
* :mod:`gcs.report.paths` - every vehicle's flown path from above and from the side, with
  the obstacles, the geofence and the closest approach.
* :mod:`gcs.report.animation` - a GIF of the swarm around the closest approach (matplotlib's
  Pillow writer, where it is installed).
* :mod:`gcs.report.sweep` - a sweep's ``runs.csv``, ``summary.md`` and ``summary.png``.
"""
