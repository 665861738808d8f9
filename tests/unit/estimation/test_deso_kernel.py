"""The compiled DESO period (offboard.estimation.deso_kernel) against the numpy formulation it
replaced: the same observer to rounding, over random states, neighbour sets (the empty set
too: the dead-reckoned period), innovations inside and outside the adaptation gate, with the
adaptive law on and off.

The oracle below is the previous numpy implementation kept verbatim (compact): the adaptive
model of ``offboard.estimation.deso_adaptive`` (C ``pow``, numpy ``clip``) and ``DESO.update``,
``coast`` and ``lumped`` (``einsum`` sums, BLAS ``@``). The matrices of a neighbour set
are the class's own (numpy ``expm`` setup, unchanged). The kernels sum the products left
to right and cube by products, so agreement is to rounding, not to the bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import CUBE8  # noqa: E402

from offboard.estimation.bearing import formation_from_scenario
from offboard.estimation.deso import (
    DESO,
    F_HAT_MAX,
    GATE_E1,
    GATE_E2,
    GATE_HOLD_S,
    V_EVAL_MAX,
    ZETA_HI,
    ZETA_LO,
    adapt_step,
    model_accel,
    regressor_t_times,
)
from offboard.estimation.peer_table import rows_of
from swarm_common.scenario.model import load_scenario

RTOL = ATOL = 1e-12


# --- the previous numpy implementation (oracle) ----------------------------------------
def _v_eval_np(z2: np.ndarray) -> tuple[float, float, float]:
    vx, vy, vz = (float(c) for c in z2)
    nv = math.sqrt(vx * vx + vy * vy + vz * vz)
    if not math.isfinite(nv):
        return 0.0, 0.0, 0.0
    if nv > V_EVAL_MAX:
        s = V_EVAL_MAX / nv
        return vx * s, vy * s, vz * s
    return vx, vy, vz


def model_accel_np(z1: np.ndarray, z2: np.ndarray, zeta: np.ndarray, h: float) -> np.ndarray:
    vx, vy, vz = _v_eval_np(z2)
    z0, z1_, z2_, z3_, z4, z5 = (float(c) for c in zeta)
    nv = math.sqrt(vx * vx + vy * vy + vz * vz)
    ge = math.exp(-max(float(z1[2]), 0.0) / h)
    k = z1_ + z2_ * nv
    fx = z0 - k * vx - z3_ * vx**3 - z5 * vy
    fy = z0 - k * vy - z3_ * vy**3 + z5 * vx
    fz = z0 - k * vz - z3_ * vz**3 + z4 * ge
    nf = math.sqrt(fx * fx + fy * fy + fz * fz)
    if nf > F_HAT_MAX:
        s = F_HAT_MAX / nf
        fx, fy, fz = fx * s, fy * s, fz * s
    return np.array([fx, fy, fz])


def regressor_t_times_np(
    z1: np.ndarray, z2: np.ndarray, e: np.ndarray, h: float
) -> tuple[np.ndarray, float]:
    vx, vy, vz = _v_eval_np(z2)
    ex, ey, ez = float(e[0]), float(e[1]), float(e[2])
    v2 = vx * vx + vy * vy + vz * vz
    nv = math.sqrt(v2)
    ve = vx * ex + vy * ey + vz * ez
    ge = math.exp(-max(float(z1[2]), 0.0) / h)
    phte = np.array(
        [ex + ey + ez, -ve, -nv * ve, -(vx**3 * ex + vy**3 * ey + vz**3 * ez), ge * ez,
         -vy * ex + vx * ey]
    )
    fro2 = 3.0 + v2 + v2 * v2 + (vx**6 + vy**6 + vz**6) + ge * ge + vx * vx + vy * vy
    return phte, fro2


def adapt_step_np(zeta: np.ndarray, phte: np.ndarray, fro2: float, mu: float, sigma: float,
                  dt: float) -> np.ndarray:
    step = phte / (1.0 + fro2) + sigma * zeta
    if not np.isfinite(step).all():
        return zeta
    return np.clip(zeta - dt * mu * step, ZETA_LO, ZETA_HI)


class NumpyDESO:
    """The previous DESO.update / coast / lumped over the state of a :class:`DESO`
    (its matrices, weights and gains; the state is copied in and out)."""

    def __init__(self, obs: DESO) -> None:
        self.obs = obs
        self.z1, self.z2, self.z3 = obs.z1.copy(), obs.z2.copy(), obs.z3.copy()
        self.zeta, self.converged_s = obs.zeta.copy(), obs.converged_s
        self.last_e1, self.last_e2 = obs.last_e1.copy(), obs.last_e2.copy()
        self.n_used, self._f_hat = obs.n_used, obs._f_hat

    def _gate_open(self) -> bool:
        e1 = math.sqrt(float(self.last_e1.dot(self.last_e1)))
        e2 = math.sqrt(float(self.last_e2.dot(self.last_e2)))
        if e1 <= GATE_E1 and e2 <= GATE_E2:
            self.converged_s += self.obs.dt
        else:
            self.converged_s = 0.0
        return self.converged_s >= GATE_HOLD_S - 1e-9

    def lumped(self) -> np.ndarray:
        self._f_hat = model_accel_np(self.z1, self.z2, self.zeta, self.obs.h)
        return self.z3 + self._f_hat

    def coast(self, u_sub: np.ndarray) -> None:
        o = self.obs
        self._f_hat = None
        for s in range(o.substeps):
            acc = self.z3 + model_accel_np(self.z1, self.z2, self.zeta, o.h) + u_sub[s]
            self.z1 = self.z1 + o.delta * self.z2 + 0.5 * o.delta**2 * acc
            self.z2 = self.z2 + o.delta * acc

    def update(self, rel_pos, rel_vel, valid, rows, have, u_sub) -> None:  # type: ignore[no-untyped-def]
        """As DESO.update; the neighbours' data taken out of the rows into dicts first."""
        nbr_p = {j: rows[j, 0:3].copy() for j in range(len(have)) if have[j]}
        nbr_v = {j: rows[j, 3:6].copy() for j in nbr_p}
        o = self.obs
        f_cached, self._f_hat = self._f_hat, None
        used = tuple(j for j in o.nbrs if valid[j] and j in nbr_p)
        self.n_used = len(used)
        if not used:
            self.converged_s = 0.0
            self.coast(u_sub)
            return
        a_s, g, dmat = o._matrices(used)
        idx = list(used)
        pu = o._stacked_weights(used)
        zp = np.array([nbr_p[j] for j in idx])
        zv = np.array([nbr_v[j] for j in idx])
        b1 = np.einsum("kij,kj->i", pu, zp - rel_pos[idx])
        b1d = np.einsum("kij,kj->i", pu, zv - rel_vel[idx])
        z1, z2 = self.z1, self.z2
        f_hat = f_cached if f_cached is not None else model_accel_np(z1, z2, self.zeta, o.h)
        self.last_e1 = dmat @ z1 - b1
        self.last_e2 = dmat @ z2 - b1d
        if o.mu > 0.0 and self._gate_open():
            phte, fro2 = regressor_t_times_np(z1, z2, self.last_e2, o.h)
            self.zeta = adapt_step_np(self.zeta, phte, fro2, o.mu, o.sigma, o.dt)
        x = np.concatenate([z1, z2, self.z3, b1, b1d])
        x = a_s @ x + g @ (np.asarray(u_sub, dtype=float) + f_hat).reshape(-1)
        self.z1, self.z2, self.z3 = x[0:3].copy(), x[3:6].copy(), x[6:9].copy()


