"""``python -m offboard``: the daemon (:func:`offboard.cli.main`), after taking a start-up
slot when the runner names a gate in ``$OFFBOARD_START_GATE`` (:mod:`offboard.daemon.start_gate`),
before the heavy imports. ``gcs mission run`` and ``gcs dashboard --launch`` start their
daemons this way."""

from __future__ import annotations

import os
import sys

from offboard.daemon import start_gate
from swarm_common.process_life import exit_now


def gated_main() -> int:
    """Take a slot (or none, without the variable), then run the daemon; 2 and one line
    on stderr when the variable is malformed or its directory unusable."""
    try:
        start_gate.acquire(os.environ.get(start_gate.GATE_ENV))
    except (ValueError, OSError) as exc:
        print(f"offboard: ${start_gate.GATE_ENV}: {exc}", file=sys.stderr)
        return 2
    from offboard.cli import main  # the heavy imports, inside the slot

    return main()


if __name__ == "__main__":
    exit_now(gated_main())  # no interpreter teardown (swarm_common.process_life)
