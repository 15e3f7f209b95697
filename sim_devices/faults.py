"""Fault injection for the emulators' transports: deterministic for a seed, and counted.

Options (``options["faults"]``, ``options["seed"]``), every key optional::

    drop, corrupt, truncate, duplicate, garbage, delay, reorder   probability per frame (sum <= 1)
    delay_ms          how long a delayed frame waits (default 20 ms)
    stall_s           [[start, duration], ...] s after the emulator is ready: nothing is sent
    disconnect_at_s   a time or list of times: the link goes away (pty removed, sockets closed) ...
    reconnect_after_s ... and comes back after this long (default 0.5 s)
    spacing           frames after a fault that get none (default 2), so each fault stays
                      distinguishable from its neighbours on the receiving side

One random draw is made per frame whatever happens, so the n-th frame meets the same fault for the
same seed. What each fault does on the wire depends on the transport (see each emulator); on a byte
link: ``corrupt`` flips one bit after the header, ``truncate`` sends the frame cut short (header
kept), ``garbage`` sends 1-16 random bytes before the frame, ``duplicate`` sends it twice; ``reorder``
(datagram transports only) sends the frame after the next one.
"""
from __future__ import annotations

import random
import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

PROBABILISTIC = ("drop", "corrupt", "truncate", "duplicate", "garbage", "delay", "reorder")
ALL_FAULTS = frozenset((*PROBABILISTIC, "stall_s", "disconnect_at_s"))
_KEYS = frozenset((*ALL_FAULTS, "delay_ms", "reconnect_after_s", "spacing"))


@dataclass(frozen=True)
class FaultConfig:
    drop: float = 0.0
    corrupt: float = 0.0
    truncate: float = 0.0
    duplicate: float = 0.0
    garbage: float = 0.0
    delay: float = 0.0
    reorder: float = 0.0
    delay_ms: float = 20.0
    stall_s: tuple[tuple[float, float], ...] = ()
    disconnect_at_s: tuple[float, ...] = ()
    reconnect_after_s: float = 0.5
    spacing: int = 2
    seed: int = 1

    @classmethod
    def from_options(cls, options: Mapping[str, Any] | None, supported: frozenset[str] = ALL_FAULTS) -> FaultConfig:
        """Validate ``options["faults"]``; raises ValueError naming an unknown or unsupported fault."""
        options = options or {}
        faults = dict(options.get("faults") or {})
        unknown = set(faults) - _KEYS
        if unknown:
            raise ValueError(f"unknown fault option(s) {sorted(unknown)} (known: {sorted(_KEYS)})")
        active = {k for k in ALL_FAULTS if faults.get(k)}
        if active - supported:
            raise ValueError(f"fault(s) {sorted(active - supported)} not supported by this transport "
                             f"(supported: {sorted(supported)})")
        probs = {k: float(faults.get(k, 0.0)) for k in PROBABILISTIC}
        if any(not 0.0 <= p <= 1.0 for p in probs.values()) or sum(probs.values()) > 1.0:
            raise ValueError(f"fault probabilities must be in [0, 1] and sum to <= 1, got {probs}")
        stalls = tuple((float(a), float(b)) for a, b in (faults.get("stall_s") or ()))
        disc = faults.get("disconnect_at_s") or ()
        disc = (float(disc),) if isinstance(disc, int | float) else tuple(float(x) for x in disc)
        return cls(**probs, delay_ms=float(faults.get("delay_ms", 20.0)), stall_s=stalls,
                   disconnect_at_s=tuple(sorted(disc)), reconnect_after_s=float(faults.get("reconnect_after_s", 0.5)),
                   spacing=int(faults.get("spacing", 2)), seed=int(options.get("seed", 1)))


class FaultInjector:
    """Decides the fault of each frame and applies byte-level faults. ``counts`` holds what was done;
    ``damaged`` the sample numbers the faults destroyed (callers append); ``at`` the sample numbers each
    fault hit, for callers that name the sample (a client that starts late saw only the later ones)."""

    def __init__(self, config: FaultConfig, clock=time.monotonic) -> None:
        self.config = config
        self.rng = random.Random(config.seed)
        self.counts: Counter[str] = Counter()
        self.damaged: list[int] = []
        self.at: dict[str, list[int]] = {}
        self.clock = clock
        self.t0 = clock()
        self._cooldown = 0
        self._disconnects = list(config.disconnect_at_s)
        self._none = not any(getattr(config, name) for name in PROBABILISTIC)  # no frame can get a fault

    def start(self) -> None:
        """Times in the configuration count from here (the emulator is ready)."""
        self.t0 = self.clock()

    def elapsed(self) -> float:
        return self.clock() - self.t0

    def next_fault(self, kind: str = "", sample: int | None = None) -> str | None:
        """The fault of the next frame (None: send it as is). ``kind`` also counts it as ``kind.fault``;
        ``sample`` (the frame's sample number) is kept in ``at``."""
        u = self.rng.random()  # one draw per frame, always
        if self._none:
            return None
        if self._cooldown > 0:
            self._cooldown -= 1
            return None
        acc = 0.0
        for name in PROBABILISTIC:
            acc += getattr(self.config, name)
            if u < acc:
                self._cooldown = self.config.spacing
                self.counts[name] += 1
                if kind:
                    self.counts[f"{kind}.{name}"] += 1
                if sample is not None:
                    self.at.setdefault(name, []).append(sample)
                return name
        return None

    def stalled(self) -> bool:
        if not self.config.stall_s:
            return False
        t = self.elapsed()
        return any(a <= t < a + d for a, d in self.config.stall_s)

    def disconnect_due(self) -> bool:
        if self._disconnects and self.elapsed() >= self._disconnects[0]:
            self._disconnects.pop(0)
            self.counts["disconnects"] += 1
            return True
        return False

    def apply(self, fault: str | None, frame: bytes, protect: int = 0) -> list[bytes]:
        """The chunks to write for ``frame`` under ``fault`` (``protect``: leading bytes never touched).
        ``delay`` and ``reorder`` are not applied here: callers wait ``delay_s`` first, or hold the frame."""
        rng = self.rng
        if fault is None or fault in ("delay", "reorder"):
            return [frame]
        if fault == "drop":
            return []
        if fault == "duplicate":
            return [frame, frame]
        if fault == "garbage":
            return [bytes(rng.randrange(256) for _ in range(rng.randint(1, 16))), frame]
        if fault == "corrupt":
            bit = rng.randrange(8 * protect, 8 * len(frame))
            bad = bytearray(frame)
            bad[bit // 8] ^= 1 << (bit % 8)
            return [bytes(bad)]
        if fault == "truncate":
            return [frame[:rng.randrange(max(protect, 1), len(frame))]]
        raise ValueError(f"unknown fault {fault!r}")

    @property
    def delay_s(self) -> float:
        return self.config.delay_ms / 1000.0

    def snapshot(self) -> dict[str, Any]:
        return {"faults": dict(self.counts), "damaged": list(self.damaged),
                "fault_at": {k: list(v) for k, v in self.at.items()}}
