"""The formation frame: the desired-state observer of a yawing formation (docs/missions.md).

A formation mission may turn the whole formation about the vertical axis by a common yaw
ψ(t). Every desired bearing then turns with it, g*_ij(t) = R_z(ψ) g*_ij(0), and the observer
of :mod:`offboard.estimation.reference`, built on the fixed projectors P*_ij(0), would
converge to the wrong shape. In the *formation frame* F, turned by −ψ(t), the desired
bearings are the fixed ones again: the observer runs there unchanged (its exact one-period
maps stay cached) on the neighbours' ξ_j turned into F, and its estimate is turned back into
the world frame for the controller and the broadcast.

**Where ψ comes from.** No new datum is sent: every follower already receives every
leader's reference state ξ_L = [p, ṗ, p̈, p⃛]. The formation turns and scales as one, so the
leaders' horizontal offset r(t) = p_L2 − p_L1 (complex x + iy) is r(t) = s(t) e^{iψ(t)} r₀, r₀
its value in the scenario's shape: ψ = arg r − arg r₀, and with ℓ = log r,
ψ⁽ⁿ⁾ = Im ℓ⁽ⁿ⁾, where ℓ' = r'/r, ℓ'' = r''/r − (r'/r)², ℓ''' = r'''/r − 3(r''/r)(r'/r) +
2(r'/r)³. Scaling and translation do not change arg r. This also serves leaders flown by an
operator: the followers read the yaw from what the leaders fly.

**Turning a jet** (Leibniz, with the turn's time derivatives): :mod:`offboard.estimation.yaw_turn`.
"""

from __future__ import annotations

import cmath
import math

import numpy as np

from offboard.estimation.peer_table import XI_COL
from offboard.estimation.reference import DesiredStateObserver, observer_core
from offboard.estimation.yaw_turn import extrapolate_kernel, offset_yaw_kernel, turn_xi_kernel
from swarm_common.fastnp import f64
from swarm_common.jit import kernel
from swarm_common.scenario.mission_check import MIN_YAW_OFFSET_M, yaw_leaders
from swarm_common.scenario.spec import Scenario

# |r₀| (m) below which the leaders' horizontal offset cannot carry the yaw
MIN_LEADER_OFFSET_M = MIN_YAW_OFFSET_M


@kernel
def rows_yaw_kernel(
    rows: np.ndarray, have: np.ndarray, a: int, b: int, arg0: float, yaw_prev: np.ndarray,
    dt: float, min_offset: float, yaw: np.ndarray,
) -> None:
    """The ψ jet at the rows' time into ``yaw`` (4,): from leaders ``a``, ``b``'s ξ in the
    rows (N,21), or ``yaw_prev`` carried ``dt`` ahead when either is missing, non-finite or
    closer than ``min_offset`` (m)."""
    ok = have[a] and have[b]
    r = np.empty(4, dtype=np.complex128)
    if ok:
        for d in range(4):
            c = XI_COL + 3 * d
            r[d] = complex(rows[b, c] - rows[a, c], rows[b, c + 1] - rows[a, c + 1])
            if not (math.isfinite(r[d].real) and math.isfinite(r[d].imag)):
                ok = False
        if ok and abs(r[0]) < min_offset:
            ok = False
    if ok:
        offset_yaw_kernel(r, arg0, yaw)
    else:
        extrapolate_kernel(yaw_prev, dt, yaw)


