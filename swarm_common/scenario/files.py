"""Scenario files on disk: the errors, the swarm-name rule, guarded reading, TOML writing.

:func:`read_scenario_text` refuses what could hang or crash the TOML parser (a FIFO or
device, more than :data:`MAX_SCENARIO_BYTES`, non-UTF-8 bytes, brackets nested deeper than
:data:`MAX_TOML_NESTING`) with one :class:`ScenarioError` line. :func:`dump_toml` writes a
scenario document back (``Scenario.to_toml_dict``), e.g. a run's scenario with its
command-line fault overrides (docs/faults.md).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from swarm_common.inputs import (
    MAX_SCENARIO_BYTES,
    BoundedReadError,
    one_line,
    read_bounded_text,
)

ALLOW_INFEASIBLE_FLAG = "--allow-infeasible"
ALLOW_UNSAFE_FLAG = "--allow-unsafe"


def run_anyway_hint(flag: str) -> str:
    """The end of a refusal that ``flag`` (:data:`ALLOW_UNSAFE_FLAG`,
    :data:`ALLOW_INFEASIBLE_FLAG`) would lift in a run: "; pass FLAG to run it anyway"."""
    return f"; pass {flag} to run it anyway"


class ScenarioError(ValueError):
    """A scenario file is missing, unreadable or invalid. ``str()`` is one line: a newline
    or another unprintable character in a file name or a key is written as its escape
    (:func:`swarm_common.inputs.one_line`)."""

    def __init__(self, message: str) -> None:
        super().__init__(one_line(message))


class InfeasibleScenarioError(ScenarioError):
    """A valid scenario that the vehicles cannot fly (:mod:`swarm_common.scenario.feasibility`);
    ``--allow-infeasible`` turns it into a warning."""


class UnsafeScenarioError(ScenarioError):
    """A scenario that breaks a load-time safety assumption
    (:mod:`swarm_common.scenario.safety_check`); ``--allow-unsafe`` turns it into warnings."""


# The scenario name is the swarm name in every Zenoh key (``swarm/<name>/...``) and part of
# the default run directory: no wildcard (``*``, ``$*``), separator (``/``), ``..``, ``?``
# or ``#`` may reach a key expression or a path.
SWARM_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$")
SWARM_NAME_RULE = "1-64 characters of A-Z a-z 0-9 _ -, starting with a letter or digit"
MAX_TOML_NESTING = 32  # arrays/tables deeper than this are refused before tomllib sees them


def swarm_name_problem(name: object) -> str | None:
    """None if ``name`` is a valid swarm/scenario name, else what is wrong (one phrase)."""
    if not isinstance(name, str) or not SWARM_NAME_RE.fullmatch(name):
        return f"must be {SWARM_NAME_RULE}"
    return None


def _nesting_problem(text: str) -> str | None:
    """Bracket depth outside strings and comments, counted before parsing: ``tomllib`` is
    recursive and a file nested thousands deep would raise ``RecursionError``."""
    depth = 0
    quote = ""
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if quote:
            if c == "\\" and quote in ('"', '"""'):
                i += 2
                continue
            if text.startswith(quote, i):
                i += len(quote)
                quote = ""
                continue
        elif c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        elif c in "\"'":
            quote = c * 3 if text.startswith(c * 3, i) else c
            i += len(quote)
            continue
        elif c in "[{":
            depth += 1
            if depth > MAX_TOML_NESTING:
                return f"arrays or tables nested deeper than {MAX_TOML_NESTING}"
        elif c in "]}":
            depth = max(0, depth - 1)
        i += 1
    return None


def read_scenario_text(p: Path) -> str:
    """The file's text: a regular file (not a FIFO, device or directory) of at most
    :data:`MAX_SCENARIO_BYTES`, UTF-8 (:func:`swarm_common.inputs.read_bounded_text`),
    nested at most :data:`MAX_TOML_NESTING` deep."""
    try:
        text = read_bounded_text(p, MAX_SCENARIO_BYTES, "scenario file")
    except BoundedReadError as exc:
        raise ScenarioError(str(exc)) from None
    problem = _nesting_problem(text)
    if problem is not None:
        raise ScenarioError(f"{p}: not a valid scenario ({problem})")
    return text


def _toml_scalar(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"cannot write {v!r} to TOML")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string: JSON's escapes are TOML's
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_toml_scalar(x) for x in v) + "]"
    raise ValueError(f"cannot write {type(v).__name__} to TOML")


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list | tuple) and bool(v) and all(isinstance(x, Mapping) for x in v)


def _toml_table(prefix: str, table: Mapping[str, Any], out: list[str]) -> None:
    plain = {k: v for k, v in table.items()
             if not isinstance(v, Mapping) and not _is_table_array(v)}
    subs = {k: v for k, v in table.items() if isinstance(v, Mapping)}
    arrays = {k: v for k, v in table.items() if _is_table_array(v)}
    if plain or not (subs or arrays):
        out.append(f"[{prefix}]")
        out.extend(f"{k} = {_toml_scalar(v)}" for k, v in plain.items())
        out.append("")
    for k, v in subs.items():
        _toml_table(f"{prefix}.{k}", v, out)
    for k, rows in arrays.items():  # an array of tables: [[prefix.k]] per row
        for row in rows:
            out.append(f"[[{prefix}.{k}]]")
            out.extend(f"{kk} = {_toml_scalar(vv)}" for kk, vv in row.items())
            out.append("")


def dump_toml(doc: Mapping[str, Any]) -> str:
    """A scenario document (tables of scalars and lists, nested tables, arrays of tables of
    scalars such as ``mission.waypoint``, and the top-level arrays of tables ``agent`` and
    ``obstacle``) as TOML text that :mod:`tomllib` reads back to ``doc``."""
    out: list[str] = []
    arrays = ("obstacle", "agent")
    for name, value in doc.items():
        if name in arrays:
            continue
        _toml_table(name, value, out)
    for name in arrays:
        for row in doc.get(name, []):
            out.append(f"[[{name}]]")
            out.extend(f"{k} = {_toml_scalar(v)}" for k, v in row.items())
            out.append("")
    return "\n".join(out)
