"""Fault injection on the transports (docs/faults.md): seeded drop, delay, duplicate, reorder.

A scenario's optional ``[faults]`` section gives one :class:`FaultConfig` per transport
(``[faults.mavlink]``, ``[faults.zenoh]``) and, optionally, per agent
(``[faults.agent.<id>.<link>]``, whose keys replace the link's for that agent's processes).
Every value is 0 by default, and a link whose values are all 0 gets no injector at all, so
a run without faults takes exactly the code path it took before this module existed.

:class:`FaultInjector` sits between a transport and its socket or publisher:
:meth:`FaultInjector.send` takes one outbound datagram or payload and a send function and
drops it, delays it (``delay_ms`` ± ``jitter_ms``, uniform), sends it twice or holds it
back until the next one has gone (reorder). Delayed and held messages are sent by one
small timer thread per injector, never by the caller, which is never blocked.
:meth:`FaultInjector.drop_inbound` draws the receive-side drop (``drop_in``).

The random draws are reproducible: each injector has its own generator seeded by
(scenario seed, agent id, link name), and every outbound message takes the same four
draws whatever the configuration. (In real time *which* message meets which draw still
depends on scheduling.)

A process that loads a scenario file (:func:`swarm_common.scenario.model.load_scenario`) installs
its fault plan here (:func:`install`); the transports then ask :func:`injector_for`.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import threading
import time
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from swarm_common.enums import FaultLink
from swarm_common.inputs import finite_float

log = logging.getLogger(__name__)

MAVLINK = FaultLink.MAVLINK.value
ZENOH = FaultLink.ZENOH.value
LINKS = tuple(link.value for link in FaultLink)
REORDER_MAX_HOLD_S = 0.1  # s: a held-back message goes out at the latest this much later
MAX_DELAY_MS = 10_000.0
MAX_PENDING = 100_000  # messages waiting in one injector's timer queue; beyond: dropped


class FaultError(ValueError):
    """A bad ``[faults]`` table or fault flag; ``str()`` is one line naming the key."""


def _prob(desc: str) -> Any:
    return field(default=0.0, metadata={"lo": 0.0, "hi": 1.0, "desc": desc})


def _ms(desc: str) -> Any:
    return field(default=0.0, metadata={"lo": 0.0, "hi": MAX_DELAY_MS, "desc": desc})


@dataclass(frozen=True)
class FaultConfig:
    """The faults of one transport link of one process (probabilities per message)."""

    drop: float = _prob("probability that a sent message is lost")
    drop_in: float = _prob("probability that a received message is discarded")
    delay_ms: float = _ms("added latency of a sent message (ms)")
    jitter_ms: float = _ms("uniform ± spread of that latency (ms)")
    duplicate: float = _prob("probability that a sent message goes out twice")
    reorder: float = _prob("probability that a sent message is held back behind the next")

    @property
    def active(self) -> bool:
        return any(getattr(self, f.name) != 0.0 for f in fields(self))

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def parse(cls, table: object, where: str, base: FaultConfig | None = None) -> FaultConfig:
        """Validate one TOML table (``where`` names it in errors); keys left out keep
        ``base``'s values (default: 0)."""
        if not isinstance(table, dict):
            raise FaultError(f"[{where}] must be a table")
        base = cls() if base is None else base
        values: dict[str, float] = {}
        for key, value in table.items():
            values[key] = check_fault_value(f"{where}.{key}", key, value)
        return replace(base, **values)

    def as_toml(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name)}


def check_fault_value(name: str, key: str, value: object) -> float:
    """``value`` as a float if it is a valid value of FaultConfig field ``key``, else
    :class:`FaultError` naming ``name`` and the allowed range."""
    spec = {f.name: f.metadata for f in fields(FaultConfig)}.get(key)
    if spec is None:
        raise FaultError(f"unknown key {name}; allowed: {', '.join(FaultConfig.keys())}")
    x = finite_float(value) if isinstance(value, int | float) else None
    if x is not None and spec["lo"] <= x <= spec["hi"]:  # an int too large: None, not raised
        return x
    shown = repr(value) if len(repr(value)) <= 40 else f"{repr(value)[:37]}..."
    raise FaultError(
        f"{name} = {shown}: must be a number in [{spec['lo']:g}, {spec['hi']:g}] "
        f"({spec['desc']})"
    )


