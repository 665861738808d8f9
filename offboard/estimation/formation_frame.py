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

**Turning a jet.** For x(t) in the world frame (complex xy) and E(t) = e^{−iψ(t)}, the
F-frame value is ζ = E x and, by Leibniz, ζ⁽ⁿ⁾ = Σ_k C(n,k) E⁽ᵏ⁾ x⁽ⁿ⁻ᵏ⁾ with
E' = w'E, E'' = (w'' + w'²)E, E''' = (w''' + 3w'w'' + w'³)E, w = −iψ; back to the world
frame with w = +iψ. z is unchanged.
"""

from __future__ import annotations

import cmath
import math

import numpy as np

from offboard.estimation.peer_table import XI_COL
from offboard.estimation.reference import DesiredStateObserver
from swarm_common.jit import kernel
from swarm_common.scenario.mission_check import MIN_YAW_OFFSET_M, yaw_leaders
from swarm_common.scenario.spec import Scenario

# |r₀| (m) below which the leaders' horizontal offset cannot carry the yaw
MIN_LEADER_OFFSET_M = MIN_YAW_OFFSET_M


def yaw_jet_from_offset(r: list[complex], arg0: float) -> np.ndarray:
    """[ψ, ψ', ψ'', ψ'''] (rad, rad/s, ...) of the leaders' horizontal offset jet ``r``
    (4 complex: r, r', r'', r''' in m, m/s, ...) against its shape value's angle ``arg0``
    (rad). Module docstring (compiled: :func:`offset_yaw_kernel`)."""
    out = np.empty(4)
    offset_yaw_kernel(np.array(r, dtype=np.complex128), float(arg0), out)
    return out


def extrapolate(jet: np.ndarray, dt: float) -> np.ndarray:
    """``jet`` (4,) = [x, x', x'', x'''] moved ``dt`` (s) ahead at constant x'''
    (compiled: :func:`extrapolate_kernel`)."""
    out = np.empty(4)
    extrapolate_kernel(np.asarray(jet, dtype=float), float(dt), out)
    return out


def turn_xi(xi: np.ndarray, yaw: np.ndarray, sign: float, out: np.ndarray) -> None:
    """``xi`` (12,) turned by ``sign``·ψ(t) (``yaw`` the jet (4,)), with the time derivatives
    of the turn, into ``out`` (12,; may be ``xi``). ``sign`` −1: world → formation frame;
    +1: back. Module docstring (compiled: :func:`turn_xi_kernel`)."""
    turn_xi_kernel(np.asarray(xi, dtype=float), np.asarray(yaw, dtype=float), float(sign), out)


@kernel
def offset_yaw_kernel(r: np.ndarray, arg0: float, out: np.ndarray) -> None:
    """[ψ, ψ', ψ'', ψ'''] into ``out`` (4,) from the offset jet ``r`` (4,) complex128:
    ψ = arg r − arg0, ψ⁽ⁿ⁾ = Im ℓ⁽ⁿ⁾ of ℓ = log r (module docstring)."""
    q1, q2, q3 = r[1] / r[0], r[2] / r[0], r[3] / r[0]
    l2 = q2 - q1 * q1
    l3 = q3 - 3.0 * q2 * q1 + 2.0 * q1 * q1 * q1
    out[0] = cmath.phase(r[0]) - arg0
    out[1] = q1.imag
    out[2] = l2.imag
    out[3] = l3.imag


@kernel
def extrapolate_kernel(jet: np.ndarray, dt: float, out: np.ndarray) -> None:
    """``jet`` (4,) moved ``dt`` (s) ahead at constant third derivative, into ``out`` (4,)."""
    x, d1, d2, d3 = jet[0], jet[1], jet[2], jet[3]
    out[0] = x + dt * (d1 + dt * (d2 / 2.0 + dt * d3 / 6.0))
    out[1] = d1 + dt * (d2 + dt * d3 / 2.0)
    out[2] = d2 + dt * d3
    out[3] = d3


@kernel
def turn_xi_kernel(xi: np.ndarray, yaw: np.ndarray, sign: float, out: np.ndarray) -> None:
    """``xi`` (12,) turned by ``sign``·ψ with the turn's time derivatives (Leibniz, module
    docstring), into ``out`` (12,; may be ``xi``); z unchanged."""
    w1 = complex(0.0, sign * yaw[1])
    w2 = complex(0.0, sign * yaw[2])
    w3 = complex(0.0, sign * yaw[3])
    e0 = cmath.exp(complex(0.0, sign * yaw[0]))
    e1 = w1 * e0
    e2 = (w2 + w1 * w1) * e0
    e3 = (w3 + 3.0 * w1 * w2 + w1 * w1 * w1) * e0
    x0 = complex(xi[0], xi[1])
    x1 = complex(xi[3], xi[4])
    x2 = complex(xi[6], xi[7])
    x3 = complex(xi[9], xi[10])
    z0 = e0 * x0
    z1 = e0 * x1 + e1 * x0
    z2 = e0 * x2 + 2.0 * e1 * x1 + e2 * x0
    z3 = e0 * x3 + 3.0 * e1 * x2 + 3.0 * e2 * x1 + e3 * x0
    out[0], out[1], out[2] = z0.real, z0.imag, xi[2]
    out[3], out[4], out[5] = z1.real, z1.imag, xi[5]
    out[6], out[7], out[8] = z2.real, z2.imag, xi[8]
    out[9], out[10], out[11] = z3.real, z3.imag, xi[11]


@kernel
def frame_rows_kernel(
    rows: np.ndarray, have: np.ndarray, used: np.ndarray, a: int, b: int, arg0: float,
    yaw_prev: np.ndarray, dt: float, min_offset: float, out_rows: np.ndarray,
    yaw: np.ndarray,
) -> None:
    """One period's frame change, compiled: the ψ jet at the rows' time into ``yaw`` (4,)
    (from leaders ``a``, ``b``'s ξ in the rows (N,21), or ``yaw_prev`` carried ``dt`` ahead
    when either is missing, non-finite or closer than ``min_offset``), and ``out_rows``
    (N,21) = ``rows`` with the ξ of every ``used`` neighbour that ``have`` marks turned into
    the formation frame."""
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
    out_rows[:, :] = rows
    seg = np.empty(12)
    for n in range(used.shape[0]):
        j = used[n]
        if have[j]:
            for q in range(12):
                seg[q] = rows[j, XI_COL + q]
            turn_xi_kernel(seg, yaw, -1.0, seg)
            for q in range(12):
                out_rows[j, XI_COL + q] = seg[q]


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
        self._used = np.array(inner.nbrs, dtype=np.int64)

    def update(self, peer_rows: np.ndarray, have: np.ndarray) -> None:
        """Advance ξ̂ one period (as :meth:`DesiredStateObserver.update`): the neighbours'
        ξ_j turned into the formation frame at the rows' time (the yaw read from the two
        leaders, or the last one carried a period ahead when either is missing), the
        observer stepped there, its estimate turned back at the next time."""
        a, b = self.leaders
        rows = np.empty(peer_rows.shape)
        yaw = np.empty(4)
        frame_rows_kernel(np.ascontiguousarray(peer_rows, dtype=float), have, self._used, a, b,
                          self.arg0, self.yaw, self.dt, MIN_LEADER_OFFSET_M, rows, yaw)
        self.inner.update(rows, have)
        nxt = np.empty(4)
        extrapolate_kernel(yaw, self.dt, nxt)
        self.yaw = nxt
        out = np.empty(12)
        turn_xi_kernel(self.inner.xi, nxt, 1.0, out)
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


def formation_frame_observer(sc: Scenario, inner: DesiredStateObserver) -> FormationFrameObserver:
    """``inner`` run in the formation frame of ``sc``'s mission: the yaw read from the first
    two leaders' offset in the mission's shape."""
    a, b, offset = yaw_leaders(sc)
    return FormationFrameObserver(inner, (a, b), offset)
