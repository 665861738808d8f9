"""Per-vehicle PX4 parameters: names, types, defaults, ranges (no I/O but the optional file).

:class:`ParamStore` is what the rest of the simulator reads (``vehicle.params.get(NAME)``);
:mod:`vehicle_sim.param_service` speaks the MAVLink parameter protocol over it.
Values are floats in memory; ``MAV_PARAM_TYPE_INT32`` parameters hold integral values.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import common as M

INT32 = M.MAV_PARAM_TYPE_INT32
REAL32 = M.MAV_PARAM_TYPE_REAL32


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: PX4 name (≤ 16 chars), MAV_PARAM_TYPE, default, inclusive range."""

    name: str
    ptype: int
    default: float
    lo: float
    hi: float
    doc: str = ""


class ParamStore:
    """The ordered parameter table of one vehicle (index = position in ``specs``)."""

    def __init__(self, specs: list[ParamSpec]) -> None:
        self.specs = list(specs)
        self.index = {s.name: i for i, s in enumerate(self.specs)}
        self.values = [s.default for s in self.specs]

    def __len__(self) -> int:
        return len(self.specs)

    def get(self, name: str) -> float:
        """Current value of ``name`` (KeyError for an unknown name: a programming error)."""
        return self.values[self.index[name]]

    def set(self, name: str, value: float) -> float:
        """Set ``name`` inside its range (ValueError, one line, otherwise); returns it."""
        i = self.index.get(name)
        if i is None:
            raise ValueError(f"unknown parameter {name!r}")
        spec = self.specs[i]
        v = float(value)
        if not (spec.lo <= v <= spec.hi):
            raise ValueError(f"{name} = {v:g} outside [{spec.lo:g}, {spec.hi:g}]")
        if spec.ptype == INT32 and v != int(v):
            raise ValueError(f"{name} is an integer parameter, got {v:g}")
        self.values[i] = v
        return v
