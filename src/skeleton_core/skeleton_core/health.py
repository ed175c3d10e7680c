"""Health bookkeeping for nodes (pure Python): message rate, latency percentiles, drop counts
by cause, and "log once per cause". Nodes publish a snapshot as diagnostics."""
from __future__ import annotations

import collections
import threading
import time
from typing import Dict, Optional

import numpy as np


class Health:
    """Counts what a node received, published and dropped, and how late its outputs were."""

    def __init__(self, window: int = 300):
        self._lock = threading.Lock()
        self.received = 0
        self.published = 0
        self.dropped: Dict[str, int] = collections.Counter()
        self._latency_ms = collections.deque(maxlen=window)
        self._pub_times = collections.deque(maxlen=window)
        self._logged = set()
        # stream inputs matched but receiving nothing (skeleton_core.input_watch): topic -> text
        self.silent_inputs: Dict[str, str] = {}

    def on_receive(self) -> None:
        with self._lock:
            self.received += 1

    def on_publish(self, latency_s: Optional[float] = None, now: Optional[float] = None) -> None:
        with self._lock:
            self.published += 1
            self._pub_times.append(time.monotonic() if now is None else now)
            if latency_s is not None and np.isfinite(latency_s):
                self._latency_ms.append(latency_s * 1000.0)

    def on_drop(self, cause: str) -> bool:
        """Count a dropped input; returns True the first time this cause is seen (log it then)."""
        with self._lock:
            self.dropped[cause] += 1
            first = cause not in self._logged
            self._logged.add(cause)
            return first

    def set_silent(self, topic: str, text: Optional[str]) -> None:
        """Mark ``topic`` as a matched input receiving nothing (``text``: what is seen), or clear
        it (``None``)."""
        with self._lock:
            if text is None:
                self.silent_inputs.pop(topic, None)
            else:
                self.silent_inputs[topic] = text

    def rate_hz(self, now: Optional[float] = None) -> float:
        with self._lock:
            t = list(self._pub_times)
        if len(t) < 2:
            return 0.0
        now = time.monotonic() if now is None else now
        if now - t[-1] > 2.0:  # stalled
            return 0.0
        return (len(t) - 1) / max(t[-1] - t[0], 1e-9)

    def latency_percentiles(self) -> Dict[str, float]:
        with self._lock:
            lat = np.array(self._latency_ms)
        if lat.size == 0:
            return {'p50_ms': float('nan'), 'p95_ms': float('nan'), 'p99_ms': float('nan')}
        p50, p95, p99 = np.percentile(lat, [50, 95, 99])
        return {'p50_ms': float(p50), 'p95_ms': float(p95), 'p99_ms': float(p99)}

    def snapshot(self) -> Dict[str, float]:
        out = {'received': self.received, 'published': self.published,
               'rate_hz': self.rate_hz(), 'dropped_total': sum(self.dropped.values())}
        out.update(self.latency_percentiles())
        for k, v in sorted(self.dropped.items()):
            out[f'dropped[{k}]'] = v
        with self._lock:
            silent = sorted(self.silent_inputs.items())
        for k, v in silent:
            out[f'silent_input[{k}]'] = v
        return out
