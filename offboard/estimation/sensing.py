"""Synthetic onboard relative sensing (paper §3 inputs; Departure 6).

For agent i and every other agent j within ``formation.sensing_range_m`` the sensor gives
the bearing ``g_ij``, the bearing rate ``ġ_ij = P_ij (v_j − v_i)/d_ij``, the distance
``d_ij`` and the range rate ``ḋ_ij = g_ijᵀ (v_j − v_i)``, each with seeded Gaussian noise
(``[sensing]``), and independent per-pair dropouts. From them the relative position and
velocity follow: ``p_j − p_i = g_ij d_ij`` and ``v_j − v_i = ġ_ij d_ij + g_ij ḋ_ij``.

Reproducibility: the generator is ``np.random.default_rng([seed, agent_id, 0x5E])``.

With ``[sensing] noise_draws = "every_agent"`` (the default) every call draws the same
count of numbers (N×8 normals and N uniforms) whatever is in range. With ``"in_range"``
it draws 8 normals and 1 uniform per agent in range, in index order, so the cost of a
call follows the number of neighbours, not N (a large swarm). Both depend only on the
seed and the true states, so runs with the same seed are identical, in process and
distributed.

Outputs: every sensor of a thread writes its measurements and its draws into one scratch
per swarm size and kind of draws (:class:`SensorScratch`), not into buffers of its own. A
follower reads its measurements within its step only, so a swarm's sensors can share them;
at a thousand agents the N-row outputs of every follower were 115 kB each, and every step
touched a few scattered rows of each, cold in the cache (docs/performance.md, "Past 255
agents").
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from offboard.estimation.sensing_kernel import (
    hold_kernel,
    measure_in_range_into,
    measure_into,
    range_index,
)
from swarm_common.enums import NoiseDraws
from swarm_common.fastnp import bools, f64, rows3
from swarm_common.jit import CallSite
from swarm_common.scenario.model import SensingConfig

DRAW_ROWS = 64  # the in-range draws' first room (agents in range), grown on demand


@dataclass
class Measurements:
    """Relative measurements of one agent to all N agents (rows for itself are invalid)."""

    valid: np.ndarray  # (N,) bool: in range, not dropped, not self
    g: np.ndarray  # (N,3) bearings g_ij
    g_dot: np.ndarray  # (N,3) bearing rates
    d: np.ndarray  # (N,) distances
    d_dot: np.ndarray  # (N,) range rates
    rel_p: np.ndarray  # (N,3) p_j − p_i = g_ij d_ij (m), from the measured ones
    rel_v: np.ndarray  # (N,3) v_j − v_i = ġ_ij d_ij + g_ij ḋ_ij (m/s), likewise

    def rel_pos(self) -> np.ndarray:
        """(N,3) measured p_j − p_i = g_ij d_ij."""
        return self.rel_p

    def rel_vel(self) -> np.ndarray:
        """(N,3) measured v_j − v_i = ġ_ij d_ij + g_ij ḋ_ij."""
        return self.rel_v


class SensorScratch:
    """What a sensor writes in a call, shared by the sensors of a thread that measure ``n``
    agents with the same kind of draws (:func:`scratch`): the outputs (:class:`Measurements`
    over all N rows) and the call's draws. For in-range draws also the agents in range of
    the call (``idx``) and the rows the last call wrote (``prev[:n_prev]``: its agents in
    range and its own row), which the next call, whichever sensor makes it, resets to an
    out-of-range row's zeros before it writes its own."""

    def __init__(self, n: int, in_range: bool) -> None:
        vec, sca = np.zeros((4, n, 3)), np.zeros((2, n))
        self.out = Measurements(np.zeros(n, dtype=np.bool_), vec[0], vec[1], sca[0], sca[1],
                                vec[2], vec[3])
        # the draws, written in place (``out=``: the same numbers as drawing new arrays of
        # that shape); with in-range draws, room for the agents in range, grown on demand
        rows = min(n, DRAW_ROWS) if in_range else n
        self.noise, self.drop = np.empty((rows, 8)), np.empty(rows)
        self.idx = np.empty(n if in_range else 0, dtype=np.int64)
        self.prev = np.empty(n if in_range else 0, dtype=np.int64)
        self.n_prev = 0

    def draw_rows(self, k: int) -> None:
        """Room for the draws of ``k`` agents in range: at least double, at most N rows
        (the numbers drawn into the first ``k`` rows do not depend on the room)."""
        rows = min(len(self.idx), max(k, 2 * len(self.drop)))
        self.noise, self.drop = np.empty((rows, 8)), np.empty(rows)


_THREAD = threading.local()


def scratch(n: int, in_range: bool) -> SensorScratch:
    """This thread's :class:`SensorScratch` for ``n`` agents and the kind of draws (two
    threads never share one: each steps its own agents)."""
    table: dict[tuple[int, bool], SensorScratch] | None = getattr(_THREAD, "table", None)
    if table is None:
        table = _THREAD.table = {}
    sh = table.get((n, in_range))
    if sh is None:
        sh = table[(n, in_range)] = SensorScratch(n, in_range)
    return sh


