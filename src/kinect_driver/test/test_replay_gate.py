"""The replay's start handshake (kinect_driver.replay_gate) on a fake clock: no sleeping, no DDS."""
import pytest

from kinect_driver.replay_gate import OTHERS_GRACE_S, ReplayGate


class Clock:
    def __init__(self):
        self.t = 50.0

    def __call__(self):
        return self.t


def make(want=2, timeout=10.0):
    clock = Clock()
    log = []
    released = []
    g = ReplayGate(want, timeout, clock=clock, info=lambda m: log.append(('info', m)),
                   warn=lambda m: log.append(('warn', m)), on_release=released.append)
    return g, clock, log, released


def test_waits_for_the_subscribers_then_for_the_acknowledgement_and_hands_back_the_time():
    g, clock, log, released = make()
    subs = [0]
    acked = [False]
    poll = lambda: g.may_poll(lambda: subs[0], lambda: (), lambda: acked[0])  # noqa: E731
    assert not poll()
    clock.t += 1.0
    subs[0] = 1
    assert not poll()                       # one of two readers: still waiting
    clock.t += 1.0
    subs[0] = 2
    assert poll()                           # both there: the first frame goes out
    g.published(1)
    assert g.state == 'acks'
    clock.t += 1.5
    assert not poll()                       # not acknowledged yet: the replay's clock is held
    clock.t += 1.0
    acked[0] = True
    assert poll() and g.playing
    assert released == [pytest.approx(2.5)]   # the source is delayed by the time held
    assert poll()                           # playing: no more questions
    assert [k for k, _ in log] == ['info', 'info', 'info']


def test_other_topics_get_a_short_grace_then_play():
    g, clock, log, _ = make(want=1)
    others = ['/kinect/ground_truth']
    assert not g.may_poll(lambda: 1, lambda: others)
    clock.t += OTHERS_GRACE_S / 2
    assert not g.may_poll(lambda: 1, lambda: others)
    clock.t += OTHERS_GRACE_S
    assert g.may_poll(lambda: 1, lambda: others)


def test_plays_anyway_after_the_timeout_with_a_warning():
    g, clock, log, released = make(want=3, timeout=4.0)
    assert not g.may_poll(lambda: 1)
    clock.t += 4.0
    assert g.may_poll(lambda: 1)
    g.published(1)
    clock.t += 4.0
    assert g.may_poll(lambda: 1, acked=lambda: False) and g.playing
    assert [k for k, _ in log] == ['info', 'warn', 'warn']
    assert released == [pytest.approx(4.0)]


def test_a_first_poll_with_nothing_due_plays_on_and_live_plays_at_once():
    g, clock, _, released = make(want=1)
    assert g.may_poll(lambda: 1)
    g.published(0)
    assert g.playing and released == []
    live = ReplayGate(0, 10.0)
    assert live.playing and live.may_poll(lambda: 0)


def test_a_live_source_waits_for_the_subscribers_but_is_never_held_after_its_first_frame():
    clock = Clock()
    log = []
    g = ReplayGate(2, 10.0, clock=clock, info=lambda m: log.append(('info', m)),
                   warn=lambda m: log.append(('warn', m)), hold_first=False, label='synthetic')
    subs = [1]
    poll = lambda: g.may_poll(lambda: subs[0], lambda: (), lambda: False)  # noqa: E731
    assert not poll()                       # one of two readers: the first frame waits
    clock.t += 0.5
    subs[0] = 2
    assert poll()
    g.published(1)
    assert g.playing                        # never acknowledged (acked False): plays on anyway
    assert all(kind == 'info' and m.startswith('synthetic:') for kind, m in log), log
