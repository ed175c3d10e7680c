"""Bring a lifecycle node to ``active`` over DDS, robust to lost replies: the launch files' manager.

launch_ros's ``autostart`` sends ``configure`` and sends ``activate`` when the node's
``transition_event`` message says it is inactive. On a loaded machine DDS may not have matched
the reply path yet when the node answers (rmw: "failed to send response (timeout): client will
not receive response") and the event can be lost the same way; the node then stays inactive for
good and nothing flows. :func:`drive_to_active` asks the node's state (``get_state``) and requests
the next transition until the node is active, so a lost reply or event costs a retry, not the
graph. A transition the node refuses (a failed configure: the node has logged why) stops it.
Services not discovered, or discovered but silent, for ``SILENT_S`` get one warning and new
clients; an error raised by a call is logged and retried: the bring-up thread never ends
silently with the node left unconfigured.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Optional

from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState

# a state query is answered at once: no answer in this long means the reply was lost
STATE_TIMEOUT_S = 2.0
# a transition may load files (a database, compiled kernels): after this long without an answer,
# the node's state says whether it is still transitioning or the reply was lost
TRANSITION_TIMEOUT_S = 10.0
# the services not discovered, or there but no state reply, for this long: the clients are made
# anew (and it is logged)
SILENT_S = 20.0
# after an error raised by a call (logged), the next attempt
RETRY_S = 1.0
# how long one attempt waits for both services to be discovered, and how often it looks (rclpy's
# Client.wait_for_service looks every 0.25 s: up to that much added to each node's start)
DISCOVER_S = 2.0
DISCOVER_POLL_S = 0.01
TRANSITIONING = {State.TRANSITION_STATE_CONFIGURING: 'configuring',
                 State.TRANSITION_STATE_CLEANINGUP: 'cleaning up',
                 State.TRANSITION_STATE_SHUTTINGDOWN: 'shutting down',
                 State.TRANSITION_STATE_ACTIVATING: 'activating',
                 State.TRANSITION_STATE_DEACTIVATING: 'deactivating',
                 State.TRANSITION_STATE_ERRORPROCESSING: 'processing an error'}
NEXT = {State.PRIMARY_STATE_UNCONFIGURED: (Transition.TRANSITION_CONFIGURE, 'configure'),
        State.PRIMARY_STATE_INACTIVE: (Transition.TRANSITION_ACTIVATE, 'activate')}


def call_once(client, request, timeout_s: float):
    """Send ``request`` once on ``client`` (its node spun by someone else): the response, or
    None when none came within ``timeout_s`` (the pending request is dropped)."""
    done = threading.Event()
    future = client.call_async(request)
    future.add_done_callback(lambda _f: done.set())
    if not done.wait(timeout_s):
        future.cancel()
        try:
            client.remove_pending_request(future)
        except (AttributeError, KeyError):   # older rclpy / already removed
            pass
        return None
    return None if future.exception() is not None else future.result()


def services_ready(clients, timeout_s: float = DISCOVER_S) -> bool:
    """True once every client's service is discovered (looked at every :data:`DISCOVER_POLL_S`),
    False after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not all(c.service_is_ready() for c in clients):
        if time.monotonic() >= deadline:
            return False
        time.sleep(DISCOVER_POLL_S)
    return True


def drive_to_active(node, name: str, stopped: Callable[[], bool],
                    log: Optional[Callable[[str], None]] = None,
                    before_activate: Optional[Callable[[], None]] = None) -> bool:
    """Take lifecycle node ``name`` (fully qualified) to ``active`` from ``node`` (spun by
    someone else). True once active; False when it refuses a transition, is finalized, or
    ``stopped()`` turns true first. ``before_activate`` (once, when the node is inactive and
    about to be activated) may block: a source waits there for the nodes that consume it (the
    state is then asked again); returning False says it did not (activated at once)."""
    def clients():
        return (node.create_client(GetState, f'{name}/get_state'),
                node.create_client(ChangeState, f'{name}/change_state'))
    get = change = None   # made in the loop (an error there is retried like any other)
    lost = 0
    # the first failed attempt (services not discovered or not answering) since the last answer
    silent_since = None
    busy_since = None      # the first state query answered with a transition since
    warned = set()

    def say(why: str, text: str):
        if log and why not in warned:   # once per kind
            log(text)
            warned.add(why)

    def renew():
        nonlocal get, change, silent_since
        for c in (get, change):
            try:
                if c is not None:
                    node.destroy_client(c)
            except Exception:   # noqa: BLE001 -- a client already gone is gone
                pass
        get = change = None
        silent_since = None

    while not stopped():
        try:
            if get is None:
                get, change = clients()
            seen = services_ready((get, change))
            reply = call_once(get, GetState.Request(), STATE_TIMEOUT_S) if seen else None
        except Exception as e:   # noqa: BLE001 -- the bring-up must not end silently
            say(type(e).__name__, f'{name}: lifecycle bring-up: {type(e).__name__}: {e}; '
                'retrying with new clients')
            time.sleep(RETRY_S)
            renew()
            continue
        if reply is None:
            now = time.monotonic()
            silent_since = silent_since or now
            if now - silent_since >= SILENT_S:
                # not discovered (is it running?), or there but no reply comes back (a reply
                # path DDS never matched stays unmatched for these clients): new clients are
                # discovered anew
                if seen:
                    say('silent', f'{name}: its lifecycle services do not answer '
                        f'({now - silent_since:.0f} s; busy or a lost reply path): still '
                        'trying, with new clients')
                else:
                    say('unseen', f'{name}: its lifecycle services not discovered after '
                        f'{now - silent_since:.0f} s (is the process running? `ros2 node '
                        'list`): still waiting, with new clients')
                renew()
            continue
        silent_since = None
        state = reply.current_state.id
        if state == State.PRIMARY_STATE_ACTIVE:
            if lost and log:
                log(f'{name} active ({lost} lost replies retried)')
            return True
        if state == State.PRIMARY_STATE_FINALIZED:
            return False
        if state not in NEXT:            # transitioning: wait for its end
            now = time.monotonic()
            busy_since = busy_since or now
            if now - busy_since >= SILENT_S:
                say('busy', f'{name}: still {TRANSITIONING.get(state, state)} after '
                    f'{now - busy_since:.0f} s: waiting for the transition to end')
            time.sleep(0.2)
            continue
        busy_since = None
        tid, label = NEXT[state]
        if tid == Transition.TRANSITION_ACTIVATE and before_activate is not None:
            waited = before_activate()
            before_activate = None
            if waited is not False:      # the state may have changed meanwhile
                continue
        try:
            reply = call_once(change, ChangeState.Request(transition=Transition(id=tid)),
                              TRANSITION_TIMEOUT_S)
        except Exception as e:   # noqa: BLE001 -- the state says what happened
            say(type(e).__name__, f'{name}: lifecycle bring-up: {type(e).__name__}: {e}; '
                'retrying')
            time.sleep(RETRY_S)
            reply = None
        if reply is None:
            lost += 1                    # the state says what happened
            continue
        if not reply.success:
            if log:
                log(f'{name}: {label} failed (the node logged why); fix it and '
                    f'`ros2 lifecycle set {name} {label}`')
            return False
    return False


__all__ = ['call_once', 'drive_to_active', 'services_ready']
