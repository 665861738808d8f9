"""The PX4 parameter protocol (PARAM_REQUEST_LIST/READ, PARAM_SET, PARAM_VALUE, PARAM_ERROR).

Contract: :class:`vehicle_sim.autopilot.nav.VehicleService`. docs/px4/params.md describes the
behaviour a client sees; in short:

* PARAM_REQUEST_LIST: every parameter as PARAM_VALUE (``param_count`` = table size,
  ``param_index`` = its position) to the requester: at once for a table of at most
  ``LIST_BURST_MAX`` (the simulator's is), else ``LIST_PER_STEP`` per simulation step; a
  second request from the same peer starts its list again.
* PARAM_REQUEST_READ: by name (``param_index`` = -1) or by index, answered to the requester.
* PARAM_SET: the new value as PARAM_VALUE to every link (MAVLink's rule, so that every
  GCS sees it). A refused write gets, to the requester, PARAM_ERROR (the reason), a
  PARAM_VALUE with the unchanged value (what clients that predate PARAM_ERROR wait for),
  and a STATUSTEXT naming the error. An unknown name on READ or SET gets PARAM_ERROR
  DOES_NOT_EXIST and the STATUSTEXT. An unsigned PARAM_SET on the unsigned GCS link
  (``--unsigned-gcs-link``) is refused with PERMISSION_DENIED, like a flight command.
* Values: PX4's encoding. ``MAV_PARAM_TYPE_INT32`` travels bytewise (the float field
  carries the int32's four bytes); ``MAV_PARAM_TYPE_REAL32`` as the float. A PARAM_SET
  whose ``param_type`` is not the parameter's is refused (VALUE_OUT_OF_RANGE: the
  pymavlink dialect has no TYPE_MISMATCH code).
"""

from __future__ import annotations

import logging
from collections import deque
from typing import Any

from pymavlink.dialects.v20 import common as M

from swarm_common.px4 import int32_to_wire, wire_to_int32
from vehicle_sim.autopilot import audit, nav_flight
from vehicle_sim.autopilot.params import INT32, ParamError, ParamSpec, ParamStore

log = logging.getLogger(__name__)

LIST_PER_STEP = 8  # PARAM_VALUEs of a long PARAM_REQUEST_LIST sent per simulation step
# a table up to this long is answered at once: lockstep time stands still until the
# controllers run, and a client must be able to read the parameters before that
LIST_BURST_MAX = 32
INDEX_BY_NAME = -1  # PARAM_REQUEST_READ.param_index meaning "use param_id"
PARAM_ID_LEN = 16
TEXT_LEN = 50  # STATUSTEXT.text
ANSWERED_COMPONENTS = (M.MAV_COMP_ID_ALL, M.MAV_COMP_ID_AUTOPILOT1)


def wire_value(spec: ParamSpec, value: float) -> float:
    """PARAM_VALUE.param_value of ``value`` for this parameter's type."""
    return int32_to_wire(int(value)) if spec.ptype == INT32 else float(value)


def decode_set(spec: ParamSpec, param_type: int, param_value: float) -> float:
    """The value a PARAM_SET asks for, or :class:`ParamError` (type mismatch)."""
    if param_type != spec.ptype:
        want = "INT32" if spec.ptype == INT32 else "REAL32"
        raise ParamError(M.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE, f"{spec.name}: type must be {want}")
    if spec.ptype == INT32:
        return float(wire_to_int32(param_value))
    return float(param_value)


def _name(raw: Any) -> str:
    """PARAM_*.param_id as text (pymavlink gives str, bytes for undecodable ids)."""
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", errors="replace")
    return str(raw).split("\x00", 1)[0]


