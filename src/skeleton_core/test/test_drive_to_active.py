"""drive_to_active without DDS: a node whose lifecycle services are there but never answer (a
reply path DDS did not match) or are never discovered gets new clients after SILENT_S, with one
warning, and is then driven to active; an error raised by a call is logged and retried; a
``before_activate`` hook runs once between configure and activate."""
import time

import pytest

pytest.importorskip('lifecycle_msgs')

from lifecycle_msgs.msg import State, Transition  # noqa: E402
from lifecycle_msgs.srv import GetState  # noqa: E402

from skeleton_core import lifecycle_client as lc  # noqa: E402


class _Future:
    def __init__(self, result):
        self._result = result

    def add_done_callback(self, cb):
        if self._result is not None:
            cb(self)

    def cancel(self):
        pass

    def exception(self):
        return None

    def result(self):
        return self._result


class _Client:
    def __init__(self, srv_type, answers, seen=True, raises=False):
        self.srv_type, self.answers, self.seen, self.raises = srv_type, answers, seen, raises

    def service_is_ready(self):
        return self.seen

    def call_async(self, request):
        if self.raises:
            raise RuntimeError('wait set index too big')
        if not self.answers:
            return _Future(None)
        reply = self.srv_type.Response()
        if self.srv_type is GetState:
            self.busy = getattr(self, 'busy', 0) - 1
            reply.current_state.id = State.TRANSITION_STATE_CONFIGURING if self.busy >= 0 \
                else State.PRIMARY_STATE_ACTIVE
        return _Future(reply)

    def remove_pending_request(self, future):
        pass


class _Node:
    """The first pair of clients never hears back (``first``: 'silent'), never finds the
    services ('unseen') or raises on a call ('raises'); the clients made after it work."""

    def __init__(self, first='silent'):
        self.made, self.destroyed, self.first = [], [], first

    def create_client(self, srv_type, name):
        later = len(self.made) >= 2
        c = _Client(srv_type, answers=later, seen=later or self.first != 'unseen',
                    raises=not later and self.first == 'raises')
        self.made.append(c)
        return c

    def destroy_client(self, c):
        self.destroyed.append(c)


@pytest.fixture(autouse=True)
def _short_discovery(monkeypatch):
    monkeypatch.setattr(lc, 'DISCOVER_S', 0.01)


class _Appears:
    """A client whose service is discovered at its ``after``-th look."""

    def __init__(self, after):
        self.after, self.looks = after, 0

    def service_is_ready(self):
        self.looks += 1
        return self.looks >= self.after


def test_services_ready_looks_until_every_service_is_there():
    a, b = _Appears(3), _Appears(5)
    assert lc.services_ready((a, b), timeout_s=5.0)
    assert b.looks == 5        # returned at the look that found the last one, not a later one
    never = _Appears(10 ** 9)
    assert not lc.services_ready((a, never), timeout_s=0.05)


def test_clients_made_anew_when_the_services_never_answer(monkeypatch):
    monkeypatch.setattr(lc, 'STATE_TIMEOUT_S', 0.01)
    monkeypatch.setattr(lc, 'SILENT_S', 0.05)
    node, logged = _Node(), []
    deadline = time.monotonic() + 5.0
    assert lc.drive_to_active(node, '/n', lambda: time.monotonic() > deadline, logged.append)
    assert len(node.made) == 4 and node.destroyed == node.made[:2]
    assert len(logged) == 1 and 'do not answer' in logged[0]


def test_clients_made_anew_when_the_services_are_never_discovered(monkeypatch):
    monkeypatch.setattr(lc, 'SILENT_S', 0.05)
    node, logged = _Node('unseen'), []
    deadline = time.monotonic() + 10.0
    assert lc.drive_to_active(node, '/n', lambda: time.monotonic() > deadline, logged.append)
    assert len(node.made) == 4 and node.destroyed == node.made[:2]
    assert len(logged) == 1 and 'not discovered' in logged[0] and '/n' in logged[0]


def test_an_error_raised_by_a_call_is_logged_and_retried(monkeypatch):
    monkeypatch.setattr(lc, 'RETRY_S', 0.01)
    node, logged = _Node('raises'), []
    deadline = time.monotonic() + 5.0
    assert lc.drive_to_active(node, '/n', lambda: time.monotonic() > deadline, logged.append)
    assert len(node.made) == 4
    assert len(logged) == 1 and 'RuntimeError' in logged[0]



class _BusyNode:
    """Its state answers 'configuring' ``busy`` times (0.2 s apart), then 'active'."""

    def __init__(self, busy):
        self.get = _Client(GetState, answers=True)
        self.get.busy = busy

    def create_client(self, srv_type, name):
        return self.get if srv_type is GetState else _Client(srv_type, answers=True)

    def destroy_client(self, c):
        pass


def test_a_transition_that_does_not_end_is_logged(monkeypatch):
    monkeypatch.setattr(lc, 'SILENT_S', 0.5)
    deadline = time.monotonic() + 5.0
    logged = []
    assert lc.drive_to_active(_BusyNode(6), '/n', lambda: time.monotonic() > deadline,
                              logged.append)
    assert len(logged) == 1 and 'still configuring' in logged[0], logged
    logged.clear()   # a short transition says nothing
    assert lc.drive_to_active(_BusyNode(1), '/n', lambda: time.monotonic() > deadline,
                              logged.append)
    assert logged == []


class _StatefulNode:
    """Unconfigured until asked to configure, inactive until asked to activate; ``events``
    records the transitions requested."""

    def __init__(self):
        self.state, self.events = State.PRIMARY_STATE_UNCONFIGURED, []
        node = self

        class Client(_Client):
            def call_async(self, request):
                reply = self.srv_type.Response()
                if self.srv_type is GetState:
                    reply.current_state.id = node.state
                else:
                    tid = request.transition.id
                    node.events.append(tid)
                    node.state = {Transition.TRANSITION_CONFIGURE: State.PRIMARY_STATE_INACTIVE,
                                  Transition.TRANSITION_ACTIVATE: State.PRIMARY_STATE_ACTIVE}[tid]
                    reply.success = True
                return _Future(reply)
        self._client = Client

    def create_client(self, srv_type, name):
        return self._client(srv_type, answers=True)

    def destroy_client(self, c):
        pass


def test_before_activate_runs_once_between_configure_and_activate():
    node = _StatefulNode()

    def hold():
        node.events.append('hold')
        assert node.state == State.PRIMARY_STATE_INACTIVE   # configured, not yet active

    deadline = time.monotonic() + 5.0
    assert lc.drive_to_active(node, '/driver', lambda: time.monotonic() > deadline,
                              before_activate=hold)
    assert node.events == [Transition.TRANSITION_CONFIGURE, 'hold', Transition.TRANSITION_ACTIVATE]
