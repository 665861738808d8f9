"""A follower's detour out of a pocket of obstacles (docs/world.md, "Liveness").

A follower that the deadlock detector finds stuck (:class:`~offboard.safety.deadlock.
DeadlockDetector`: error stalled, the filter holding it, the agent not moving) while a
world row is near, cannot leave by going toward its vertex: each surface around it holds
it at its stand-off. For :data:`DETOUR_S` its nominal law then tracks a point
:data:`DETOUR_M` away along the nearest obstacle's surface instead of its desired state:
the horizontal part of the direction of its vertex with the surface's normal taken out,
or, when that is short (the vertex is
straight behind the surface), n × e_z (turned by the agent's index parity, so two
neighbours stuck at one obstacle go opposite ways, and the other way at each new detour).
The surface is the one in the way: of the obstacles whose plane barrier is below
:data:`NEAR_M`, the one the vertex direction pushes into most. Every second detour climbs
straight up instead: a pocket between obstacles whose gaps are narrower than two
stand-offs is often open only above (the filter's fence and ground rows still hold).

The filter still keeps every row: the detour changes the nominal command only, so the
guarantee is the filter's as before.

Pure maths: no I/O. ENU, z up (m, s).
"""

from __future__ import annotations

import math

import numpy as np

from offboard.safety.dcbf.world_rows import WorldPlanes

DETOUR_M = 1.5  # m, how far along the surface the detour's point lies
DETOUR_S = 3.0  # s, how long the detour is tracked before the formation again
ALONG_MIN = 0.3  # the vertex direction's share along the surface below which n × e_z is used
NEAR_M = 1.0  # m, a plane's barrier below which its obstacle counts as holding the agent


class Detour:
    """One follower's detour (module docstring); ``index`` its scenario index."""

    def __init__(self, planes: WorldPlanes, index: int) -> None:
        self.planes = planes
        self.sign = 1.0 if index % 2 == 0 else -1.0
        self.until = -math.inf  # s, the end of the current detour
        self.target = np.zeros(3)  # m, its point
        self.count = 0  # detours started

    def active(self, t: float) -> bool:
        return t < self.until

    def start(self, t: float, p: np.ndarray, goal: np.ndarray) -> bool:
        """Start a detour at ``t`` (s) from ``p`` (m) whose formation point is ``goal`` (m);
        False (none started) when no obstacle's plane is within range."""
        m = self.planes.at(np.asarray(p, float))
        n_obs = len(self.planes.table)
        near = [k for k in range(m) if k < n_obs]  # obstacle planes come first
        if not near:
            return False
        g = np.asarray(goal, float) - np.asarray(p, float)
        # the surface in the way: of the obstacles holding it (plane within NEAR_M), the
        # one the vertex direction pushes into most; else the nearest
        h = np.array([float(self.planes.normals[k] @ p - self.planes.offsets[k]) for k in near])
        push = np.array([float(self.planes.normals[k] @ g) for k in near])
        holding = np.flatnonzero(h < NEAR_M)
        pick = (holding[int(np.argmin(push[holding]))] if holding.size
                else int(np.argmin(h)))
        n = self.planes.normals[near[pick]].copy()
        along = g - float(g @ n) * n
        along[2] = 0.0  # around it horizontally; every second detour climbs instead
        if float(np.linalg.norm(along)) < ALONG_MIN * max(float(np.linalg.norm(g)), 1e-9):
            along = self.sign * np.cross(n, np.array([0.0, 0.0, 1.0]))
            if float(np.linalg.norm(along)) < 1e-6:  # n vertical: any horizontal way
                along = np.array([self.sign, 0.0, 0.0])
        if self.count % 2 == 1:  # every second detour climbs: a pocket is often left upward
            along = np.array([0.0, 0.0, 1.0])
        else:  # the next sideways one turns the other way
            self.sign = -self.sign
        self.target = np.asarray(p, float) + DETOUR_M * along / float(np.linalg.norm(along))
        self.until = t + DETOUR_S
        self.count += 1
        return True

    def reference(self, t: float, xi: np.ndarray) -> np.ndarray:
        """``xi`` (12,), or during a detour the detour's point at rest."""
        if not self.active(t):
            return xi
        out = np.zeros(12)
        out[0:3] = self.target
        return out
