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
from swarm_common.scenario.mission_check import mission_shape
from swarm_common.scenario.spec import Scenario

# |r₀| (m) below which the leaders' horizontal offset cannot carry the yaw
MIN_LEADER_OFFSET_M = 1e-3


def _cplx(xi: np.ndarray) -> list[complex]:
    """The xy parts of ξ (12,) = [p, ṗ, p̈, p⃛] as four complex numbers."""
    return [complex(xi[3 * d], xi[3 * d + 1]) for d in range(4)]


def yaw_jet_from_offset(r: list[complex], arg0: float) -> np.ndarray:
    """[ψ, ψ', ψ'', ψ'''] (rad, rad/s, ...) of the leaders' horizontal offset jet ``r``
    (4 complex: r, r', r'', r''' in m, m/s, ...) against its shape value's angle ``arg0``
    (rad). Module docstring."""
    q1, q2, q3 = r[1] / r[0], r[2] / r[0], r[3] / r[0]
    l2 = q2 - q1 * q1
    l3 = q3 - 3.0 * q2 * q1 + 2.0 * q1 * q1 * q1
    return np.array([cmath.phase(r[0]) - arg0, q1.imag, l2.imag, l3.imag])


def extrapolate(jet: np.ndarray, dt: float) -> np.ndarray:
    """``jet`` (4,) = [x, x', x'', x'''] moved ``dt`` (s) ahead at constant x'''."""
    x, d1, d2, d3 = (float(v) for v in jet)
    return np.array([
        x + dt * (d1 + dt * (d2 / 2.0 + dt * d3 / 6.0)),
        d1 + dt * (d2 + dt * d3 / 2.0),
        d2 + dt * d3,
        d3,
    ])


def turn_xi(xi: np.ndarray, yaw: np.ndarray, sign: float, out: np.ndarray) -> None:
    """``xi`` (12,) turned by ``sign``·ψ(t) (``yaw`` the jet (4,)), with the time derivatives
    of the turn, into ``out`` (12,; may be ``xi``). ``sign`` −1: world → formation frame;
    +1: back. Module docstring."""
    w1, w2, w3 = (complex(0.0, sign * float(yaw[k])) for k in (1, 2, 3))
    e0 = cmath.exp(complex(0.0, sign * float(yaw[0])))
    e = (e0, w1 * e0, (w2 + w1 * w1) * e0, (w3 + 3.0 * w1 * w2 + w1 * w1 * w1) * e0)
    x = _cplx(xi)
    z = (
        e[0] * x[0],
        e[0] * x[1] + e[1] * x[0],
        e[0] * x[2] + 2.0 * e[1] * x[1] + e[2] * x[0],
        e[0] * x[3] + 3.0 * e[1] * x[2] + 3.0 * e[2] * x[1] + e[3] * x[0],
    )
    for d in range(4):
        out[3 * d] = z[d].real
        out[3 * d + 1] = z[d].imag
        out[3 * d + 2] = xi[3 * d + 2]


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
        self._used = list(inner.nbrs)

    def _yaw_at(self, rows: np.ndarray, have: np.ndarray) -> np.ndarray:
        """ψ jet at the rows' time from the two leaders' ξ, or the last one carried a period
        ahead when either leader's row is missing or degenerate."""
        a, b = self.leaders
        if have[a] and have[b]:
            xa = rows[a, XI_COL:XI_COL + 12]
            xb = rows[b, XI_COL:XI_COL + 12]
            r = [complex(xb[3 * d] - xa[3 * d], xb[3 * d + 1] - xa[3 * d + 1]) for d in range(4)]
            if abs(r[0]) >= MIN_LEADER_OFFSET_M and all(map(cmath.isfinite, r)):
                return yaw_jet_from_offset(r, self.arg0)
        return extrapolate(self.yaw, self.dt)

    def update(self, peer_rows: np.ndarray, have: np.ndarray) -> None:
        """Advance ξ̂ one period (as :meth:`DesiredStateObserver.update`): the neighbours'
        ξ_j turned into the formation frame at the rows' time, the observer stepped there,
        its estimate turned back at the next time."""
        yaw = self._yaw_at(peer_rows, have)
        rows = np.array(peer_rows, dtype=float, copy=True)
        for j in self._used:
            if have[j]:
                seg = rows[j, XI_COL:XI_COL + 12]
                turn_xi(seg, yaw, -1.0, seg)
        self.inner.update(rows, have)
        self.yaw = extrapolate(yaw, self.dt)
        out = np.empty(12)
        turn_xi(self.inner.xi, self.yaw, 1.0, out)
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
    shape = mission_shape(sc)
    a, b = (sc.index_of(i) for i in sc.formation.leaders[:2])
    return FormationFrameObserver(inner, (a, b), shape[b] - shape[a])
