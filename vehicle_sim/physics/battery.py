"""A simple simulated battery: what SYS_STATUS and BATTERY_STATUS report.

Reporting only: the charge never limits thrust and an empty battery triggers no
failsafe (docs/px4/streams.md). The model, per vehicle, integrated on simulation time:

* current (A): ``I = I_idle`` disarmed, ``I = I_idle + I_hover · (T / T_hover)^1.5``
  armed, with T the applied thrust (N) and T_hover = m·g: the induced power of a rotor
  grows as thrust^(3/2) (momentum theory), drawn at a nearly constant pack voltage;
* consumed charge (mAh): ``Q += I · dt / 3.6`` (A·s -> mAh), remaining = 1 - Q / C;
* pack voltage (V): ``cells · (V_empty + (V_full - V_empty) · remaining) - I · R``, a
  linear open-circuit curve and one internal resistance.

Defaults: a 4S 5000 mAh LiPo, 12 A at hover: about 24 minutes of hover from full.
"""

from __future__ import annotations

from dataclasses import dataclass

MAH_PER_AS = 1.0 / 3.6  # 1 A·s = 1/3.6 mAh
MAX_STEP_S = 1.0  # a longer gap (a paused clock) is integrated as this much
THRUST_EXPONENT = 1.5  # induced power ∝ T^(3/2)


@dataclass
class BatteryModel:
    """One vehicle's battery (SI units unless the name says otherwise)."""

    cells: int = 4
    capacity_mah: float = 5000.0
    v_full: float = 4.2  # V per cell at 100 %
    v_empty: float = 3.5  # V per cell at 0 %
    r_internal_ohm: float = 0.02
    idle_current_a: float = 0.4  # avionics, motors off
    hover_current_a: float = 12.0  # motors at hover thrust
    consumed_mah: float = 0.0
    current_a: float = 0.4
    last_t: float | None = None

    def update(self, sim_t: float, thrust_n: float, hover_n: float, armed: bool) -> None:
        """Integrate the charge drawn since the last call (simulation seconds)."""
        motors = 0.0
        if armed and hover_n > 0.0:
            motors = self.hover_current_a * (max(0.0, thrust_n) / hover_n) ** THRUST_EXPONENT
        self.current_a = self.idle_current_a + motors
        if self.last_t is not None:
            dt = min(MAX_STEP_S, max(0.0, sim_t - self.last_t))
            self.consumed_mah += self.current_a * dt * MAH_PER_AS
        self.last_t = sim_t

    @property
    def remaining(self) -> float:
        """State of charge, 0..1."""
        return min(1.0, max(0.0, 1.0 - self.consumed_mah / self.capacity_mah))

    @property
    def cell_voltage(self) -> float:
        """Per-cell voltage under the present load (V)."""
        ocv = self.v_empty + (self.v_full - self.v_empty) * self.remaining
        return max(0.0, ocv - self.current_a * self.r_internal_ohm / self.cells)

    @property
    def voltage(self) -> float:
        """Pack voltage under the present load (V)."""
        return self.cells * self.cell_voltage

    def time_remaining_s(self) -> int:
        """Seconds left at the present current (0 when empty)."""
        left_mah = self.capacity_mah - self.consumed_mah
        if left_mah <= 0.0 or self.current_a <= 0.0:
            return 0
        return int(left_mah / (self.current_a * MAH_PER_AS))
