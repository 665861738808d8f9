"""Safety filters: how a follower turns the nominal control into the applied one.

One class per collision-avoidance method (:class:`swarm_common.enums.Method`), listed in
:data:`SAFETY_FILTERS`; a new method plugs in by adding a ``Method`` member, one
:class:`offboard.safety.base.SafetyFilter` subclass and its row in the table. Every
filter starts from the same nominal formation controller ``u_nom`` (paper §4.2,
Departure 10):

* ``rcbf``: CLF–RCBF QP (§4.3–4.4, Departures 12–14), :mod:`offboard.safety.rcbf.filter`;
* ``apf``: improved artificial potential field (§5.4, Departure 17), :mod:`offboard.safety.apf`;
* ``dcbf``: CLF + sampled-data CBF QP over the realisable input set
  (:mod:`offboard.safety.dcbf.filter`, docs/safety.md);
* ``none``: the nominal control clipped to the box (:mod:`offboard.safety.apf`).

The filters' input, output and base class are in :mod:`offboard.safety.base`.
"""

from __future__ import annotations

import numpy as np

from offboard.safety.apf import ApfFilter, NoFilter
from offboard.safety.base import SafetyFilter
from offboard.safety.dcbf.filter import DcbfFilter
from offboard.safety.rcbf.filter import RcbfFilter
from swarm_common.enums import Method
from swarm_common.scenario.model import ControllerConfig

SAFETY_FILTERS: dict[Method, type[SafetyFilter]] = {
    Method.NONE: NoFilter,
    Method.APF: ApfFilter,
    Method.RCBF: RcbfFilter,
    Method.DCBF: DcbfFilter,
}


def parse_method(method: Method | str) -> Method:
    """``method`` as a :class:`Method`; ValueError naming the choices if it is not one."""
    try:
        return Method(method)
    except ValueError:
        choices = ", ".join(m.value for m in Method)
        raise ValueError(f"unknown method {method!r}; use one of {choices}") from None


def make_filters(
    ctl: ControllerConfig, u_lo: np.ndarray, u_hi: np.ndarray, leader_mask: np.ndarray
) -> dict[Method, SafetyFilter]:
    """One filter per method of :data:`SAFETY_FILTERS` (kept for the agent's lifetime: a
    method switch keeps each filter's state, e.g. the QP's warm start)."""
    return {m: cls(ctl, u_lo, u_hi, leader_mask) for m, cls in SAFETY_FILTERS.items()}
