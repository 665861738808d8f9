"""``gcs mission run --fault-*`` (docs/faults.md): transport faults from the command line.

The flags set :class:`swarm_common.faults.FaultConfig` values on the links that
``--fault-link`` names (default both), over the scenario's own ``[faults]`` (per-agent
tables included). The run's scenario, with those values, is written to
``<run dir>/scenario.toml``; the runner and every process it starts load that file, so each
applies the same seeded plan.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable
from pathlib import Path

from swarm_common.enums import FaultLinkChoice
from swarm_common.scenario.model import Scenario

log = logging.getLogger(__name__)

# --fault-* flag (argparse dest) -> swarm_common.faults.FaultConfig field
FAULT_FLAGS = {
    "fault_drop": "drop", "fault_drop_in": "drop_in", "fault_delay_ms": "delay_ms",
    "fault_jitter_ms": "jitter_ms", "fault_duplicate": "duplicate", "fault_reorder": "reorder",
}
FAULT_LINK_CHOICES = tuple(c.value for c in FaultLinkChoice)


def _fault_value(key: str) -> Callable[[str], float]:
    def parse(text: str) -> float:
        from swarm_common.faults import FaultError, check_fault_value

        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        try:
            return check_fault_value(repr(text), key, v)
        except FaultError as exc:  # "'1.5' = 1.5: must be ..." -> "'1.5': must be ..."
            raise argparse.ArgumentTypeError(f"{text!r}: {str(exc).split(': ', 1)[1]}") from None

    return parse


def add_fault_flags(d: argparse._ArgumentGroup) -> None:
    """``--fault-*`` (docs/faults.md): set these [faults] values on the chosen links."""
    for dest, key in FAULT_FLAGS.items():
        unit = "MS" if key.endswith("_ms") else "P"
        d.add_argument("--" + dest.replace("_", "-"), type=_fault_value(key), default=None,
                       metavar=unit, help=f"[faults] {key} on --fault-link (docs/faults.md)")
    d.add_argument("--fault-link", choices=FAULT_LINK_CHOICES, default=None,
                   help="the transport(s) the --fault-* values apply to (default both)")


def write_fault_scenario(args: argparse.Namespace, sc: Scenario) -> Path | None:
    """Write ``sc`` with the ``--fault-*`` values set on ``--fault-link``'s links to
    ``<out>/scenario.toml`` and return that path (the run is then loaded from it, and every
    process of the run reads that file, so all apply the same plan); ``args.out`` is set
    to the run directory. None without ``--fault-*`` flags; :class:`ValueError` (one line)
    for flags that do not go together or a file that cannot be written."""
    from swarm_common.faults import LINKS
    from swarm_common.scenario.model import dump_toml

    values = {key: getattr(args, dest) for dest, key in FAULT_FLAGS.items()
              if getattr(args, dest) is not None}
    problem = None
    if not values and args.fault_link is not None:
        problem = "--fault-link needs a --fault-* value"
    elif values and args.inproc:
        problem = "--fault-* flags need a distributed run (the in-process run has no links)"
    if problem:
        raise ValueError(problem)
    if not values:
        return None
    from gcs.mission.distributed import default_out_dir

    links = LINKS if args.fault_link in (None, FaultLinkChoice.BOTH) else (args.fault_link,)
    doc = sc.to_toml_dict()
    doc["faults"] = sc.faults.with_link_values(links, values).as_toml()
    out = Path(args.out) if args.out else default_out_dir(sc, str(args.method or
                                                                 sc.controller.method))
    path = out / "scenario.toml"
    try:
        out.mkdir(parents=True, exist_ok=True)
        path.write_text(dump_toml(doc))
    except OSError as exc:
        raise ValueError(f"cannot write {path}: {exc.strerror}") from None
    args.out = str(out)
    log.info("faults %s: scenario written to %s", doc["faults"], path)
    return path