@dataclass(frozen=True)
class FaultPlan:
    """A scenario's ``[faults]``: one config per link, and per-agent replacements."""

    links: Mapping[str, FaultConfig] = field(
        default_factory=lambda: {name: FaultConfig() for name in LINKS}
    )
    agents: Mapping[int, Mapping[str, FaultConfig]] = field(default_factory=dict)

    @property
    def active(self) -> bool:
        return any(c.active for c in self.links.values()) or any(
            c.active for per in self.agents.values() for c in per.values()
        )

    def for_agent(self, agent_id: int, link: str) -> FaultConfig:
        """The faults of ``link`` in agent (vehicle) ``agent_id``'s processes."""
        per = self.agents.get(agent_id, {})
        return per.get(link, self.links.get(link, FaultConfig()))

    @classmethod
    def parse(cls, table: object) -> FaultPlan:
        """Validate a decoded ``[faults]`` table (:class:`FaultError`: one line)."""
        if not isinstance(table, dict):
            raise FaultError("[faults] must be a table")
        links = {name: FaultConfig() for name in LINKS}
        for key, sub in table.items():
            if key == "agent":
                continue
            if key not in LINKS:
                raise FaultError(f"unknown key faults.{key}; allowed: {', '.join(LINKS)}, agent")
            links[key] = FaultConfig.parse(sub, f"faults.{key}")
        agents: dict[int, dict[str, FaultConfig]] = {}
        per_agent = table.get("agent", {})
        if not isinstance(per_agent, dict):
            raise FaultError("[faults.agent] must be a table of agent ids")
        for aid_text, sub in per_agent.items():
            if not aid_text.isdigit() or not 1 <= int(aid_text) <= 255:
                raise FaultError(f"faults.agent.{aid_text}: must be an agent id (1..255)")
            if not isinstance(sub, dict):
                raise FaultError(f"[faults.agent.{aid_text}] must be a table")
            aid = int(aid_text)
            for link, cfg in sub.items():
                if link not in LINKS:
                    raise FaultError(f"unknown key faults.agent.{aid}.{link}; allowed: "
                                     f"{', '.join(LINKS)}")
                agents.setdefault(aid, {})[link] = FaultConfig.parse(
                    cfg, f"faults.agent.{aid}.{link}", links[link]
                )
        return cls(links, agents)

    def with_link_values(
        self, link_names: tuple[str, ...], values: Mapping[str, float]
    ) -> FaultPlan:
        """A copy with ``values`` set on every link of ``link_names`` (the CLI flags); the
        per-agent tables take them too, so the flags win everywhere."""
        links = dict(self.links)
        for name in link_names:
            links[name] = replace(links[name], **values)
        agents = {
            aid: {ln: replace(c, **values) if ln in link_names else c for ln, c in per.items()}
            for aid, per in self.agents.items()
        }
        return FaultPlan(links, agents)

    def as_toml(self) -> dict[str, Any]:
        """The plan as a ``[faults]`` TOML table (only the values that are not 0)."""
        out: dict[str, Any] = {n: c.as_toml() for n, c in self.links.items() if c.active}
        if self.agents:
            out["agent"] = {
                str(aid): {ln: c.as_toml() for ln, c in per.items()}
                for aid, per in self.agents.items()
            }
        return out


@dataclass
class FaultStats:
    sent: int = 0  # messages handed to the send function (duplicates included)
    dropped: int = 0
    dropped_in: int = 0
    delayed: int = 0
    duplicated: int = 0
    reordered: int = 0
    overflow: int = 0  # dropped because MAX_PENDING messages were already waiting

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


SendFn = Callable[[Any], object]


def seed_for(seed: int, agent_id: int, link: str) -> list[int]:
    """The generator seed of (scenario seed, agent id, link name)."""
    return [int(seed) & 0xFFFFFFFF, int(agent_id), zlib.crc32(link.encode())]


