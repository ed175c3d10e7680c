"""skeleton_core.presence: users present in a stream, on the stream's own clock."""
import pytest

from skeleton_core.presence import Presence

S = 1_000_000_000


def test_offline_users_leave_after_the_timeout_in_message_time():
    p = Presence(2.0)
    p.observe(100 * S, [1, 2])
    p.observe(101 * S, [2])
    assert p.expired() == []
    p.observe(int(102.5 * S), [2])      # user 1 unseen for 2.5 s of message time
    assert p.expired() == [1] and p.users == [2]
    assert p.expired() == []             # forgotten: not reported twice
    p.observe(103 * S, [1])              # back later: a new arrival, present again
    assert p.seen(1)


def test_live_clock_runs_on_when_nothing_arrives():
    p = Presence(1.0)
    p.observe(50 * S, [4], wall=10.0)
    assert p.expired(wall=10.9) == []
    assert p.now_ns(wall=10.5) == int(50.5 * S)
    assert p.expired(wall=11.1) == [4]   # no message for 1.1 s: gone


def test_stamps_behind_the_clock_do_not_move_it_back():
    p = Presence(1.0)
    p.observe(50 * S, [1, 2], wall=0.0)
    # a looped bag: stamps jump 40 s back, user 1 keeps coming, user 2 has left
    for k in range(1, 20):
        p.observe(10 * S + k * S // 10, [1], wall=k / 10)
    assert p.expired(wall=1.95) == [2] and p.users == [1]


def test_unstamped_messages_use_the_clock_and_timeout_is_checked():
    p = Presence(0.5)
    p.observe(0, [1], wall=1.0)
    p.observe(0, [], wall=1.6)
    assert p.expired(wall=1.6) == [1]
    with pytest.raises(ValueError):
        Presence(0.0)