class Sensor:
    """Bearing / bearing-rate / range / range-rate sensor of agent ``index``."""

    def __init__(
        self,
        index: int,
        agent_id: int,
        n: int,
        sensing: SensingConfig,
        sensing_range_m: float,
        seed: int,
    ) -> None:
        self.index = index
        self.n = n
        self.range = float(sensing_range_m)
        self.sig = np.array(
            [  # noise standard deviations (rad, rad/s, m, m/s)
                sensing.bearing_noise_rad,
                sensing.bearing_rate_noise_radps,
                sensing.distance_noise_m,
                sensing.range_rate_noise_mps,
            ],
            dtype=float,
        )
        self._sig = tuple(float(x) for x in self.sig)  # plain floats: no numpy scalars
        self.dropout = float(sensing.dropout_prob)
        self.rng = np.random.default_rng([int(seed), int(agent_id), 0x5E])
        self.in_range_only = sensing.noise_draws is NoiseDraws.IN_RANGE
        # the kernels' call sites: truth through rows3, the rest the sensor's own buffers
        self._range = CallSite(range_index)
        self._in_range = CallSite(measure_in_range_into)
        self._every = CallSite(measure_into)

    def measure(self, p: np.ndarray, v: np.ndarray) -> Measurements:
        """Measurements from ground-truth (N,3) ENU positions (m) and velocities (m/s).

        The noise is drawn here (N×8 standard normals, then N uniforms, or as many rows as
        agents in range: module docstring); the geometry, the noisy measurements and the
        validity mask are the compiled
        :func:`offboard.estimation.sensing_kernel.measure_into`.

        The result is this thread's :class:`SensorScratch`'s, its arrays rewritten in place
        by the next call of any sensor of the same size and kind of draws in the thread,
        so a caller that keeps them past its step copies them. With ``noise_draws =
        "in_range"`` the cost follows the agents in range: the next call rewrites only the
        rows in range then and those this call wrote
        (:func:`~offboard.estimation.sensing_kernel.measure_in_range_into`).
        """
        n = self.n
        p, v = np.asarray(p), np.asarray(v)
        if p.shape != (n, 3) or v.shape != (n, 3):  # the kernel writes n rows, unchecked
            raise ValueError(f"truth of shapes {p.shape} and {v.shape}, expected ({n}, 3)")
        sb, sr, sd, sdd = self._sig
        sh = scratch(n, self.in_range_only)
        out = sh.out
        if self.in_range_only:
            p, v = rows3(p), rows3(v)
            k = self._range.call(p, self.index, self.range, sh.idx)
            if k > len(sh.drop):
                sh.draw_rows(k)
            noise = self.rng.standard_normal(out=sh.noise[:k])
            drop = self.rng.random(out=sh.drop[:k])
            k = self._in_range.call(
                p, v, self.index, noise, drop, sh.idx, k, sh.prev, sh.n_prev,
                sb, sr, sd, sdd, self.range, self.dropout, out.valid, out.g, out.g_dot,
                out.d, out.d_dot, out.rel_p, out.rel_v,
            )
            # its own row was written too (k < N: the agent is never in its own range)
            sh.prev[k] = self.index
            sh.n_prev = k + 1
            return out
        noise = self.rng.standard_normal(out=sh.noise)
        drop = self.rng.random(out=sh.drop)
        self._every.call(
            rows3(p), rows3(v), self.index, noise, drop, sb, sr, sd, sdd, self.range,
            self.dropout, out.valid, out.g, out.g_dot, out.d, out.d_dot, out.rel_p, out.rel_v,
        )
        return out


class DropoutHold:
    """Keeps a dropped pair in the safety constraints for ``hold_s`` seconds.

    A pair dropped this step but sensed within ``hold_s`` is extrapolated with its last
    measured relative velocity (dropouts must not switch a barrier off). ``enabled`` is
    False when the scenario has no dropouts (then nothing is tracked). The bookkeeping is
    the compiled :func:`offboard.estimation.sensing_kernel.hold_kernel`.
    """

    def __init__(self, n: int, index: int, hold_s: float, enabled: bool) -> None:
        self.index = index
        self.hold_s = hold_s
        self.enabled = enabled
        # per agent: when last sensed and what; none kept when disabled (57 kB per
        # follower at a thousand agents, never read)
        rows = n if enabled else 0
        self._last_seen = np.full(rows, -np.inf)
        self._last_rp = np.zeros((rows, 3))
        self._last_rv = np.zeros((rows, 3))

    def pairs(
        self, t: float, valid: np.ndarray, rel_p: np.ndarray, rel_v: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(sel, rp, rv): indices of the pairs to constrain at ``t`` (s) and the (N,3)
        relative positions p_j − p_i (m) / velocities (m/s) to use for them."""
        if not self.enabled:
            return valid.nonzero()[0], rel_p, rel_v
        sel, rp_s, rv_s, n_held = hold_kernel(
            float(t), bools(valid),
            f64(rel_p), f64(rel_v),
            self._last_seen, self._last_rp, self._last_rv, self.index, float(self.hold_s),
        )
        if n_held == 0:
            return sel, rel_p, rel_v
        return sel, rp_s, rv_s
