"""Old (9879731: inline in physics_node.py, re-typed here) against new
(physics_sim.scheduler.TickScheduler) tick decisions on random arrival sequences, fake clock:
the same ticks at the same times with the same simulated time?"""
import random

from physics_sim.scheduler import TickScheduler


class Old:
    def __init__(self, rate):
        self.period = 1.0 / rate
        self.last_input_stamp = self.last_input_tick = self.pending = None
        self.deferred = self.last_tick = None
        self.log = []

    def tick(self, now, dt=None):
        if dt is None and self.last_tick is not None:
            dt = min(max(now - self.last_tick, 0.5 * self.period), 1.5 * self.period)
        elif dt is None:
            dt = self.period
        self.last_tick = now
        self.log.append((round(now, 6), round(dt, 6)))

    def on_input(self, now, stamp):
        p, last = self.period, self.last_input_stamp
        if last is None or stamp - last >= 0.75 * p or stamp < last - 1.0:
            self.pending = self.deferred = None
            self.last_input_tick = now
            dt = None if last is None else min(max(stamp - last, 0.5 * p), 1.5 * p)
            self.last_input_stamp = stamp
            self.tick(now, dt)
        else:
            self.pending = max(self.pending or stamp, stamp)
            if self.deferred is None:
                self.deferred = now + max(0.75 * p - (now - self.last_input_tick), 1e-4)

    def on_deferred(self, now):
        self.deferred, self.last_input_tick = None, now
        stamp, self.pending = self.pending, None
        dt = None
        if stamp is not None and self.last_input_stamp is not None:
            dt = min(max(stamp - self.last_input_stamp, 0.5 * self.period), 1.5 * self.period)
            self.last_input_stamp = stamp
        self.tick(now, dt)

    def on_timer(self, now):
        if self.last_input_tick is None or now - self.last_input_tick >= self.period:
            self.tick(now)


class New:
    def __init__(self, rate):
        self.now = 0.0
        self.period = 1.0 / rate
        self.sc = TickScheduler(rate, True, clock=lambda: self.now)
        self.deferred = None
        self.log = []

    def tick(self, now, dt=None):
        self.log.append((round(now, 6), round(self.sc.tick_time(dt), 6)))

    def on_input(self, now, stamp):
        self.now = now
        d = self.sc.on_input(stamp)
        if d.action == 'tick':
            self.deferred = None
            self.tick(now, d.dt)
        elif d.action == 'defer' and self.deferred is None:
            self.deferred = now + d.delay_s

    def on_deferred(self, now):
        self.now, self.deferred = now, None
        self.tick(now, self.sc.on_deferred())

    def on_timer(self, now):
        self.now = now
        if self.sc.timer_due():
            self.tick(now)


def run(cls, events, rate=30.0):
    s = cls(rate)
    next_timer = s.period
    for t, stamp in events:
        while True:       # the timers due before this arrival, in order
            due = [x for x in (s.deferred, next_timer) if x is not None and x <= t]
            if not due:
                break
            x = min(due)
            if s.deferred is not None and s.deferred == x:
                s.on_deferred(x)
            else:
                s.on_timer(x)
                next_timer += s.period
        s.on_input(t, stamp)
    return s.log


def events(seed, n=300):
    r = random.Random(seed)
    t, stamp, out = 0.1, 100.0, []
    for _ in range(n):
        gap = r.choice([1 / 30] * 6 + [1 / 60, 0.002, 0.05, 0.1, r.random() * 0.1])
        stamp += gap if r.random() > 0.01 else -2.0                  # a bag loop now and then
        t += max(1e-4, gap + r.gauss(0, 0.004)) if r.random() > 0.05 else 0.0005   # bursts
        out.append((round(t, 6), stamp))
    return out


if __name__ == '__main__':
    differ = [s for s in range(300) if run(Old, events(s)) != run(New, events(s))]
    ticks = sum(len(run(New, events(s))) for s in range(300))
    print(f'sequences with different ticks: {len(differ)} of 300 ({ticks} ticks)')