# --- comparisons -----------------------------------------------------------------------
def _close(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.allclose(a, b, rtol=RTOL, atol=ATOL))


def _assert_same(obs: DESO, ref: NumpyDESO, what: object) -> None:
    for name in ("z1", "z2", "z3", "zeta", "last_e1", "last_e2"):
        assert _close(getattr(obs, name), getattr(ref, name)), (what, name)
    assert obs.n_used == ref.n_used, what
    assert math.isclose(obs.converged_s, ref.converged_s, rel_tol=RTOL, abs_tol=ATOL), what


@pytest.fixture(scope="module")
def cube8():  # type: ignore[no-untyped-def]
    sc = load_scenario(CUBE8)
    form = formation_from_scenario(sc)
    return sc, form, form.desired_positions(sc.initial_positions()[form.leader_idx])


@pytest.mark.full
def test_adaptive_model_equals_numpy() -> None:
    rng = np.random.default_rng(5)
    for trial in range(3000):
        scale = 10.0 ** rng.uniform(-2, 1.5)  # speeds below and above V_EVAL_MAX
        z1, z2, e = rng.normal(0, scale, 3), rng.normal(0, scale, 3), rng.normal(0, scale, 3)
        if trial % 7 == 0:
            z1[2] = -abs(z1[2])  # below ground: the ground-effect factor is exp(0)
        zeta = rng.uniform(ZETA_LO, ZETA_HI) * rng.choice([0.01, 1.0])
        h = float(rng.uniform(0.3, 1.5))
        assert _close(model_accel(z1, z2, zeta, h), model_accel_np(z1, z2, zeta, h)), trial
        phte, fro2 = regressor_t_times(z1, z2, e, h)
        phte_np, fro2_np = regressor_t_times_np(z1, z2, e, h)
        assert _close(phte, phte_np) and math.isclose(fro2, fro2_np, rel_tol=RTOL), trial
        mu, sigma, dt = float(rng.uniform(0, 3)), float(rng.uniform(0, 0.5)), 0.02
        new = adapt_step(zeta, phte_np, fro2_np, mu, sigma, dt)
        assert _close(new, adapt_step_np(zeta, phte_np, fro2_np, mu, sigma, dt)), trial
    inf = np.full(3, np.inf)  # non-finite inputs take the same guards
    assert np.array_equal(np.isnan(model_accel(np.zeros(3), inf, ZETA_HI, 0.8)),
                          np.isnan(model_accel_np(np.zeros(3), inf, ZETA_HI, 0.8)))
    assert _close(model_accel(np.zeros(3), inf, ZETA_HI, 0.8),
                  model_accel_np(np.zeros(3), inf, ZETA_HI, 0.8))
    bad = np.array([np.nan, 0, 0, 0, 0, 0])
    zeta = np.full(6, 0.05)
    assert np.array_equal(adapt_step(zeta, bad, 1.0, 1.0, 0.1, 0.02), zeta)


