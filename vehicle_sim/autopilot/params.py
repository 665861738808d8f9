"""Per-vehicle PX4 parameters: names, types, defaults, ranges, and the optional file.

:class:`ParamStore` is what the rest of the simulator reads (``vehicle.params.get(NAME)``);
:mod:`vehicle_sim.services.param` speaks the MAVLink parameter protocol over it.
Values are floats in memory; ``MAV_PARAM_TYPE_INT32`` parameters hold integral values.

The parameter file (``vehicle-sim --params-file PATH``, docs/px4/params.md) is one JSON
object keyed by vehicle id::

    {"format": "vehicle-sim-params/1",
     "vehicles": {"1": {"MPC_THR_HOVER": 0.42}, "3": {"COM_OF_LOSS_T": 1.0}}}

It holds only the values that were set (loaded from the file or written by PARAM_SET);
everything else keeps the default of the run. It is validated on load (unknown name,
read-only name, wrong type or out-of-range value: :class:`ParamFileError`, one line) and
rewritten atomically (temporary file + rename) after every accepted PARAM_SET.
"""

from __future__ import annotations

import json
import logging
import math
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as M

from swarm_common.inputs import (
    MAX_PARAMS_BYTES,
    BoundedReadError,
    finite_float,
    read_bounded_text,
)

log = logging.getLogger(__name__)