class FaultInjector:
    """Seeded faults on one link of one process (module docstring).

    ``threaded=False`` (unit tests): nothing runs in the background; :meth:`service`
    sends what is due at the time ``clock()`` returns."""

    def __init__(
        self,
        cfg: FaultConfig,
        seed: int,
        agent_id: int,
        link: str,
        clock: Callable[[], float] = time.monotonic,
        threaded: bool = True,
    ) -> None:
        self.cfg = cfg
        self.link = link
        self.clock = clock
        self.threaded = threaded
        self.stats = FaultStats()
        self._rng = np.random.default_rng(seed_for(seed, agent_id, link))
        self._rng_in = np.random.default_rng([*seed_for(seed, agent_id, link), 1])
        self._heap: list[tuple[float, int, SendFn, Any]] = []
        self._seq = itertools.count()
        self._held: tuple[int, SendFn, Any, float] | None = None  # (token, fn, payload, delay)
        self._cv = threading.Condition()
        self._thread: threading.Thread | None = None
        self._closed = False

    # -- outbound ---------------------------------------------------------------------
    def send(self, payload: Any, send_fn: SendFn) -> None:
        """Drop, delay, duplicate or hold back ``payload``; ``send_fn(payload)`` sends it."""
        c = self.cfg
        u_drop, u_dup, u_reo, u_jit = self._rng.random(4)
        if u_drop < c.drop:
            self.stats.dropped += 1
            return
        delay = max(0.0, c.delay_ms + c.jitter_ms * (2.0 * u_jit - 1.0)) / 1000.0
        copies = 2 if u_dup < c.duplicate else 1
        self.stats.duplicated += copies - 1
        with self._cv:
            held, self._held = self._held, None
            if u_reo < c.reorder and held is None:
                token = next(self._seq)
                self._held = (token, send_fn, payload, delay)
                self.stats.reordered += 1
                self._push(self.clock() + delay + REORDER_MAX_HOLD_S, self._release, token)
                return
        now = self.clock()
        for _ in range(copies):
            self._emit(now + delay, send_fn, payload)
        if held is not None:  # the held-back message goes out right behind this one
            self._emit(now + max(delay, held[3]), held[1], held[2])

    def _release(self, token: int) -> None:
        """The hold of message ``token`` timed out (no next message came): send it."""
        with self._cv:
            held = self._held
            if held is None or held[0] != token:
                return
            self._held = None
        self._call(held[1], held[2])

    def _emit(self, due: float, send_fn: SendFn, payload: Any) -> None:
        """Send now if due and nothing queued is due before it; else queue it."""
        now = self.clock()
        with self._cv:
            if due > now or (self._heap and self._heap[0][0] <= due):
                self.stats.delayed += due > now
                self._push(due, send_fn, payload)
                return
        self._call(send_fn, payload)

    def _push(self, due: float, send_fn: SendFn, payload: Any) -> None:
        """Queue a timed call (the caller holds ``self._cv``)."""
        if len(self._heap) >= MAX_PENDING or self._closed:
            self.stats.overflow += 1
            return
        heapq.heappush(self._heap, (due, next(self._seq), send_fn, payload))
        if self.threaded and self._thread is None:
            self._thread = threading.Thread(
                target=self._run, name=f"faults-{self.link}", daemon=True
            )
            self._thread.start()
        self._cv.notify()

    def _call(self, send_fn: SendFn, payload: Any) -> None:
        if send_fn == self._release:
            send_fn(payload)
            return
        self.stats.sent += 1
        send_fn(payload)

    # -- the timer ----------------------------------------------------------------------
    def service(self) -> int:
        """Send every queued message that is due now; returns how many calls were made."""
        n = 0
        while True:
            with self._cv:
                if not self._heap or self._heap[0][0] > self.clock():
                    return n
                _, _, fn, payload = heapq.heappop(self._heap)
            self._call(fn, payload)
            n += 1

    @property
    def pending(self) -> int:
        with self._cv:
            return len(self._heap) + (self._held is not None)

    def _run(self) -> None:
        while True:
            with self._cv:
                while not self._closed and (not self._heap or self._heap[0][0] > self.clock()):
                    wait = None if not self._heap else self._heap[0][0] - self.clock()
                    self._cv.wait(wait)
                if self._closed:
                    return
            try:
                self.service()
            except OSError as exc:  # a send function that does not catch its own errors
                log.debug("%s faults: delayed send failed: %s", self.link, exc)

    def close(self) -> None:
        """Stop the timer thread; messages still waiting are discarded."""
        with self._cv:
            self._closed = True
            self._heap.clear()
            self._held = None
            self._cv.notify()
        if self._thread is not None:
            self._thread.join(1.0)
        log.info("%s faults: %s", self.link, " ".join(f"{k}={v}" for k, v in
                                                        self.stats.as_dict().items()))

    # -- inbound ----------------------------------------------------------------------
    def drop_inbound(self) -> bool:
        """Whether to discard one received message (``drop_in``); counted."""
        if self.cfg.drop_in <= 0.0:
            return False
        if self._rng_in.random() < self.cfg.drop_in:
            self.stats.dropped_in += 1
            return True
        return False


# -- the process's plan ------------------------------------------------------------------
_installed: tuple[FaultPlan, int] | None = None
_announced = False  # "fault injection on" logged by this process (once, at its first link)


def install(plan: FaultPlan, seed: int) -> None:
    """Make ``plan`` (seeded by the scenario seed) this process's fault plan. Nothing is
    logged here: a process that opens no faulted link (the in-process runner, a ground
    station) injects nothing, and says so where it matters; the first link that does
    logs "fault injection on" (:func:`injector_for`)."""
    global _installed, _announced
    _installed = (plan, int(seed)) if plan.active else None
    _announced = False


def injector_for(link: str, agent_id: int, endpoint: str = "") -> FaultInjector | None:
    """An injector for ``link`` ("mavlink" or "zenoh") of agent ``agent_id``'s processes
    under the installed plan, or None when there is no plan or its values are all 0.
    ``endpoint`` tells the ends of one link apart in the seed (e.g. "vehicle.api")."""
    if _installed is None:
        return None
    plan, seed = _installed
    cfg = plan.for_agent(agent_id, link)
    if not cfg.active:
        return None
    name = f"{link}.{endpoint}" if endpoint else link
    global _announced
    if not _announced:
        _announced = True
        log.warning("fault injection on: %s", plan.as_toml())
    return FaultInjector(cfg, seed, agent_id, name)
