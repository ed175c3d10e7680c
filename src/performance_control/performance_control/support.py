"""Is the user supported from above? (Hanging: the bars' engage by the user's own support.)

The monkey bars' example is a swing imitated by a user standing on the floor (Ishigaki et al.
2009, Sec. 8.1). A user who really hangs -- from a pull-up bar in the lab, or CMU subject 01 on a
playground -- barely swings: the hands hold still above the head (the recognizer's activity gate
rightly says "not imitating") and the body dangles or pulls up. What tells the hang is not the
hands' motion but the body's support: both feet have left the user's floor for longer than any
jump can keep them there, and the hands are above the head. A body off the floor for longer than
a ballistic flight is held by something; with both hands overhead, by the hands.

* the user's floor: the lowest foot height seen (the lowest foot, low-passed over ``FLOOR_TAU``
  so that one noisy frame does not lower it), like the controller's first-frame floor but
  following the user when the first frames are off the floor;
* airborne: the lowest foot more than ``CLEARANCE`` above that floor (a foot lifted to step or
  kick keeps the other down; standing on tiptoe raises a foot 0.05-0.08 m);
* supported: airborne for longer than ``MAX_FLIGHT`` s -- the flight time of a 0.45 m standing
  vertical jump, 2 sqrt(2 h / g) = 0.61 s (a good adult jumps 0.3-0.5 m); the feet spend less
  than the whole flight above ``CLEARANCE``;
* hanging: supported with both hands above the head (``hand_above``: the bars' engage joint).
  The jump itself (airborne, hands up, not yet supported) is :attr:`HangDetector.reaching`: the
  controller's reach/jump-to-engage rule under the bars.

No parameter: the constants are physics (a jump's flight time) and sensor facts (tiptoe, noise).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from skeleton_core.model import FOOT_LEFT, FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, JOINT_INDEX

G = 9.81
# m: the lowest foot this far above the user's floor is off it (tiptoe 0.05-0.08 m, Kinect foot
# noise ~0.02 m)
CLEARANCE = 0.12
# s: the longest a jump keeps the feet off the floor (a 0.45 m standing vertical jump)
MAX_FLIGHT = 2.0 * math.sqrt(2.0 * 0.45 / G)
# s: low-pass of the lowest foot before it may lower the floor (one noisy frame does not)
FLOOR_TAU = 0.1


class HangDetector:
    """Per user: :meth:`update` with one pose (20, 3, z up) per frame; then :attr:`airborne`,
    :attr:`supported`, :meth:`hanging` and :meth:`reaching`."""

    def __init__(self):
        self.floor: Optional[float] = None
        self._low: Optional[float] = None
        self._t_last: Optional[float] = None
        self.airborne_since: Optional[float] = None
        self.airborne = False
        self.supported = False
        self._p: Optional[np.ndarray] = None

    def reset(self) -> None:
        self.__init__()

    def update(self, positions: np.ndarray, t: float) -> None:
        p = np.asarray(positions, float)
        low = float(min(p[FOOT_LEFT, 2], p[FOOT_RIGHT, 2]))
        dt = 1.0 / 30.0 if self._t_last is None else max(t - self._t_last, 1e-3)
        self._t_last = t
        if self._low is None:
            self._low = low
        else:
            self._low += (1.0 - math.exp(-dt / FLOOR_TAU)) * (low - self._low)
        self.floor = self._low if self.floor is None else min(self.floor, self._low)
        self.airborne = low - self.floor > CLEARANCE
        if not self.airborne:
            self.airborne_since = None
        elif self.airborne_since is None:
            self.airborne_since = t
        self.supported = bool(self.airborne and t - self.airborne_since > MAX_FLIGHT)
        self._p = p

    def hands_above(self, joint: str = 'Head') -> bool:
        """Both of the user's hands above ``joint``."""
        if self._p is None:
            return False
        z = self._p[JOINT_INDEX[joint], 2]
        return bool(self._p[HAND_LEFT, 2] > z and self._p[HAND_RIGHT, 2] > z)

    def hanging(self, joint: str = 'Head') -> bool:
        """Supported from above: off the floor longer than a jump, both hands above ``joint``."""
        return self.supported and self.hands_above(joint)

    def reaching(self, joint: str = 'Head') -> bool:
        """Off the floor (a jump, or a hang not yet told from one) with both hands above
        ``joint``: reaching up for the bars."""
        return self.airborne and self.hands_above(joint)


__all__ = ['HangDetector', 'CLEARANCE', 'MAX_FLIGHT']
