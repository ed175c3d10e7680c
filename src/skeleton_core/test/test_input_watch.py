"""skeleton_core.input_watch: a stream input matched with a publisher and receiving nothing is
reported once per episode, and again when it recovers; with a fake clock (no ROS)."""
from skeleton_core.input_watch import RECOVERED, SILENT, UNMATCHED, InputWatch


def _run(w, steps, t0=0.0, dt=1.0):
    """Feed ``steps`` [(publishers, received)] one per ``dt``; the events [(t, event)]."""
    out = []
    for i, (pubs, received) in enumerate(steps):
        t = t0 + i * dt
        e = w.check(t, pubs, received)
        if e is not None:
            out.append((t, e))
    return out


def test_a_matched_input_receiving_nothing_is_reported_once():
    w = InputWatch('/kinect/skeletons', silent_after_s=10.0)
    events = _run(w, [(1, 0)] * 60)
    assert events == [(10.0, SILENT)] and w.silent
    line = w.message(SILENT, 10.0)
    assert line.startswith('input /kinect/skeletons: 1 publisher matched for 10 s, nothing received')
    assert 'docs/recovery.md' in line and w.status() == '1 matched, nothing received'


def test_not_reported_before_the_delay():
    w = InputWatch('/in', silent_after_s=10.0)
    assert _run(w, [(1, 0)] * 10) == [] and not w.silent   # 0..9 s


def test_a_message_after_the_report_is_a_recovery():
    w = InputWatch('/in', silent_after_s=10.0)
    events = _run(w, [(1, 0)] * 15 + [(1, 1)] + [(1, 1)] * 30)
    assert events == [(10.0, SILENT), (15.0, RECOVERED)] and not w.silent
    assert 'receiving now' in w.message(RECOVERED, 15.0)


def test_publishers_gone_then_back_is_a_new_episode():
    w = InputWatch('/in', silent_after_s=10.0)
    events = _run(w, [(1, 0)] * 12 + [(0, 0)] * 3 + [(2, 0)] * 12)
    assert events == [(10.0, SILENT), (12.0, UNMATCHED), (25.0, SILENT)]
    assert w.message(SILENT, 25.0).startswith('input /in: 2 publishers matched for 10 s')


def test_a_new_match_after_a_healthy_one_is_watched_again():
    # messages came, the publisher left, a new one matched and sends nothing (the restart case)
    w = InputWatch('/in', silent_after_s=10.0)
    steps = [(1, i) for i in range(1, 6)] + [(0, 5)] * 2 + [(1, 5)] * 12
    assert _run(w, steps) == [(17.0, SILENT)]


def test_no_publisher_is_never_silent():
    w = InputWatch('/in', silent_after_s=10.0)
    assert _run(w, [(0, 0)] * 100) == [] and not w.silent


def test_messages_flowing_are_never_silent():
    w = InputWatch('/in', silent_after_s=10.0)
    assert _run(w, [(1, 30 * i) for i in range(1, 100)]) == []


def test_messages_before_the_first_look_count_for_the_episode():
    # the publisher sent a few, then paused before the watch first saw it matched: not silent
    w = InputWatch('/in', silent_after_s=10.0)
    assert _run(w, [(1, 3)] * 30) == []


def test_a_publisher_that_stops_after_sending_is_not_this_fault():
    w = InputWatch('/in', silent_after_s=10.0)
    assert _run(w, [(1, 1), (1, 2)] + [(1, 2)] * 30) == []


def test_the_callback_counter_is_the_default():
    w = InputWatch('/in', silent_after_s=2.0)
    assert w.check(0.0, 1) is None
    w.count += 1
    assert w.check(5.0, 1) is None and not w.silent


def test_the_module_delay_is_the_default(monkeypatch):
    import skeleton_core.input_watch as iw
    monkeypatch.setattr(iw, 'SILENT_AFTER_S', 0.5)
    w = InputWatch('/in')
    assert w.silent_after_s == 0.5 and _run(w, [(1, 0)] * 3, dt=0.25) == [(0.5, SILENT)]
