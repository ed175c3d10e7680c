"""The sensor model's failures of joints it still reports TRACKED: class d's confident failures
(hand snaps, limb swaps, foot slides, jumps to another person) and class e's small persistent
errors. A mixin of :class:`~.sensor_corrupter._Corrupter`, whose per-frame state (random
generator, parameters, scenario, object box, noise terms, events) it uses."""
from __future__ import annotations

import numpy as np

from skeleton_core.geometry import yaw_matrix
from skeleton_core.model import (FOOT_LEFT, FOOT_RIGHT, HAND_LEFT, HAND_RIGHT, HIP_CENTER,
                                 JOINT_INDEX, LIMB_JOINTS, NUM_JOINTS, PARENTS, TRACKED)
from .sensor_geometry import _box_distance


class FailureModes:
    """Classes d and e of :class:`~.sensor_corrupter._Corrupter` (see the module)."""

    def _confident_failures(self, fi, i, truth, pos, state, clean, rel_deg):
        """Class d (``confident_failure`` parameters; rates in the scenario, per minute; the limb
        swap's per minute of side-on time): every mode keeps the joints TRACKED.

        * hand_snap — a hand (with ``wrist_probability`` its wrist too) snaps to the nearest point
          of the scenario's object when within ``surface_reach_m``, else to the other hand when
          within ``other_hand_m`` (and follows it), else to a static surface point
          ``surface_offset_m`` away, and stays there with the ordinary sensor noise (no
          vibration, so the behaviour term of Eq. 1-4 does not see it);
        * limb_swap — while the user is turned at least ``side_on_deg`` from the sensor, the two
          arms (or, with ``legs_probability``, the two legs), girdle joints included, swap;
        * foot_slide — a foot (with ``ankle_probability`` its ankle too) slides along the floor at
          ``speed_m_s`` from where it was reported and sinks up to ``sink_m`` into it;
        * person_jump — for ``duration_frames`` the whole skeleton is another person: the clip's
          posture of another moment, turned and placed ``distance_m`` to the side."""
        cfp = self.p.get('confident_failure') or {}
        sc, rng = self.sc, self.rng

        def rate(mode):
            if not (cfp.get(mode) or {}).get('enabled', False):
                return 0.0
            return self._per_frame(sc.get(f'{mode}_per_min', 0.0))

        def begin(mode, joints, n, cause, **extra):
            self.events.append({'type': mode, 'cause': cause, 'frame': fi, 'joints': list(joints),
                                'duration': int(n), **extra})
            return {'joints': list(joints), 'left': int(n), 'k': 0, 'cause': cause, **extra}

        # hand snap
        hs = cfp.get('hand_snap') or {}
        if self.cf['hand_snap'] is None and self._onset(rate('hand_snap')):
            hand = HAND_LEFT if rng.random() < 0.5 else HAND_RIGHT
            other = HAND_RIGHT if hand == HAND_LEFT else HAND_LEFT
            joints = [hand] + ([PARENTS[hand]] if rng.random() < float(hs['wrist_probability'])
                               else [])
            n = self._duration(hs['duration_s'])
            target, cause = None, 'surface'
            if self.box is not None:
                d, closest = _box_distance(pos[[hand]], *self.box)
                if d[0] < float(hs['surface_reach_m']):
                    target, cause = closest[0], 'object'
            if target is None and np.linalg.norm(pos[other] - pos[hand]) < float(hs['other_hand_m']):
                cause = 'other_hand'
            elif target is None:
                d = rng.standard_normal(3)
                d[2] *= 0.5
                d /= np.linalg.norm(d)
                target = pos[hand] + d * rng.uniform(*hs['surface_offset_m'])
            rel = pos[joints] - pos[hand]
            self.cf['hand_snap'] = begin('hand_snap', joints, n, cause, other=int(other),
                                         target=target, rel=rel)
        e = self.cf['hand_snap']
        if e is not None:
            j = e['joints']
            hand = j[0]
            # the ordinary noise of the joint (its fast and slow error) rides on the wrong point
            noise = self.e_fast[j] + self.e_slow[j]
            if e['cause'] == 'other_hand':
                anchor = pos[e['other']] + 0.03 * np.array([0.0, 1.0 if hand == HAND_RIGHT else
                                                             -1.0, 0.0])
            else:
                anchor = e['target']
            pos[j] = anchor + e['rel'] + noise
            state[j] = TRACKED
            clean[j] = False
            self._tick('hand_snap')

        # left/right limb swap while side-on
        ls = cfp.get('limb_swap') or {}
        side_on = rel_deg >= float(ls.get('side_on_deg', 45.0))
        if self.cf['limb_swap'] is None and side_on and self._onset(rate('limb_swap')):
            legs = rng.random() < float(ls['legs_probability'])
            a, b = (('left_leg', 'right_leg') if legs else ('left_arm', 'right_arm'))
            joints = list(LIMB_JOINTS[a]) + list(LIMB_JOINTS[b])
            self.cf['limb_swap'] = begin('limb_swap', joints, self._duration(ls['duration_s']),
                                         'side_on', limbs='legs' if legs else 'arms')
        e = self.cf['limb_swap']
        if e is not None:
            j = e['joints']
            h = len(j) // 2
            sw = j[h:] + j[:h]
            pos[j] = pos[sw]
            state[j] = state[sw]
            clean[j] = False
            self._tick('limb_swap')

        # foot slide
        fs = cfp.get('foot_slide') or {}
        if self.cf['foot_slide'] is None and self._onset(rate('foot_slide')):
            foot = FOOT_LEFT if rng.random() < 0.5 else FOOT_RIGHT
            joints = [foot] + ([PARENTS[foot]] if rng.random() < float(fs['ankle_probability'])
                               else [])
            ang = rng.uniform(0, 2 * np.pi)
            vel = rng.uniform(*fs['speed_m_s']) / self.fps * np.array([np.cos(ang), np.sin(ang),
                                                                         0.0])
            self.cf['foot_slide'] = begin('foot_slide', joints, self._duration(fs['duration_s']),
                                          'random', start=pos[joints].copy(), vel=vel,
                                          sink=float(rng.uniform(*fs['sink_m'])))
        e = self.cf['foot_slide']
        if e is not None:
            j = e['joints']
            e['k'] += 1
            p_new = e['start'] + e['k'] * e['vel']
            sink = e['sink'] * min(1.0, e['k'] / 5.0)
            foot_z = self.floor - sink
            p_new[0, 2] = foot_z
            if len(j) > 1:
                p_new[1, 2] = min(p_new[1, 2], foot_z + 0.05)
            pos[j] = p_new + self.e_fast[j]
            state[j] = TRACKED
            clean[j] = False
            self._tick('foot_slide', count=False)

        # the whole skeleton jumps to another person
        pj = cfp.get('person_jump') or {}
        if self.cf['person_jump'] is None and self._onset(rate('person_jump')):
            lo, hi = (int(v) for v in pj['duration_frames'])
            n = int(rng.integers(lo, hi + 1))
            other = self.truth_all[int(rng.integers(0, self.T))]
            root = other[HIP_CENTER]
            yaw = rng.uniform(-np.pi, np.pi)
            shift = np.array([rng.uniform(-0.3, 0.3),
                              rng.choice([-1.0, 1.0]) * rng.uniform(*pj['distance_m']), 0.0])
            ghost = (other - root) @ yaw_matrix(yaw).T + root + shift
            ghost[:, 2] += truth[:, 2].min() - ghost[:, 2].min()
            self.cf['person_jump'] = begin('person_jump', range(NUM_JOINTS), n, 'random',
                                           ghost=ghost)
        e = self.cf['person_jump']
        if e is not None:
            pos[:] = e['ghost'] + self.e_fast + self.e_slow
            state[:] = TRACKED
            clean[:] = False
            self._tick('person_jump')

    def _tracked_error(self, fi, truth, pos, state, clean):
        """Class e (``tracked_error`` parameters, rate ``tracked_error_per_min`` in the
        scenario): a joint of ``joints`` that the sensor reports TRACKED sits 5-15 cm
        (``offset_m``) from its true centre for ``duration_s``, still TRACKED, with a little
        vibration (``vibration_mm``) and the ordinary noise; its parent joint (the neighbour the
        SDK's skeleton fit drags along) is pulled by ``neighbour_fraction`` of that offset. Two
        modes: with ``rest_probability`` *rest* (a hand or foot resting on an object: the joint is
        reported at a point fixed in the room, ``offset_m`` from where it was; the offset changes
        as the limb moves), else *drift* (a joint centre drifting: an offset of fixed direction
        and size carried with the joint). Both ramp in and out over ``ramp_s``. Unlike class d's
        snaps the errors are small (the length of a hand) and last seconds; unlike the false
        positives they do not vibrate, so the behaviour term of Eq. 1-4 cannot see them."""
        te = self.p.get('tracked_error') or {}
        rate = 0.0
        if te.get('enabled', False):
            rate = self._per_frame(self.sc.get('tracked_error_per_min', 0.0))
        rng = self.rng
        if self.te is None and self._onset(rate):
            cands = [JOINT_INDEX[n] for n in te['joints']]
            cands = [j for j in cands if state[j] == TRACKED and state[PARENTS[j]] == TRACKED]
            if cands:
                j = int(rng.choice(cands))
                n = self._duration(te['duration_s'])
                d = rng.standard_normal(3)
                d /= np.linalg.norm(d)
                size = float(rng.uniform(*te['offset_m']))
                rest = rng.random() < float(te['rest_probability'])
                frac = float(rng.uniform(*te['neighbour_fraction']))
                self.te = {'joint': j, 'parent': int(PARENTS[j]), 'left': n, 'n': n, 'k': 0,
                           'mode': 'rest' if rest else 'drift', 'frac': frac,
                           'offset': d * size, 'point': pos[j] + d * size}
                self.events.append({'type': 'tracked_error', 'cause': self.te['mode'],
                                    'frame': fi, 'joints': [j, int(PARENTS[j])], 'duration': n,
                                    'offset_m': size, 'neighbour_fraction': frac})
        e = self.te
        if e is None:
            return
        j, par = e['joint'], e['parent']
        ramp = max(1, int(round(float(te.get('ramp_s', 0.5)) * self.fps)))
        a = min(1.0, (e['k'] + 1) / ramp, e['left'] / ramp)
        if e['mode'] == 'rest':
            off = e['point'] - truth[j]
            size = np.linalg.norm(off)
            lo, hi = (float(v) for v in te['offset_m'])
            if size > hi:   # the limb moved away: the joint lets go of the point partway
                off *= hi / size
            elif size < lo:
                off = off * (lo / max(size, 1e-6)) if size > 1e-6 else e['offset']
        else:
            off = e['offset']
        vib = rng.standard_normal(3) * float(te.get('vibration_mm', 0.0)) * 1e-3
        if state[j] == TRACKED:
            pos[j] = pos[j] + a * off + vib
            clean[j] = False
        if state[par] == TRACKED:
            pos[par] = pos[par] + a * e['frac'] * off
            clean[par] = False
        e['k'] += 1
        e['left'] -= 1
        if e['left'] <= 0:
            self.te = None

    def _onset(self, p: float) -> bool:
        """A Bernoulli draw with probability ``p``; no draw at all when ``p`` is 0, so classes
        without confident failures keep the random sequence (and streams) they had before."""
        return p > 0.0 and self.rng.random() < p

    def _tick(self, mode, count=True):
        e = self.cf[mode]
        if count:
            e['k'] += 1
        e['left'] -= 1
        if e['left'] <= 0:
            self.cf[mode] = None
