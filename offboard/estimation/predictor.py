"""Neighbour data ageing: the last received estimate per agent, predicted to a requested
time (Departure 16, ``communication.max_age_s``; docs/estimation.md §4).

The desired state ξ is propagated by the exosystem
(:func:`offboard.estimation.reference.exo_propagator`);
the agent's offset from it (e1 = z1 − p*, e2 = z2 − v*) by the closed-loop error dynamics
``ë1 = −k_v ė1 − k_p' e1`` (the nominal controller's for followers, the leaders' PD for
leaders). Both are exact matrix exponentials, cached per step count.

* **Leaders** fly the exosystem's trajectory with their own PD and never yield, so their
  data is predicted through any outage and never dropped for its age (bound 0).
* **Followers** may be held by their safety filter or saturated, so the assumed closed
  loop can be wrong. Their prediction error is bounded by ``½ a_dev age²`` (m), with
  ``a_dev = a_max + ā* + c_r ‖(e1, e2)‖`` (m/s²): ``a_max`` bounds the follower's actual
  acceleration, ``ā*`` the exosystem's desired acceleration over the gap and
  ``c_r ‖(e1, e2)‖`` the assumed loop's own error acceleration. Their data is dropped
  once that bound exceeds ``drop_bound`` (m), or after ``max_age`` (s).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.linalg import expm

from offboard.estimation.peer_table import XI, XI_COL, Z1, Z2, EstimateBatch, PeerTable
from offboard.estimation.reference import exo_propagator, xi_a, xi_j, xi_p, xi_v
from offboard.records import NeighbourEstimate
from swarm_common.jit import CallSite, kernel

A_MAX_DEFAULT = 16.0  # m/s², follower acceleration bound: √3·u_max (8 m/s²) + 2 m/s² disturbance
DROP_BOUND_M = 1.0  # m, a follower's prediction is dropped once its error bound exceeds this
# s, data at most this much older than the requested time is current (age 0): a stamp
# t_k + dt computed by the sender and the receiver's (k + 1)·dt differ by rounding only
CURRENT_AGE_S = 1e-9
UNBOUNDED_AGE_S = 1.0  # s of propagators computed up front when max_age is unbounded

_EXO_CACHE: dict[tuple[float, float, int], np.ndarray] = {}
_ERR_CACHE: dict[tuple[float, float, float, int], np.ndarray] = {}
_CR_CACHE: dict[tuple[float, float], float] = {}

Prediction = tuple[np.ndarray, np.ndarray, np.ndarray]  # (p, v, ξ) of one agent


def error_accel_gain(kp: float, kv: float) -> float:
    """c_r = sup_{s ≥ 0} ‖[−k_p, −k_v] e^{A s}‖₂ (1/s²) for A = [[0, 1], [−k_p, −k_v]]:
    the largest acceleration of the assumed error loop per unit ‖(e1, e2)‖ at the start.
    Per axis ``|ë(s)| ≤ c_r |(e1, e2)|``, hence ``‖ë(s)‖ ≤ c_r √(‖e1‖² + ‖e2‖²)``."""
    key = (kp, kv)
    c = _CR_CACHE.get(key)
    if c is None:
        a = np.array([[0.0, 1.0], [-kp, -kv]])
        row = np.array([-kp, -kv])
        decay = max(1e-3, -float(np.max(np.linalg.eigvals(a).real)))
        ss = np.linspace(0.0, 12.0 / decay, 2001)
        step = expm(a * (ss[1] - ss[0]))
        m, c = np.eye(2), 0.0
        for _ in ss:
            c = max(c, float(np.linalg.norm(row @ m)))
            m = step @ m
        c *= 1.0 + 1e-3  # margin for the sampling of s
        _CR_CACHE[key] = c
    return c


class NeighbourPredictor:
    """Last received estimate per agent, predicted to a requested time (Departure 16).

    ``ids`` are the scenario's agent ids (the table's rows, :class:`PeerTable`; estimates of
    other ids are ignored); ``omega`` (rad/s) is the exosystem frequency, ``dt`` (s) the
    control period; ``fol_gains``/``lead_gains`` are (k_p', k_v) of the error dynamics of
    followers and leaders; ``max_age`` (s) caps the age of followers' data, ``a_max``
    (m/s²) bounds a follower's actual acceleration and ``drop_bound`` (m) is the error
    bound beyond which a follower's prediction is useless (see :meth:`bound_at`).
    """

    def __init__(self, ids: Sequence[int], omega: float, dt: float,
                 fol_gains: tuple[float, float], lead_gains: tuple[float, float],
                 max_age: float = math.inf, a_max: float = A_MAX_DEFAULT,
                 drop_bound: float = DROP_BOUND_M) -> None:
        self.ids = tuple(ids)
        self.index_of = {aid: j for j, aid in enumerate(self.ids)}
        self.table = PeerTable(len(self.ids))
        self.omega = omega
        self.dt = dt
        self.max_age = max_age  # followers' older data is dropped (communication.max_age_s)
        self.a_max = a_max
        self.drop_bound = drop_bound
        self.gains = {False: fol_gains, True: lead_gains}
        # per index: (the table's version of the row, a_dev of that row (m/s²))
        self._a_dev: dict[int, tuple[int, float]] = {}
        self._have = np.zeros(len(self.ids), dtype=np.bool_)  # predict_rows' mask
        self._mark = CallSite(mark_current)  # its arguments' types are fixed
        self._fill_caches()

    def _fill_caches(self) -> None:
        """Compute, now, what the first outage would otherwise compute inside the control
        loop: c_r of the followers' gains (:func:`error_accel_gain`) and the propagators
        of every step count up to ``max_age`` (:data:`UNBOUNDED_AGE_S` when it is
        unbounded). They are exact functions of the gains, ω, dt and the count, cached
        for the process, so a run's numbers are the same; only when they are computed
        changes. Left to the first outage, they took 10–22 ms of one control step (c_r's
        2001-point sweep and one matrix exponential per new count; in process, 2-core),
        and made the in-process runs' slowest 1 % of follower steps. Older data
        (a leader's, never dropped) still fills the caches as it comes."""
        error_accel_gain(*self.gains[False])
        horizon = self.max_age if math.isfinite(self.max_age) else UNBOUNDED_AGE_S
        for n in range(1, int(math.ceil(horizon / self.dt)) + 2):
            self.exo(n)
            self.err(False, n)
            self.err(True, n)

    @property
    def revision(self) -> int:
        """Bumped when an agent is first heard from or its ``cooperative`` flag changes:
        what a reader derives from who is heard and who cooperates is current while this
        is unchanged."""
        return self.table.revision

    @property
    def newest(self) -> float:
        """The newest stamp received from anyone (s; −inf before the first)."""
        return self.table.newest

    def exo(self, n: int) -> np.ndarray:
        """12×12 exosystem propagator over ``n`` control periods (cached)."""
        key = (self.omega, self.dt, n)
        m = _EXO_CACHE.get(key)
        if m is None:
            m = exo_propagator(self.omega, n * self.dt)
            _EXO_CACHE[key] = m
        return m

    def err(self, leader: bool, n: int) -> np.ndarray:
        """2×2 propagator of (e1, e2) over ``n`` control periods (cached)."""
        kp, kv = self.gains[leader]
        key = (kp, kv, self.dt, n)
        m = _ERR_CACHE.get(key)
        if m is None:
            m = expm(np.array([[0.0, 1.0], [-kp, -kv]]) * n * self.dt)
            _ERR_CACHE[key] = m
        return m

    def ingest(self, neighbours: Mapping[int, NeighbourEstimate], comm_ok: bool) -> None:
        """Keep the newest estimate per agent (an out-of-order older one is ignored; nothing
        while the link is down); the acceleration slots take theirs either way
        (:class:`PeerTable`)."""
        batch, idx = EstimateBatch.from_estimates(self.index_of, len(self.ids), neighbours)
        self.table.ingest(batch, idx, comm_ok)

    def ingest_batch(self, batch: EstimateBatch, idx: np.ndarray, comm_ok: bool) -> None:
        """:meth:`ingest` of the rows ``idx`` (scenario indices, int64) of ``batch``."""
        self.table.ingest(batch, idx, comm_ok)

    def a_dev_of(self, z1: np.ndarray, z2: np.ndarray, xi: np.ndarray) -> float:
        """Bound (m/s²) on the gap between a follower's actual acceleration and the one its
        prediction from (z1, z2, ξ) assumes: a_max + ā* + c_r ‖(e1, e2)‖ (module
        docstring). The exosystem's acceleration is a sinusoid per axis, so
        ‖a*(s)‖ ≤ ā* = √(‖a*₀‖² + ‖j*₀‖²/ω²) for all s."""
        a0, j0 = xi_a(xi), xi_j(xi)
        w2 = self.omega**2 if self.omega > 0.0 else 1.0
        a_star = math.sqrt(float(a0 @ a0) + float(j0 @ j0) / w2)
        e1 = z1 - xi_p(xi)
        e2 = z2 - xi_v(xi)
        kp, kv = self.gains[False]
        c_r = error_accel_gain(kp, kv)
        return self.a_max + a_star + c_r * math.sqrt(float(e1 @ e1) + float(e2 @ e2))

    def bound_at(self, j: int, t: float) -> float | None:
        """Bound (m) on the error of agent ``j``'s (scenario index) predicted position at
        ``t``, None if nothing was received. Leaders: 0 (exosystem and their own PD;
        docs/estimation.md). Followers: ½ a_dev age² (0 while the data is current, age ≤
        CURRENT_AGE_S); its velocity error is at most a_dev·age."""
        tab = self.table
        stamp = float(tab.t[j])
        if stamp == -math.inf:
            return None
        age = max(0.0, t - stamp)
        if tab.leader[j] or age <= CURRENT_AGE_S:
            return 0.0
        version = int(tab.version[j])
        got = self._a_dev.get(j)
        if got is None or got[0] != version:
            r = tab.rows[j]
            got = (version, self.a_dev_of(r[Z1], r[Z2], r[XI]))
            self._a_dev[j] = got
        return 0.5 * got[1] * age * age

    def velocity_bound_at(self, j: int, t: float) -> float:
        """Bound (m/s) on the error of agent ``j``'s predicted velocity at ``t``: a_dev·age
        for a follower (the derivative of :meth:`bound_at`), 0 for a leader or current
        data."""
        b = self.bound_at(j, t)
        if b is None or b <= 0.0:
            return 0.0
        return 2.0 * b / max(t - float(self.table.t[j]), 1e-9)

    def predict_rows(self, peers: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The rows of ``peers`` (scenario indices, int64) predicted to ``t``: (rows (N,
        ROW), have (N,) bool), ``have[j]`` where agent j's row is usable (:meth:`get_at`
        is not None). Data current at ``t`` (age ≤ CURRENT_AGE_S, the common case in
        lockstep) is read where it lies, the table itself; otherwise a copy holds the
        predictions of the others. Both are valid until the next ingest."""
        tab, have = self.table, self._have
        if self._mark.call(peers, tab.t, t, CURRENT_AGE_S, have) == 0:
            return tab.rows, have
        rows = tab.rows.copy()
        for j in peers.tolist():
            if have[j] or tab.t[j] == -math.inf:
                continue
            n = self._periods_ahead(j, t)
            if n is None:
                continue
            if n > 0:  # else the copy holds the row as received
                src = tab.rows[j]
                xi_n = self.exo(n) @ src[XI]  # numpy's product, as get_at's
                predict_row_into(src, xi_n, self.err(bool(tab.leader[j]), n), rows[j])
            have[j] = True
        return rows, have

    def get_at(self, j: int, t: float) -> Prediction | None:
        """(p, v, ξ) of agent ``j`` (scenario index) predicted to ``t``; None if never
        received or, for a follower, if older than ``max_age`` or its :meth:`bound_at`
        exceeds ``drop_bound`` (the agent then runs without that neighbour: the
        conservative behaviour for a silent or unpredictable neighbour; onboard sensing
        still feeds the safety filter). A leader's data is never dropped. Current data is
        returned as views of the table's row (valid until the next ingest)."""
        n = self._periods_ahead(j, t)
        if n is None:
            return None
        tab = self.table
        r = tab.rows[j]
        if n == 0:  # current data (bound 0): as received
            return r[Z1], r[Z2], r[XI]
        out = r.copy()
        xi_n = self.exo(n) @ r[XI]  # numpy's product (BLAS's order), as predict_rows's
        predict_row_into(r, xi_n, self.err(bool(tab.leader[j]), n), out)
        return out[Z1], out[Z2], out[XI]

    def constant_velocity_at(
        self, j: int, t: float,
    ) -> tuple[np.ndarray, np.ndarray, float, float] | None:
        """Agent ``j``'s (p (m), v (m/s)) at ``t`` with bounds on their errors (b_p m, b_v
        m/s), for a row that must hold against every state the other can be in (the dcbf
        rows of unsensed neighbours, offboard.agent.unsensed); None when its data is not
        usable. A leader's, and current data, as :meth:`get_at` gives them (exact: bounds
        0). A follower's older data at constant velocity from its last estimate,
        b_p = ½ a_max age², b_v = a_max age: the model's own bound takes
        a_dev = a_max + ā* + c_r ‖e‖ ≥ a_max, so this is the tighter claim. Its data is
        dropped as :meth:`get_at` drops it, with b_p as the bound."""
        tab = self.table
        age = t - float(tab.t[j])
        if bool(tab.leader[j]) or age <= CURRENT_AGE_S:
            got = self.get_at(j, t)
            return None if got is None else (got[0], got[1], 0.0, 0.0)
        b = 0.5 * self.a_max * age * age
        if self._stale(age) or b > self.drop_bound:
            return None
        row = tab.rows[j]
        return row[Z1] + row[Z2] * age, row[Z2], b, self.a_max * age

    def _stale(self, age: float) -> bool:
        """A follower's data of this age (s) is older than ``max_age``."""
        return age > self.max_age + 1e-9

    def _periods_ahead(self, j: int, t: float) -> int | None:
        """Control periods to predict agent ``j``'s row over to reach ``t``: 0 for data
        current at ``t`` (or less than half a period old), None when it is not usable
        (never received; a follower's older than ``max_age`` or beyond ``drop_bound``)."""
        tab = self.table
        stamp = float(tab.t[j])
        if stamp == -math.inf:
            return None
        age = t - stamp
        if age <= CURRENT_AGE_S:
            return 0
        if not bool(tab.leader[j]):
            if self._stale(age):
                return None
            b = self.bound_at(j, t)
            if b is not None and b > self.drop_bound:
                return None
        return max(0, int(round(age / self.dt)))


@kernel
def predict_row_into(src: np.ndarray, xi_n: np.ndarray, m: np.ndarray, out: np.ndarray) -> None:
    """The prediction of a row n periods ahead (:meth:`NeighbourPredictor.get_at` and
    :meth:`~NeighbourPredictor.predict_rows`), written into ``out`` (ROW,): from ``src`` =
    [z1, z2, z3, ξ] (m, m/s, m/s², ξ), ξ_n (12,) = the exosystem's propagator times ξ
    (given: numpy's product, BLAS's order) and m (2,2) the error loop's propagator,
    ``p = p*_n + m₀₀ e1 + m₀₁ e2``, ``v = v*_n + m₁₀ e1 + m₁₁ e2`` with ``e1 = z1 − p*``,
    ``e2 = z2 − v*``, and ξ_n; z3 is left as ``out`` holds it. The operations of the numpy
    formulation (kept in tests/unit/estimation/test_predictor.py) in its order, so the same bits."""
    for c in range(3):
        e1 = src[c] - src[XI_COL + c]
        e2 = src[3 + c] - src[XI_COL + 3 + c]
        p = xi_n[c] + m[0, 0] * e1 + m[0, 1] * e2
        v = xi_n[3 + c] + m[1, 0] * e1 + m[1, 1] * e2
        out[c] = p
        out[3 + c] = v
    for c in range(12):
        out[XI_COL + c] = xi_n[c]


@kernel
def mark_current(
    peers: np.ndarray, t_tab: np.ndarray, t: float, age_max: float, have: np.ndarray
) -> int:
    """For each ``j`` in ``peers``: ``have[j]`` = its last stamp ``t_tab[j]`` (s, −inf never
    heard) is at most ``age_max`` (s) before ``t``. Returns how many peers were heard but
    are not current (to be predicted)."""
    stale = 0
    for r in range(peers.shape[0]):
        j = peers[r]
        if not (0 <= j < t_tab.shape[0] and j < have.shape[0]):
            raise ValueError("mark_current: an index outside the table")
        cur = t - t_tab[j] <= age_max
        have[j] = cur
        if not cur and t_tab[j] > -math.inf:
            stale += 1
    return stale
