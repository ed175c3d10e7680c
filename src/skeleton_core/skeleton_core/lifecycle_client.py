"""Bring a lifecycle node to ``active`` over DDS, robust to lost replies: the launch files' manager.

launch_ros's ``autostart`` sends ``configure`` and sends ``activate`` when the node's
``transition_event`` message says it is inactive. On a loaded machine DDS may not have matched
the reply path yet when the node answers (rmw: "failed to send response (timeout): client will
not receive response") and the event can be lost the same way; the node then stays inactive for
good and nothing flows. :func:`drive_to_active` asks the node's state (``get_state``) and requests
the next transition until the node is active, so a lost reply or event costs a retry, not the
graph. A transition the node refuses (a failed configure: the node has logged why) stops it.
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
# the services there but no state reply for this long: the clients are made anew (and it is logged)
SILENT_S = 20.0
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


def drive_to_active(node, name: str, stopped: Callable[[], bool],
                    log: Optional[Callable[[str], None]] = None) -> bool:
    """Take lifecycle node ``name`` (fully qualified) to ``active`` from ``node`` (spun by
    someone else). True once active; False when it refuses a transition, is finalized, or
    ``stopped()`` turns true first."""
    def clients():
        return (node.create_client(GetState, f'{name}/get_state'),
                node.create_client(ChangeState, f'{name}/change_state'))
    get, change = clients()
    lost = 0
    silent_since = None   # the first of the state queries not answered since the last answer
    warned = False
    while not stopped():
        if not get.wait_for_service(timeout_sec=1.0) or \
                not change.wait_for_service(timeout_sec=1.0):
            continue
        reply = call_once(get, GetState.Request(), STATE_TIMEOUT_S)
        if reply is None:
            now = time.monotonic()
            silent_since = silent_since or now
            if now - silent_since >= SILENT_S:
                # the service is there but no reply comes back: a reply path DDS never
                # matched stays unmatched for these clients; new ones are discovered anew
                if log and not warned:
                    log(f'{name}: its lifecycle services do not answer ({now - silent_since:.0f} '
                        's; busy or a lost reply path): still trying, with new clients')
                    warned = True
                node.destroy_client(get)
                node.destroy_client(change)
                get, change = clients()
                silent_since = None
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
            time.sleep(0.2)
            continue
        tid, label = NEXT[state]
        reply = call_once(change, ChangeState.Request(transition=Transition(id=tid)),
                      TRANSITION_TIMEOUT_S)
        if reply is None:
            lost += 1                    # the state says what happened
            continue
        if not reply.success:
            if log:
                log(f'{name}: {label} failed (the node logged why); fix it and '
                    f'`ros2 lifecycle set {name} {label}`')
            return False
    return False


__all__ = ['call_once', 'drive_to_active']
