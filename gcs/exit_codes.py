"""The exit codes of every ``gcs`` command: one table (docs/cli in :mod:`gcs.cli`).

====  =====================================================================================
0     success
1     a distributed run failed once started: a child process died or the run stalled
2     bad input: a bad flag or scenario, a busy port, a refused Zenoh endpoint
3     ``mission run`` of a safety filter (dcbf, rcbf) finished, but its safety verdict is
      not "safe": the truth broke (a barrier below 0, a contact, a ground strike) or an
      agent raised a safety alarm (``metrics.json`` ``safety_verdict``,
      ``safety_alarms``; docs/metrics.md). The results are written as for 0.
130   interrupted by Ctrl-C (SIGINT); every child process was stopped first
143   ``mission`` stopped by SIGTERM; every child process was stopped first
====  =====================================================================================
"""

from __future__ import annotations

EXIT_OK = 0
EXIT_RUN_FAILED = 1
EXIT_USAGE = 2
EXIT_SAFETY = 3
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143