class FormationFrameObserver:
    """The desired-state observer of follower ``index`` run in the formation frame (module
    docstring): the interface of :class:`~offboard.estimation.reference.DesiredStateObserver`
    (``update``, ``xi``, ``rate``), with ``xi`` in the world frame.

    ``leaders``: the scenario indices of the two leaders whose offset carries the yaw;
    ``shape_offset``: their offset p_L2 − p_L1 (m) in the scenario's shape (yaw 0)."""

    def __init__(
        self, inner: DesiredStateObserver, leaders: tuple[int, int], shape_offset: np.ndarray,
    ) -> None:
        r0 = complex(float(shape_offset[0]), float(shape_offset[1]))
        if abs(r0) < MIN_LEADER_OFFSET_M:
            raise ValueError("the leaders' horizontal offset is too small to carry a yaw")
        self.inner = inner
        self.leaders = leaders
        self.arg0 = cmath.phase(r0)
        self.dt = inner.dt
        self.yaw = np.zeros(4)  # ψ jet at the estimate's time (rad, rad/s, ...)
        self._xi_world = inner.xi.copy()
        inner.xi = inner.xi.copy()  # at yaw 0 the frames agree

    def update(self, peer_rows: np.ndarray, have: np.ndarray) -> None:
        """Advance ξ̂ one period (as :meth:`DesiredStateObserver.update`): the neighbours'
        ξ_j turned into the formation frame at the rows' time (the yaw read from the two
        leaders, or the last one carried a period ahead when either is missing), the
        observer stepped there, its estimate turned back at the next time (one compiled
        call, :func:`frame_observer_kernel`, unless no neighbour is heard)."""
        a, b = self.leaders
        rows = f64(peer_rows)
        maps = self.inner.maps(have)
        nxt = np.empty(4)
        out = np.empty(12)
        if maps is None:  # open loop on the exosystem (the inner observer's own path)
            yaw = np.empty(4)
            rows_yaw_kernel(rows, have, a, b, self.arg0, self.yaw, self.dt,
                            MIN_LEADER_OFFSET_M, yaw)
            self.inner.update(rows, have)
            extrapolate_kernel(yaw, self.dt, nxt)
            turn_xi_kernel(self.inner.xi, nxt, 1.0, out)
        else:
            xi_f = np.empty(12)
            frame_observer_kernel(rows, have, a, b, self.arg0, self.yaw, self.dt,
                                  MIN_LEADER_OFFSET_M, *maps, self.inner.xi, xi_f, nxt, out)
            self.inner.xi = xi_f
        self.yaw = nxt
        self._xi_world = out

    @property
    def xi(self) -> np.ndarray:
        """ξ̂ (12,) in the world frame."""
        return self._xi_world

    @property
    def rate(self) -> float:
        """As :attr:`DesiredStateObserver.rate` (the frames do not change it)."""
        return self.inner.rate

    @property
    def yaw_rad(self) -> float:
        """The formation's yaw ψ (rad, wrapped to (−π, π]) at the estimate's time."""
        return math.remainder(float(self.yaw[0]), 2.0 * math.pi)


@kernel
def frame_observer_kernel(
    rows: np.ndarray, have: np.ndarray, a: int, b: int, arg0: float, yaw_prev: np.ndarray,
    dt: float, min_offset: float, mx: np.ndarray, mc: np.ndarray, pu: np.ndarray,
    idx: np.ndarray, xi_f: np.ndarray, xi_f_out: np.ndarray, yaw_next: np.ndarray,
    xi_world: np.ndarray,
) -> None:
    """One period of :meth:`FormationFrameObserver.update` in one call: the ψ jet at the
    rows' time (:func:`rows_yaw_kernel`); the observer's step in the formation frame
    (:func:`~offboard.estimation.reference.observer_core` with the maps ``mx``, ``mc``,
    ``pu``, ``idx`` of the neighbours heard, each neighbour's ξ_j turned by −ψ as it is
    read) from ``xi_f`` (12,) into ``xi_f_out``; the ψ jet carried to the next time into
    ``yaw_next`` (4,), and the estimate turned back into the world frame there, into
    ``xi_world`` (12,)."""
    yaw = np.empty(4)
    rows_yaw_kernel(rows, have, a, b, arg0, yaw_prev, dt, min_offset, yaw)
    observer_core(mx, mc, pu, idx, rows, xi_f, yaw, True, xi_f_out)
    extrapolate_kernel(yaw, dt, yaw_next)
    turn_xi_kernel(xi_f_out, yaw_next, 1.0, xi_world)


def formation_frame_observer(sc: Scenario, inner: DesiredStateObserver) -> FormationFrameObserver:
    """``inner`` run in the formation frame of ``sc``'s mission: the yaw read from the first
    two leaders' offset in the mission's shape."""
    a, b, offset = yaw_leaders(sc)
    return FormationFrameObserver(inner, (a, b), offset)
