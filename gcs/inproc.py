"""In-process mission runner: dynamics + all agents in one process, lockstep.

Same order as the distributed run (design-notes "Lockstep, step by step"), step k:

1. truth(k) = float32(p, v) of the simulator (what the truth message carries);
2. every agent, in scenario order: ``agent.step(k, t_k, truth, neighbours(k−1), comm_ok)``
   where neighbours are the float32-rounded estimates published at step k−1 (valid for
   t_k); during an outage window (``communication.outages_s``) comm_ok is False;
3. each setpoint goes through the wire form (float32 quaternion + thrust_norm) and is
   decoded exactly as the simulator does (:func:`wire_to_command`) → ``set_command``;
4. the dynamics advance one control period (physics_hz/control_hz physics steps).

Everything that would cross a wire is rounded to float32 with :func:`f32` /
:func:`round_estimate`, so a distributed run can reproduce this one bit for bit.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gcs.metrics import Series, compute_metrics
from offboard.agent import FollowerAgent, NeighbourEstimate, make_agent
from offboard.bearing import formation_from_scenario
from swarm_common.frames import euler_enu_from_quat_ned, norm_to_thrust
from vehicle_sim.dynamics import SwarmDynamics


def f32(x: np.ndarray | float) -> np.ndarray:
    """Round to float32 and back to float64: the value after one trip over the wire.

    Use it on every value that crosses a process boundary (truth p/v, setpoint quaternion
    and thrust_norm, neighbour estimates) in both the in-process and the distributed run.
    """
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def wire_to_command(
    q_ned: np.ndarray, thrust_norm: float, thrust_max_n: float
) -> tuple[float, float, float, float]:
    """SET_ATTITUDE_TARGET payload → (roll, pitch, yaw, F) exactly as the simulator does it.

    ``roll, pitch, yaw = euler_enu_from_quat_ned(float32 q)``; ``F = norm_to_thrust(float32
    thrust_norm)``. The simulator's MAVLink side must call this same function.
    """
    roll, pitch, yaw = euler_enu_from_quat_ned(np.asarray(q_ned, dtype=np.float32))
    return roll, pitch, yaw, norm_to_thrust(np.float32(thrust_norm), thrust_max_n)


def round_estimate(e: NeighbourEstimate) -> NeighbourEstimate:
    """A published estimate as the receivers see it (float32 vectors; t kept exact)."""
    return NeighbourEstimate(e.id, e.t, f32(e.z1), f32(e.z2), f32(e.z3), f32(e.xi), e.is_leader)


def in_outage(t: float, outages: tuple[tuple[float, float], ...]) -> bool:
    return any(a <= t < b for a, b in outages)


@dataclass
class MissionResult:
    scenario: str
    method: str
    seed: int
    metrics: dict
    series: Series
    gains: list[str] = field(default_factory=list)
    collision_pairs: list = field(default_factory=list)

    def save(self, out_dir: str | Path) -> None:
        """Write metrics.json and series.npz to ``out_dir``."""
        import json

        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        meta = {
            "scenario": self.scenario,
            "method": self.method,
            "seed": self.seed,
            "metrics": self.metrics,
            "gains": self.gains,
            "collision_pairs": [list(map(float, c)) for c in self.collision_pairs],
        }
        (d / "metrics.json").write_text(json.dumps(meta, indent=2) + "\n")
        np.savez_compressed(d / "series.npz", **self.series.as_dict())


def run_inproc(
    sc,
    method: str | None = None,
    seed: int | None = None,
    duration: float | None = None,
    progress: bool = False,
) -> MissionResult:
    """Run a mission in process and return its metrics and time series."""
    seed = sc.seed if seed is None else int(seed)
    method = method or sc.controller.method
    dur = float(sc.run.duration_s if duration is None else duration)
    dt = sc.control_dt
    n_steps = int(round(dur / dt))
    nsub = sc.substeps_per_control
    veh = sc.vehicle
    f_max = veh.thrust_max_n
    form = formation_from_scenario(sc)
    dyn = SwarmDynamics(sc, seed=seed)
    agents = [make_agent(sc, a.id, method=method, seed=seed, form=form) for a in sc.agents]
    gains: list[str] = []
    for ag in agents:
        if isinstance(ag, FollowerAgent):
            gains = ag.gains.lines()
            break
    if progress:
        print("\n".join(gains), file=sys.stderr)
    published = {ag.id: round_estimate(ag.initial_estimate()) for ag in agents}
    n = sc.n
    K = n_steps
    z = lambda *s: np.zeros((K, *s))  # noqa: E731
    ser = Series(
        t=np.arange(K) * dt, p=z(n, 3), v=z(n, 3), p_des=z(n, 3), v_des=z(n, 3), z1=z(n, 3),
        z2=z(n, 3), lumped_est=z(n, 3), lumped_true=z(n, 3), u=z(n, 3), thrust=z(n),
        tilt_deg=z(n), min_dist=z(), h_min=z(n), solve_us=z(n), fallback=np.zeros((K, n), bool),
    )
    lid = form.leader_idx
    t_wall = time.perf_counter()
    for k in range(K):
        t = k * dt
        tp, tv = f32(dyn.p), f32(dyn.v)
        comm = not in_outage(t, sc.outages)
        ser.p[k], ser.v[k] = dyn.p, dyn.v
        ser.p_des[k] = form.desired_positions(dyn.p[lid])
        ser.v_des[k] = form.desired_positions(dyn.v[lid]) - 0.0
        ser.lumped_true[k] = dyn.lumped_accel()
        ser.thrust[k] = dyn.thrust
        r, pch = dyn.att[:, 0], dyn.att[:, 1]
        ser.tilt_deg[k] = np.degrees(np.arccos(np.clip(np.cos(r) * np.cos(pch), -1, 1)))
        new_pub: dict[int, NeighbourEstimate] = {}
        for i, ag in enumerate(agents):
            e = published[ag.id]
            ser.z1[k, i], ser.z2[k, i] = e.z1, e.z2
            nb = {j: v for j, v in published.items() if j != ag.id} if comm else {}
            out = ag.step(k, t, tp, tv, nb, comm)
            roll, pitch, yaw, fn = wire_to_command(out.q_ned, out.thrust_norm, f_max)
            dyn.set_command(i, roll, pitch, yaw, fn)
            new_pub[ag.id] = round_estimate(out.estimate)
            ser.u[k, i] = out.u
            ser.lumped_est[k, i] = out.lumped
            st = out.status
            ser.h_min[k, i] = st.h_min
            ser.solve_us[k, i] = st.solve_us
            ser.fallback[k, i] = st.qp_status in ("relaxed", "fallback")
        published = new_pub
        md = math.inf
        for _ in range(nsub):
            dyn.step()
            md = min(md, dyn.min_pair_distance())
        ser.min_dist[k] = md
        if progress and k % int(round(5.0 / dt)) == 0:
            print(f"  [{method}] t = {t:5.1f} s  min dist {ser.min_dist[: k + 1].min():.3f} m",
                  file=sys.stderr)
    wall = time.perf_counter() - t_wall
    zeta_est = np.zeros((n, 6))
    fallbacks = 0
    for i, ag in enumerate(agents):
        if isinstance(ag, FollowerAgent):
            zeta_est[i] = ag.deso.zeta
            fallbacks += ag.fallbacks
    metrics = compute_metrics(
        ser, form.follower_idx, dt, veh.mass_kg, veh.gravity_mps2, dyn.collisions,
        dyn.zeta, zeta_est, fallbacks, wall, dur,
    )
    return MissionResult(
        scenario=sc.name, method=method, seed=seed, metrics=metrics, series=ser, gains=gains,
        collision_pairs=list(dyn.collision_pairs),
    )
