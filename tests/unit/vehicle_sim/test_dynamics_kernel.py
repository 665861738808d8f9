"""The compiled physics step (vehicle_sim.physics.dynamics_kernel) against the numpy step it
replaced: the same step to rounding, from identical states (single steps over random
states with held vehicles and ground contact) and over short rollouts with random
commands, so the compiled simulator is the same simulator.

The oracle below is the previous numpy implementation of ``SwarmDynamics.step`` (with its
``thrust_accel``, ``lumped_accel`` and collision bookkeeping) kept verbatim, as functions
of a :class:`SwarmDynamics`. The kernel differs from it in the last bit only: the C
library's ``exp`` against numpy's AVX-512 one, cubes as products against numpy's ``pow``
(module docstring of vehicle_sim.physics.dynamics_kernel).
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from conftest import CUBE8

from swarm_common.fastnp import einsum
from swarm_common.scenario.model import load_scenario
from vehicle_sim.physics.dynamics import SwarmDynamics, regressor

# the oracle: the previous numpy step, verbatim ----------------------------------------


def thrust_accel_np(self: SwarmDynamics) -> np.ndarray:
    att = self.att
    c, s = np.cos(att), np.sin(att)
    cr, cp, cy = c[:, 0], c[:, 1], c[:, 2]
    sr, sp, sy = s[:, 0], s[:, 1], s[:, 2]
    b3 = np.empty((len(att), 3))
    b3[:, 0] = cy * sp * cr + sy * sr
    b3[:, 1] = sy * sp * cr - cy * sr
    b3[:, 2] = cp * cr
    b3 *= (self.thrust / self.mass)[:, None]
    return b3


def lumped_accel_np(self: SwarmDynamics, t: float | None = None) -> np.ndarray:
    tt = self.t if t is None else t
    v, z = self.v, self.zeta
    speed = np.sqrt(einsum("ij,ij->i", v, v))[:, None]
    f = z[:, 0:1] - (z[:, 1:2] + z[:, 2:3] * speed) * v - z[:, 3:4] * v**3
    f[:, 2] += z[:, 4] * np.exp(-np.maximum(self.p[:, 2], 0.0) / self.ge_height)
    f[:, 0] -= z[:, 5] * v[:, 1]
    f[:, 1] += z[:, 5] * v[:, 0]
    amp, m, wt = self.dist_amp, self.mass, self.dist_omega * tt
    dc, ds = amp * math.cos(wt) / m, amp * math.sin(wt) / m
    f += (dc, ds, ds)
    return f


def pair_distances_np(self: SwarmDynamics) -> np.ndarray:
    p = self.p
    d = p[:, None, :] - p[None, :, :]
    d *= d
    return np.sqrt(np.add.reduce(d, axis=-1))


def step_np(self: SwarmDynamics) -> None:
    dt = self.dt
    cmd_att, cmd_thrust = self.cmd_att, self.cmd_thrust
    self.att = cmd_att + (self.att - cmd_att) * self._a_att
    self.thrust = cmd_thrust + (self.thrust - cmd_thrust) * self._a_f
    acc = thrust_accel_np(self)
    acc[:, 2] -= self.g
    acc += lumped_accel_np(self)
    acc *= dt
    v_new = self.v + acc
    p_new = v_new * dt
    p_new += self.p
    ground = p_new[:, 2] < 0.0
    if ground.any():
        p_new[ground, 2] = 0.0
        v_new[ground, 2] = np.maximum(v_new[ground, 2], 0.0)
        v_new[ground, :2] *= 0.0
    held = self.held
    if held.any():
        free = ~held
        self.v = np.where(free[:, None], v_new, self.v)
        self.p = np.where(free[:, None], p_new, self.p)
    else:
        self.v, self.p = v_new, p_new
    self.t = (self.step_count + 1) * dt
    self.step_count += 1
    dist = pair_distances_np(self)
    self._step_dist = dist
    contact = dist < self.collision_radius
    np.fill_diagonal(contact, False)
    new = contact & ~self._in_contact
    if new.any():
        for i, j in zip(*np.nonzero(np.triu(new, 1)), strict=True):
            self.collisions += 1
            self.collision_pairs.append((self.t, self.ids[i], self.ids[j]))
    self._in_contact = contact


# ---------------------------------------------------------------------------------------

TOL = {"rtol": 1e-13, "atol": 1e-13}


@pytest.fixture(scope="module")
def cube8():
    return load_scenario(CUBE8)


def assert_same(new: SwarmDynamics, old: SwarmDynamics, tol: dict[str, float], tag: object
                ) -> None:
    for name in ("p", "v", "att", "thrust"):
        a, b = getattr(new, name), getattr(old, name)
        assert a.shape == b.shape and a.dtype == b.dtype, (name, tag)
        assert np.allclose(a, b, **tol), (name, tag, np.max(np.abs(a - b)))
    # the lags: the same operations, but two implementations: within ``tol`` above
    assert np.allclose(new._step_dist, old._step_dist, **tol), tag
    assert math.isclose(new.step_min_distance(), float(old._step_dist[old._iu].min()),
                        rel_tol=tol["rtol"], abs_tol=tol["atol"]), tag
    assert np.array_equal(new._in_contact, old._in_contact), tag
    assert (new.t, new.step_count, new.collisions) == (old.t, old.step_count, old.collisions)
    assert new.collision_pairs == old.collision_pairs, tag


def random_state(dyn: SwarmDynamics, rng: np.random.Generator) -> None:
    """Positions from clustered (collisions) to spread, some at or below the ground;
    velocities, attitudes, thrusts, commands, held flags, contacts at random."""
    n = dyn.n
    dyn.p = rng.normal(0.0, 1.0, (n, 3)) * rng.uniform(0.05, 3.0)
    dyn.p[:, 2] += rng.uniform(-0.02, 2.0, n) * rng.integers(0, 2, n)
    dyn.v = rng.normal(0.0, 3.0, (n, 3))
    dyn.att = rng.uniform(-0.6, 0.6, (n, 3)) + rng.uniform(-np.pi, np.pi, (n, 3)) * [0, 0, 1]
    dyn.thrust = rng.uniform(0.0, dyn.f_max, n)
    for i in range(n):
        dyn.set_command(i, *rng.uniform(-1.0, 1.0, 3), rng.uniform(-5.0, 1.2 * dyn.f_max))
    dyn.held = rng.uniform(size=n) < 0.3
    c = rng.uniform(size=(n, n)) < 0.2
    dyn._in_contact = np.triu(c, 1) | np.triu(c, 1).T
    dyn.t = float(rng.uniform(0.0, 100.0))
    dyn.step_count = int(round(dyn.t / dyn.dt))


@pytest.mark.full
def test_single_steps_equal_numpy_step(cube8) -> None:
    rng = np.random.default_rng(7)
    for trial in range(2000):
        new = SwarmDynamics(cube8, seed=trial)
        random_state(new, rng)
        old = copy.deepcopy(new)
        assert np.allclose(new.lumped_accel(), lumped_accel_np(old), **TOL), trial
        t = float(rng.uniform(0.0, 50.0))
        assert np.allclose(new.lumped_accel(t), lumped_accel_np(old, t), **TOL), trial
        # the same operations in two implementations: within TOL (tests/reference/close.py)
        assert np.allclose(new.thrust_accel(), thrust_accel_np(old), **TOL), trial
        assert np.allclose(new.pair_distances(), pair_distances_np(old), **TOL), trial
        new.step()
        step_np(old)
        assert_same(new, old, TOL, trial)


def test_lumped_accel_is_the_regressor_sum(cube8) -> None:
    """Φ(p, v) ζ + d(t)/m with the shared regressor (swarm_common.unmodeled)."""
    rng = np.random.default_rng(3)
    dyn = SwarmDynamics(cube8, seed=5)
    random_state(dyn, rng)
    f = np.einsum("nij,nj->ni", regressor(dyn.p, dyn.v, dyn.ge_height), dyn.zeta)
    wt = dyn.dist_omega * dyn.t
    f += dyn.dist_amp / dyn.mass * np.array([math.cos(wt), math.sin(wt), math.sin(wt)])
    assert np.allclose(dyn.lumped_accel(), f, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("ground_start", [False, True])
def test_rollouts_equal_numpy_steps(cube8, ground_start: bool) -> None:
    """Short rollouts (50 physics steps = 0.25 s, random commands every 4 steps, vehicles
    released at random, landings) from a common state, 40 of them: 2000 steps each way."""
    rng = np.random.default_rng(19 + ground_start)
    new = SwarmDynamics(cube8, seed=3, held=True)
    if ground_start:
        new.p[:, 2] = 0.0
        new.v[:] = 0.0
    for _ in range(40):
        old = copy.deepcopy(new)
        for k in range(50):
            if k % 4 == 0:
                for i in range(new.n):
                    cmd = (*rng.uniform(-0.4, 0.4, 3), rng.uniform(0.0, 1.1 * new.f_max))
                    new.set_command(i, *cmd)
                    old.set_command(i, *cmd)
                if rng.uniform() < 0.2:
                    i = int(rng.integers(0, new.n))
                    new.release(i)
                    old.release(i)
            new.step()
            step_np(old)
            assert_same(new, old, {"rtol": 1e-11, "atol": 1e-11}, k)
    assert not new.held.all()


def test_advance_period_equals_single_steps(cube8) -> None:
    """A control period's sub-steps in one compiled call give the bits of as many
    :meth:`step` calls: state, contacts, distances, clock, collisions with their times,
    and the minimum pair distance over the sub-steps, from random (clustered, colliding)
    states with random commands."""
    rng = np.random.default_rng(23)
    entered = later = 0
    for trial in range(300):
        one = SwarmDynamics(cube8, seed=trial)
        random_state(one, rng)
        period = copy.deepcopy(one)
        n_steps = int(rng.integers(1, 6))
        md = math.inf
        for _ in range(n_steps):
            one.step()
            md = min(md, one.step_min_distance())
        got = period.advance_period(n_steps)
        assert got == md or (math.isnan(got) and math.isnan(md)), trial
        for name in ("p", "v", "att", "thrust", "_step_dist", "_in_contact"):
            assert np.array_equal(getattr(period, name), getattr(one, name)), (name, trial)
        assert period.step_min_distance() == one.step_min_distance(), trial
        assert (period.t, period.step_count) == (one.t, one.step_count), trial
        assert period.collision_pairs == one.collision_pairs, trial
        assert period.collisions == one.collisions, trial
        entered += one.collisions
        first_end = (period.step_count - n_steps + 1) * period.dt
        later += sum(1 for c in one.collision_pairs if c[0] > first_end)
    assert entered > 50 and later > 0  # contacts are reached, in later sub-steps too (8)
    with pytest.raises(ValueError, match="n_steps 0"):
        SwarmDynamics(cube8, seed=0).advance_period(0)


def test_one_pass_contacts_equal_the_matrix_and_its_scans() -> None:
    """contacts_into gives, bit for bit, what the step made before from the full distance
    matrix: the matrix itself, the contact flags, the pairs entering contact (in the same
    order) and the minimum of the upper triangle; with coincident vehicles, pairs at the
    radius, NaN and inf positions, and contacts carried from the step before."""
    from vehicle_sim.physics.contacts_kernel import (
        contacts_into,
        min_upper_kernel,
        pair_distances_kernel,
    )

    rng = np.random.default_rng(12)
    radius = 0.3
    for trial in range(400):
        n = int(rng.integers(0, 12))
        p = rng.normal(0.0, 0.6, (n, 3))
        if n > 2 and trial % 4 == 0:
            p[1] = p[0]  # coincident
        if n > 2 and trial % 5 == 0:
            p[2] = p[0] + np.array([radius, 0.0, 0.0])  # at the radius
        if n > 3 and trial % 9 == 0:
            p[3, int(rng.integers(0, 3))] = rng.choice([math.nan, math.inf])
        before = rng.random((n, n)) < 0.3
        # the previous step's matrix scans, verbatim
        dist = pair_distances_kernel(p)
        want_contact, want_pairs = before.copy(), []
        for i in range(n):
            for j in range(n):
                c = i != j and dist[i, j] < radius
                if c and j > i and not want_contact[i, j]:
                    want_pairs.append([i, j])
                want_contact[i, j] = c
        got_contact, got_dist = before.copy(), np.full((n, n), 7.0)
        pairs = np.full((max(1, n * (n - 1) // 2), 2), -1, dtype=np.int64)
        count = np.array([int(np.triu(before, 1).sum())], dtype=np.int64)
        k, d_min = contacts_into(p, got_contact, radius, got_dist, pairs, count)
        assert count[0] == int(np.triu(want_contact, 1).sum()), trial
        assert np.array_equal(got_dist, dist, equal_nan=True), trial
        assert np.array_equal(got_contact, want_contact), trial
        assert pairs[:k].tolist() == want_pairs, trial
        want_min = min_upper_kernel(dist)
        assert d_min == want_min or (math.isnan(d_min) and math.isnan(want_min)), trial


def test_grid_contacts_equal_the_pass_over_every_pair() -> None:
    """Past GRID_MIN vehicles a step without a distance matrix finds its contacts on a
    grid: over sequences of steps (clusters that touch, drift apart and come back, a
    vehicle far away, coincident vehicles, one that is not finite), the same contact flags,
    the same pairs entering contact in the same order, the same count and the same
    minimum, bit for bit, as the pass over every pair."""
    from vehicle_sim.physics.contacts_kernel import CONTACT_ROOM, GRID_MIN, contacts_into

    rng = np.random.default_rng(44)
    radius = 0.3
    most = 0  # the most pairs in contact at once: past the grid's first room somewhere
    for trial in range(40):
        n = int(rng.integers(GRID_MIN + 1, 400))
        p = rng.uniform(-8.0, 8.0, (n, 3))
        p[: n // 4] = rng.normal(0.0, 0.5, (n // 4, 3))  # a dense cluster: contacts
        if trial % 3 == 0:
            p[n - 1] = [900.0, -700.0, 50.0]  # far from everyone
        if trial % 4 == 0:
            p[5] = p[6]  # coincident
        states = [(np.zeros((n, n), dtype=bool), np.zeros((0, 0)), np.zeros(1, np.int64)),
                  (np.zeros((n, n), dtype=bool), np.empty((n, n)), np.zeros(1, np.int64))]
        for step in range(6):
            if step == 5 and trial % 5 == 0:
                p[7, 1] = math.nan  # not finite: the grid gives way to the full pass
            got = []
            for contact, dist, count in states:
                pairs = np.full((n * (n - 1) // 2, 2), -1, dtype=np.int64)
                k, d_min = contacts_into(p, contact, radius, dist, pairs, count)
                got.append((k, d_min, pairs[:k].tolist(), contact.copy(), int(count[0])))
            (ka, ma, pa, ca, na), (kb, mb, pb, cb, nb) = got
            assert (ka, pa, na) == (kb, pb, nb), (trial, step)
            assert ma == mb or (math.isnan(ma) and math.isnan(mb)), (trial, step)
            assert np.array_equal(ca, cb), (trial, step)
            most = max(most, na)
            if step == 0:
                assert na > 0 or trial % 4, trial  # the cluster touches
            p = p + rng.normal(0.0, 0.15, p.shape)  # drift: some contacts end, some begin
            if step == 2:
                p[: n // 4] *= 3.0  # the cluster spreads: every contact may end
    assert most > CONTACT_ROOM, most