@pytest.mark.full
@pytest.mark.parametrize("anchor,kappa,mu", [
    (0.0, (0.0, 0.0), 0.0), (1.0, (1.0, 4.0), 0.0), (1.0, (1.0, 4.0), 0.5),
    (0.0, (0.0, 0.0), 2.0),
])
def test_one_period_equals_numpy(cube8, anchor, kappa, mu) -> None:  # type: ignore[no-untyped-def]
    """From the same state, one period (update with random neighbour sets and data, the
    empty set included, or coast) gives the same state to rounding. The gate's timer is
    drawn around GATE_HOLD_S and the data are near or far from consistent, so ζ̂ both
    adapts and stays frozen."""
    sc, form, p = cube8
    rng = np.random.default_rng(int(10 * mu + anchor))
    counts = {"adapted": 0, "frozen": 0, "coast": 0}
    for i in form.follower_idx:
        obs = DESO(form, i, tuple(sc.observer.beta), mu, 0.15, 4, 0.02, 0.8, p[i], np.zeros(3),
                   anchor, kappa)
        for trial in range(150):
            truth = p + rng.normal(0, 0.5, p.shape)
            vel = rng.normal(0, 2.0, p.shape)
            noise = rng.choice([0.001, 0.05, 1.0])
            obs.z1 = truth[i] + rng.normal(0, noise, 3)
            obs.z2 = vel[i] + rng.normal(0, noise, 3)
            obs.z3 = rng.normal(0, 0.5, 3)
            obs.zeta = rng.uniform(ZETA_LO, ZETA_HI)
            obs.converged_s = float(rng.choice([0.0, GATE_HOLD_S - 0.02, GATE_HOLD_S + 0.5]))
            ref = NumpyDESO(obs)
            valid = rng.random(sc.n) < rng.choice([0.0, 0.5, 1.0])
            valid[i] = False
            nbr_p = {j: truth[j] + rng.normal(0, noise, 3) for j in obs.nbrs if rng.random() < 0.9}
            nbr_v = {j: vel[j] + rng.normal(0, noise, 3) for j in nbr_p}
            u_sub = rng.normal(0, 3.0, (4, 3))
            rel_p, rel_v = truth - truth[i], vel - vel[i]
            if rng.random() < 0.7:
                assert _close(obs.lumped(), ref.lumped()), (i, trial)
            if rng.random() < 0.1:
                obs.coast(u_sub)
                ref.coast(u_sub)
                counts["coast"] += 1
            else:
                zeta0 = obs.zeta.copy()
                rows, have = rows_of(sc.n, nbr_p, nbr_v)
                obs.update(rel_p, rel_v, valid, rows, have, u_sub)
                ref.update(rel_p, rel_v, valid, rows, have, u_sub)
                counts["adapted" if not np.array_equal(obs.zeta, zeta0) else "frozen"] += 1
            _assert_same(obs, ref, (i, trial))
    assert counts["frozen"] > 0 and counts["coast"] > 0
    assert (counts["adapted"] > 0) == (mu > 0.0)