class ParamService:
    """Attached to one :class:`~vehicle_sim.vehicle.Vehicle` (``vehicle``)."""

    def __init__(self, vehicle: Any) -> None:
        self.vehicle = vehicle
        self.pending: deque[tuple[int, Any]] = deque()  # (index, requester) of lists
        self.refused = 0  # PARAM_ERRORs sent

    @property
    def store(self) -> ParamStore:
        store: ParamStore = self.vehicle.params
        return store

    def handlers(self) -> dict[int, Any]:
        """MAVLink message id -> ``handler(msg, src, wall, sim_t)``."""
        return {
            M.MAVLINK_MSG_ID_PARAM_REQUEST_LIST: self._on_request_list,
            M.MAVLINK_MSG_ID_PARAM_REQUEST_READ: self._on_request_read,
            M.MAVLINK_MSG_ID_PARAM_SET: self._on_set,
        }

    def command_handlers(self) -> dict[int, Any]:
        """MAV_CMD -> ``handler(vehicle, command) -> (MAV_RESULT, reply or None)``."""
        return {}

    def update(self, sim_t: float) -> None:
        """Once per simulation step (before the vehicle's controllers run): the speed
        ceilings (``MPC_*_VEL_MAX*``) to the position controller, then the next
        ``LIST_PER_STEP`` values of open lists."""
        pc = getattr(self.vehicle, "pc", None)
        if pc is not None:
            pc.set_ceiling(nav_flight.velocity_ceiling(self.store))
        for _ in range(min(LIST_PER_STEP, len(self.pending))):
            i, src = self.pending.popleft()
            self.vehicle.outbox.append((self.value_msg(i), src))

    # ------------------------------------------------------------------------------
    def value_msg(self, i: int) -> M.MAVLink_param_value_message:
        """PARAM_VALUE of parameter ``i``."""
        spec = self.store.specs[i]
        v = wire_value(spec, self.store.values[i])
        return M.MAVLink_param_value_message(spec.name.encode(), v, spec.ptype, len(self.store), i)

    def _refuse(self, m: Any, src: Any, name: str, index: int, exc: ParamError) -> None:
        """PARAM_ERROR and a STATUSTEXT to the requester (and the server's log)."""
        self.refused += 1
        err = M.MAVLink_param_error_message(
            m.get_srcSystem(), m.get_srcComponent(), name[:PARAM_ID_LEN].encode(errors="replace"),
            index, exc.code,
        )  # fmt: skip
        self.vehicle.outbox.append((err, src))
        text = f"param: {exc}"
        self.vehicle.events.append((M.MAV_SEVERITY_WARNING, f"vehicle {self.vehicle.id}: {text}"))
        st = M.MAVLink_statustext_message(
            M.MAV_SEVERITY_WARNING, text[:TEXT_LEN].encode(errors="replace")
        )
        self.vehicle.outbox.append((st, src))

    @staticmethod
    def _for_us(m: Any) -> bool:
        return getattr(m, "target_component", 0) in ANSWERED_COMPONENTS

    def _on_request_list(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if not self._for_us(m):
            return
        self.pending = deque(p for p in self.pending if p[1] != src)  # restart for src
        if len(self.store) <= LIST_BURST_MAX:  # short: at once, even while time stands still
            self.vehicle.outbox.extend((self.value_msg(i), src) for i in range(len(self.store)))
            return
        self.pending.extend((i, src) for i in range(len(self.store)))

    def _on_request_read(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if not self._for_us(m):
            return
        name = _name(m.param_id)
        idx = int(m.param_index)
        if idx == INDEX_BY_NAME:
            i = self.store.index.get(name)
            if i is None:
                exc = ParamError(M.MAV_PARAM_ERROR_DOES_NOT_EXIST, f"unknown parameter {name!r}")
                self._refuse(m, src, name, idx, exc)
                return
        elif 0 <= idx < len(self.store):
            i = idx
        else:
            exc = ParamError(M.MAV_PARAM_ERROR_DOES_NOT_EXIST, f"no parameter index {idx}")
            self._refuse(m, src, "", idx, exc)
            return
        self.vehicle.outbox.append((self.value_msg(i), src))

    def _audit(self, m: Any, src: Any, sim_t: float, name: str, exc: ParamError | None) -> None:
        """PARAM_SET in the vehicle's audit trail: params (name, value, MAV_PARAM_TYPE),
        result ACCEPTED or the MAV_PARAM_ERROR with its reason."""
        params = [name, m.param_value, m.param_type]
        if exc is None:
            audit.record(self.vehicle, m, src, sim_t, "PARAM_SET", params, "ACCEPTED", True)
        else:
            audit.record(self.vehicle, m, src, sim_t, "PARAM_SET", params,
                         audit.enum_name("MAV_PARAM_ERROR", exc.code), False, str(exc))

    def _on_set(self, m: Any, src: Any, wall: float, sim_t: float) -> None:
        if not self._for_us(m):
            return
        name = _name(m.param_id)
        i = self.store.index.get(name)
        if i is None:
            exc = ParamError(M.MAV_PARAM_ERROR_DOES_NOT_EXIST, f"unknown parameter {name!r}")
            self._audit(m, src, sim_t, name, exc)
            self._refuse(m, src, name, INDEX_BY_NAME, exc)
            return
        try:
            if getattr(m, "_restricted", False):
                raise ParamError(
                    M.MAV_PARAM_ERROR_PERMISSION_DENIED, f"{name}: unsigned link, read only"
                )
            value = decode_set(self.store.specs[i], int(m.param_type), float(m.param_value))
            changed = self.store.set(name, value)
        except ParamError as exc:
            self._audit(m, src, sim_t, name, exc)
            self._refuse(m, src, name, i, exc)
            self.vehicle.outbox.append((self.value_msg(i), src))  # unchanged value
            return
        self._audit(m, src, sim_t, name, None)
        log.info("vehicle %d: %s = %g", self.vehicle.id, name, changed)
        for n in self.store.linked(name):
            self.vehicle.outbox.append((self.value_msg(self.store.index[n]), None))
