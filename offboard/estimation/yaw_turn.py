"""Turning a formation's jets by its yaw ψ(t): the kernels of the formation frame.

**Turning a jet.** For x(t) in the world frame (complex xy) and E(t) = e^{−iψ(t)}, the
F-frame value is ζ = E x and, by Leibniz, ζ⁽ⁿ⁾ = Σ_k C(n,k) E⁽ᵏ⁾ x⁽ⁿ⁻ᵏ⁾ with
E' = w'E, E'' = (w'' + w'²)E, E''' = (w''' + 3w'w'' + w'³)E, w = −iψ; back to the world
frame with w = +iψ. z is unchanged.

The yaw itself comes from the leaders' horizontal offset r(t) = s(t) e^{iψ(t)} r₀ (see
:mod:`offboard.estimation.formation_frame`): with ℓ = log r, ψ = arg r − arg r₀ and
ψ⁽ⁿ⁾ = Im ℓ⁽ⁿ⁾. A module of its own so that the desired-state observer
(:mod:`offboard.estimation.reference`) can read its neighbours turned in its compiled step.
"""

from __future__ import annotations

import cmath

import numpy as np

from swarm_common.jit import kernel


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
    e = np.empty(4, dtype=np.complex128)
    turn_coeffs_kernel(yaw, sign, e)
    turn_by_kernel(xi, e, out)


@kernel
def turn_coeffs_kernel(yaw: np.ndarray, sign: float, e: np.ndarray) -> None:
    """E, E', E'', E''' of E = e^{i·sign·ψ} (module docstring) into ``e`` (4,) complex128,
    from the ψ jet ``yaw`` (4,): computed once for every jet turned by the same ψ."""
    w1 = complex(0.0, sign * yaw[1])
    w2 = complex(0.0, sign * yaw[2])
    w3 = complex(0.0, sign * yaw[3])
    e0 = cmath.exp(complex(0.0, sign * yaw[0]))
    e[0] = e0
    e[1] = w1 * e0
    e[2] = (w2 + w1 * w1) * e0
    e[3] = (w3 + 3.0 * w1 * w2 + w1 * w1 * w1) * e0


@kernel
def turn_by_kernel(xi: np.ndarray, e: np.ndarray, out: np.ndarray) -> None:
    """``xi`` (12,) turned by the coefficients ``e`` of :func:`turn_coeffs_kernel` (Leibniz),
    into ``out`` (12,; may be ``xi``); z unchanged."""
    e0, e1, e2, e3 = e[0], e[1], e[2], e[3]
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