@pytest.mark.full
@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_trajectories_equal_numpy(cube8, mu) -> None:  # type: ignore[no-untyped-def]
    """All followers over 600 periods of a moving formation with noisy, dropped
    measurements: the compiled and the numpy observers stay equal to rounding (the
    observer contracts, so rounding differences do not grow)."""
    sc, form, p0 = cube8
    rng = np.random.default_rng(7)
    dt, sub = 0.02, 4
    obs = {i: DESO(form, i, tuple(sc.observer.beta), mu, 0.15, sub, dt, 0.8,
                   p0[i] + rng.normal(0, 0.3, 3), np.zeros(3), 1.0, (1.0, 4.0))
           for i in form.follower_idx}
    ref = {i: NumpyDESO(o) for i, o in obs.items()}
    dist = np.array([0.2, -0.1, 0.3])
    for k in range(600):
        t = k * dt
        p = p0 + np.array([np.sin(0.3 * t), np.cos(0.2 * t), 0.1 * t])
        v = np.tile([0.3 * np.cos(0.3 * t), -0.2 * np.sin(0.2 * t), 0.1], (sc.n, 1))
        u_sub = np.tile(-dist, (sub, 1)) + rng.normal(0, 0.05, (sub, 3))
        pub_o = {i: (o.z1, o.z2) for i, o in obs.items()}
        pub_r = {i: (r.z1, r.z2) for i, r in ref.items()}
        for li in form.leader_idx:
            pub_o[li] = pub_r[li] = (p[li], v[li])
        for i in form.follower_idx:
            valid = rng.random(sc.n) > 0.1
            valid[i] = False
            rel_p = p - p[i] + rng.normal(0, 0.01, p.shape)
            rel_v = v - v[i] + rng.normal(0, 0.01, p.shape)
            for o, r in ((obs[i], pub_o), (ref[i], pub_r)):
                o.lumped()
                rows, have = rows_of(sc.n, {j: r[j][0] for j in obs[i].nbrs},
                                     {j: r[j][1] for j in obs[i].nbrs})
                o.update(rel_p, rel_v, valid, rows, have, u_sub)
            _assert_same(obs[i], ref[i], (i, k))
    if mu > 0.0:
        assert any(np.any(o.zeta != 0.0) for o in obs.values())  # the law did run


def test_used_mask_gives_the_neighbours_read_in_python() -> None:
    """The compiled neighbour set (deso_kernel.used_mask, its sets cached by mask) is the
    one a Python pass over the masks finds, over random masks and neighbour lists up to
    the mask's limit; past it the DESO takes the Python pass; an index outside the masks
    raises."""
    from offboard.estimation.deso_kernel import MASK_NEIGHBOURS, used_mask

    sc = load_scenario(str(CUBE8))
    form = formation_from_scenario(sc)
    i = form.follower_idx[0]
    obs = DESO(form, i, tuple(sc.observer.beta), 0.0, 0.15, 4, 0.02, 0.8, np.zeros(3),
               np.zeros(3))
    rng = np.random.default_rng(7)
    for _ in range(200):
        valid, have = rng.random(sc.n) < 0.6, rng.random(sc.n) < 0.8
        want = tuple(j for j in obs.nbrs if valid[j] and have[j])
        assert obs._used(valid, have) == want
        assert obs._used(valid.tolist(), have.astype(np.uint8)) == want  # other array types
    for k in (1, 17, MASK_NEIGHBOURS):
        n = 3 * k
        nbrs = np.sort(rng.choice(n, k, replace=False)).astype(np.int64)
        valid, have = rng.random(n) < 0.5, rng.random(n) < 0.5
        m = used_mask(nbrs, valid, have)
        assert [int(j) for r, j in enumerate(nbrs) if m >> r & 1] == [
            int(j) for j in nbrs if valid[j] and have[j]]
    with pytest.raises(ValueError, match="outside"):
        used_mask(np.array([0, 9], dtype=np.int64), np.ones(5, bool), np.ones(5, bool))
    many = list(range(MASK_NEIGHBOURS + 1))
    obs.nbrs, obs._mask = many, None  # what a DESO with more neighbours than that holds
    valid = rng.random(len(many)) < 0.5
    assert obs._used(valid, np.ones(len(many), bool)) == tuple(np.nonzero(valid)[0].tolist())
