"""The server's clock as the bridge sees it: offset from Ping/Pong exchanges, kept against drift.

Each exchange gives t1 (bridge, ping sent), t2 (server, received), t3 (server, pong sent), t4 (bridge, pong
received). Its offset estimate is theta = ((t2 - t1) + (t3 - t4)) / 2 (server minus bridge), off by at most
half the round trip delta = (t4 - t1) - (t3 - t2), so the exchanges with the shortest round trip are the
ones to trust (NTP's clock filter does the same). The estimator keeps the best exchange of each `bucket_s`
and, once the kept ones span `drift_span_s`, fits a line through them: offset and drift (the two crystal
clocks of two machines part by tens of microseconds per second).

Pure: the caller passes every time in; no clock is read here.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass


@dataclass
class Sample:
    t_ns: int        # bridge time of the exchange (midpoint) [ns]
    offset_ns: float
    rtt_ns: int


class ClockSync:
    def __init__(self, bucket_s: float = 2.0, buckets: int = 30, drift_span_s: float = 10.0) -> None:
        self.bucket_ns = int(bucket_s * 1e9)
        self.kept: deque[Sample] = deque(maxlen=buckets)
        self.drift_span_ns = int(drift_span_s * 1e9)
        self.exchanges = 0
        self.best_rtt_ns = 0
        self.last_rtt_ns = 0
        self._offset_ns = 0.0      # at _ref_ns
        self._drift = 0.0          # d offset / d t (dimensionless)
        self._ref_ns = 0

    @property
    def synced(self) -> bool:
        return self.exchanges > 0

    def add(self, t1: int, t2: int, t3: int, t4: int) -> bool:
        """Books one exchange; False (ignored) when its times are inconsistent."""
        rtt = (t4 - t1) - (t3 - t2)
        if t4 < t1 or t3 < t2 or rtt < 0:
            return False
        s = Sample((t1 + t4) // 2, ((t2 - t1) + (t3 - t4)) / 2.0, rtt)
        self.exchanges += 1
        self.last_rtt_ns = rtt
        if self.kept and self.kept[-1].t_ns // self.bucket_ns == s.t_ns // self.bucket_ns:  # same bucket
            if rtt < self.kept[-1].rtt_ns:
                self.kept[-1] = s
        else:
            self.kept.append(s)
        self.best_rtt_ns = min(k.rtt_ns for k in self.kept)
        self._fit()
        return True

    def _fit(self) -> None:
        k = self.kept
        if len(k) >= 3 and k[-1].t_ns - k[0].t_ns >= self.drift_span_ns:
            # Least squares through the kept samples, weighted toward short round trips.
            w = [1.0 / (1.0 + (s.rtt_ns - self.best_rtt_ns) / 1e5) for s in k]
            sw = sum(w)
            tm = sum(wi * s.t_ns for wi, s in zip(w, k, strict=True)) / sw
            om = sum(wi * s.offset_ns for wi, s in zip(w, k, strict=True)) / sw
            stt = sum(wi * (s.t_ns - tm) ** 2 for wi, s in zip(w, k, strict=True))
            sto = sum(wi * (s.t_ns - tm) * (s.offset_ns - om) for wi, s in zip(w, k, strict=True))
            self._drift = sto / stt if stt > 0 else 0.0
            self._offset_ns, self._ref_ns = om, int(tm)
        else:
            best = min(k, key=lambda s: s.rtt_ns)
            self._offset_ns, self._ref_ns, self._drift = best.offset_ns, best.t_ns, 0.0

    def offset_ns(self, bridge_ns: int) -> float:
        """Server clock minus bridge clock at bridge time `bridge_ns` [ns]."""
        return self._offset_ns + self._drift * (bridge_ns - self._ref_ns)

    def to_bridge(self, server_ns: int, near_bridge_ns: int) -> int:
        """A server time as a bridge time (the offset taken at `near_bridge_ns`)."""
        return int(server_ns - self.offset_ns(near_bridge_ns))

    @property
    def drift_ppm(self) -> float:
        return self._drift * 1e6