INT32 = M.MAV_PARAM_TYPE_INT32
REAL32 = M.MAV_PARAM_TYPE_REAL32
FILE_FORMAT = "vehicle-sim-params/1"
MAX_VEHICLE_ID = 255


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: PX4 name (≤ 16 chars), MAV_PARAM_TYPE, default, inclusive range.

    ``read_only``: an identity value (PARAM_SET answers MAV_PARAM_ERROR_READ_ONLY);
    ``alias_of``: another parameter of the table that this one always equals (writing
    either writes both)."""

    name: str
    ptype: int
    default: float
    lo: float
    hi: float
    doc: str = ""
    read_only: bool = False
    alias_of: str | None = None


class ParamError(ValueError):
    """A refused read or write; ``code`` is the MAV_PARAM_ERROR_* the protocol answers."""

    def __init__(self, code: int, text: str) -> None:
        super().__init__(text)
        self.code = code


class ParamStore:
    """The ordered parameter table of one vehicle (index = position in ``specs``)."""

    def __init__(self, specs: list[ParamSpec]) -> None:
        self.specs = list(specs)
        self.index = {s.name: i for i, s in enumerate(self.specs)}
        if len(self.index) != len(self.specs):
            raise ValueError("duplicate parameter name in the table")
        self.values = [float(s.default) for s in self.specs]
        self.overrides: dict[str, float] = {}  # what was set: loaded or PARAM_SET
        self.listeners: list[Callable[[ParamStore, list[str]], None]] = []

    def __len__(self) -> int:
        return len(self.specs)

    def get(self, name: str) -> float:
        """Current value of ``name`` (KeyError for an unknown name: a programming error)."""
        return self.values[self.index[name]]

    def spec(self, name: str) -> ParamSpec:
        """The spec of ``name``; :class:`ParamError` DOES_NOT_EXIST for an unknown one."""
        i = self.index.get(name)
        if i is None:
            raise ParamError(M.MAV_PARAM_ERROR_DOES_NOT_EXIST, f"unknown parameter {name!r}")
        return self.specs[i]

    def check(self, name: str, value: float) -> float:
        """The value ``name`` would take, or :class:`ParamError` (one line) saying why not."""
        spec = self.spec(name)
        if spec.read_only:
            raise ParamError(M.MAV_PARAM_ERROR_READ_ONLY, f"{name} is read-only")
        v = float(value)
        if not (math.isfinite(v) and spec.lo <= v <= spec.hi):
            raise ParamError(
                M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE,
                f"{name} = {v:g} outside [{spec.lo:g}, {spec.hi:g}]",
            )
        if spec.ptype == INT32 and v != int(v):
            raise ParamError(
                M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE, f"{name} is an integer, got {v:g}"
            )
        return v

    def linked(self, name: str) -> list[str]:
        """``name`` and every parameter aliased to it (or that it aliases), table order."""
        root = self.spec(name).alias_of or name
        return [s.name for s in self.specs if s.name == root or s.alias_of == root]

    def set(self, name: str, value: float) -> float:
        """Set ``name`` (and its aliases) inside its range; :class:`ParamError` otherwise.
        Returns the value; listeners are told which names changed."""
        v = self.check(name, value)
        names = self.linked(name)
        for n in names:
            self.values[self.index[n]] = v
        self.overrides[self.spec(name).alias_of or name] = v
        for fn in self.listeners:
            fn(self, names)
        return v

    def load_overrides(self, values: dict[str, float]) -> None:
        """Apply already validated values without telling the listeners."""
        for name, v in values.items():
            v = self.check(name, v)
            for n in self.linked(name):
                self.values[self.index[n]] = v
            self.overrides[self.spec(name).alias_of or name] = v


class ParamFileError(ValueError):
    """A parameter file that cannot be read or is invalid (one line)."""


def _vehicle_key(key: Any) -> int:
    if not (isinstance(key, str) and key.isdigit() and 1 <= int(key) <= MAX_VEHICLE_ID):
        raise ParamFileError(f"vehicle key {key!r}: must be an id in [1, {MAX_VEHICLE_ID}]")
    return int(key)


def _entry(store: ParamStore, vid: int, name: Any, value: Any) -> float:
    if not isinstance(name, str):
        raise ParamFileError(f"vehicle {vid}: parameter name {name!r} is not a string")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParamFileError(f"vehicle {vid}: {name} = {value!r} is not a number")
    number = finite_float(value)
    if number is None:  # NaN, ±inf or an int too large for a float (no OverflowError)
        raise ParamFileError(f"vehicle {vid}: {name} = {str(value)[:40]} is not a finite number")
    try:
        return store.check(name, number)
    except ParamError as exc:
        raise ParamFileError(f"vehicle {vid}: {exc}") from None


def parse_param_file(data: Any, table: ParamStore) -> dict[int, dict[str, float]]:
    """Validate a decoded parameter file against ``table`` (names, types, ranges: the
    same for every vehicle); returns {vehicle id: {name: value}}."""
    if not isinstance(data, dict) or set(data) != {"format", "vehicles"}:
        raise ParamFileError('must be an object with exactly "format" and "vehicles"')
    if data["format"] != FILE_FORMAT:
        raise ParamFileError(f"format {data['format']!r}: expected {FILE_FORMAT!r}")
    vehicles = data["vehicles"]
    if not isinstance(vehicles, dict):
        raise ParamFileError('"vehicles" must be an object keyed by vehicle id')
    out: dict[int, dict[str, float]] = {}
    for key, entries in vehicles.items():
        vid = _vehicle_key(key)
        if not isinstance(entries, dict):
            raise ParamFileError(f"vehicle {vid}: must be an object of name: value")
        out[vid] = {name: _entry(table, vid, name, v) for name, v in entries.items()}
    return out


def read_param_file(path: str | Path, table: ParamStore) -> dict[int, dict[str, float]]:
    """Read and validate ``path``; a missing file is an empty one (it is created on the
    first PARAM_SET). :class:`ParamFileError` with one line otherwise."""
    p = Path(path)
    if not os.path.lexists(p):
        return {}
    try:  # a regular file of at most MAX_PARAMS_BYTES: never a FIFO or /dev/zero
        text = read_bounded_text(p, MAX_PARAMS_BYTES, "parameter file")
    except BoundedReadError as exc:
        raise ParamFileError(str(exc).removeprefix(f"{p}: ")) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ParamFileError(f"not JSON: {exc}") from None
    except (ValueError, RecursionError) as exc:  # an int of > 4300 digits; nesting too deep
        raise ParamFileError(f"not valid JSON ({type(exc).__name__})") from None
    return parse_param_file(data, table)


class ParamFile:
    """The file behind ``--params-file``: the values loaded from it for vehicles not in
    this run are kept, the stores of this run are written over them on every change."""

    def __init__(self, path: str | Path, stored: dict[int, dict[str, float]]) -> None:
        self.path = Path(path)
        self.stored = {vid: dict(v) for vid, v in stored.items()}
        self.stores: dict[int, ParamStore] = {}
        self.saves = 0
        self.save_errors = 0

    def attach(self, vid: int, store: ParamStore) -> None:
        """Apply the file's values for vehicle ``vid`` and save whenever it changes."""
        store.load_overrides(self.stored.get(vid, {}))
        self.stores[vid] = store
        store.listeners.append(self._on_change)

    def _on_change(self, _store: ParamStore, _names: list[str]) -> None:
        """Save after a change; a failed write is logged and counted, the value stays."""
        try:
            self.save()
        except OSError as exc:
            self.save_errors += 1
            log.error("--params-file %s: cannot save: %s", self.path, exc)

    def document(self) -> dict[str, Any]:
        merged = {vid: dict(v) for vid, v in self.stored.items()}
        for vid, store in self.stores.items():
            merged[vid] = dict(store.overrides)
        vehicles = {str(vid): merged[vid] for vid in sorted(merged) if merged[vid]}
        return {"format": FILE_FORMAT, "vehicles": vehicles}

    def save(self) -> None:
        """Write atomically (temporary file in the same folder, then rename); OSError on
        failure (the caller reports it)."""
        text = json.dumps(self.document(), indent=2, sort_keys=True) + "\n"
        folder = self.path.parent if str(self.path.parent) else Path(".")
        fd, tmp = tempfile.mkstemp(prefix=self.path.name + ".", suffix=".tmp", dir=folder)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.path)
        except OSError:
            Path(tmp).unlink(missing_ok=True)
            raise
        self.saves += 1
