"""The sensor model's per-frame state machine (:class:`_Corrupter`), shared by
:meth:`~.sensor_model.SensorModel.corrupt` and :meth:`~.sensor_model.SensorModel.stream`: the
user turning away, noise (jitter, drift, systematic offsets), field of view and range, geometric
and random occlusion, false positives and left/right confusion (classes a-c); the failure modes
of classes d and e come from :class:`~.sensor_failures.FailureModes`."""
from __future__ import annotations

import zlib
from typing import Dict, List, Optional

import numpy as np

from skeleton_core.geometry import facing_yaw, yaw_matrix
from skeleton_core.model import (HIP_CENTER, HIP_LEFT, HIP_RIGHT, INFERRED, JOINT_INDEX, LIMB_JOINTS,
                                 MIRROR, NOT_TRACKED, NUM_JOINTS, PARENTS, SEGMENT_CHILD_INDEX,
                                 SEGMENT_PARENT_INDEX, SHOULDER_LEFT, SHOULDER_RIGHT, SPINE, TRACKED,
                                 estimate_height, standard_body)
from .sensor_failures import FailureModes
from .sensor_geometry import (_OCCLUDABLE, _box_distance, _point_segment_2d, _ray_box, _shifted,
                              _wrap)
from .sensor_params import CONFIDENT_FAILURES, JOINT_GROUP, LIMBS, _group_array


class _Corrupter(FailureModes):
    """Per-frame state machine shared by :meth:`SensorModel.corrupt` and :meth:`SensorModel.stream`
    (``model``: the :class:`~.sensor_model.SensorModel`)."""

    def __init__(self, model, clip, scenario: str, seed: int, view=None,
                 time_shift_s: float = 0.0):
        if scenario not in model.params['scenarios']:
            raise ValueError(f'unknown scenario {scenario!r}; '
                             f'known: {sorted(model.params["scenarios"])}')
        self.p = model.params
        self.sc = self.p['scenarios'][scenario]
        self.scenario = scenario
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.turns_drawn = False   # several views: the turns are drawn ahead, in the truth
        self.fps = float(self.p['fps'])
        self.truth_all = model.place(clip)
        self.height = float(self.p['placement']['sensor_height_m'])
        if view is not None:
            # one of several sensors (see SensorModel.stream): the same people (and the same
            # turns, drawn from the stream's own seed) seen from this sensor, with its own noise,
            # occlusion and failures (drawn from a seed of the view)
            tag = zlib.crc32(' '.join(f'{v:.6f}' for v in view.xyz_ypr()).encode())
            self.rng = np.random.default_rng((seed * 1_000_003 + tag + 1) % (2 ** 31))
            self.truth_all = self._turned(self.truth_all, np.random.default_rng(seed))
            if time_shift_s:
                self.truth_all = _shifted(self.truth_all, float(time_shift_s) * self.fps)
            ref_truth = self.truth_all
            self.truth_all = view.inverse().apply(self.truth_all)
            self.height += float(view.translation[2])
        self.T = len(self.truth_all)
        rng = self.rng
        # body size for the capsules
        self.body = standard_body(float(np.clip(estimate_height(self.truth_all[0]), 1.0, 2.4)))
        self.radii = self.body.segment_radii * float(self.p['occlusion_geometry']['radius_scale'])
        # noise tables
        self.base = _group_array(self.p['jitter']['base_mm']) * 1e-3
        self.slow_sigma = _group_array(self.p['slow_drift']['sigma_mm']) * 1e-3
        self.sys_sigma = _group_array(self.p['systematic']['sigma_mm']) * 1e-3
        self.sys_offset = rng.standard_normal((NUM_JOINTS, 3)) * self.sys_sigma[:, None]
        self.e_fast = np.zeros((NUM_JOINTS, 3))
        self.e_slow = rng.standard_normal((NUM_JOINTS, 3)) * self.slow_sigma[:, None]
        self.first = True
        # object for classes b/c
        self.box = None
        obj = self.sc.get('object')
        if obj:
            # one object in the room: placed between the user and the *reference* sensor (drawn
            # from the stream's seed, so every view has the same one) and seen by each view from
            # its own place. Its box in a view's frame: the bounds of its corners there (exact for
            # views turned by multiples of 90 deg about z, the evaluation's front + side)
            orng = rng if view is None else np.random.default_rng(seed)
            ref = self.truth_all if view is None else ref_truth
            ref_height = float(self.p['placement']['sensor_height_m'])
            root = ref[:, HIP_CENTER]
            near_x = float(np.min(ref[..., 0]))
            gap = orng.uniform(*obj['gap_m'])
            width = orng.uniform(*obj['width_m'])
            top = orng.uniform(*obj['top_m']) - ref_height
            yc = float(np.median(root[:, 1])) + orng.uniform(*obj['lateral_m'])
            floor = -ref_height
            x1 = near_x - 0.02 if gap < 0.5 else near_x - gap + float(obj['depth_m'])
            x1 = min(x1, near_x - 0.02)
            x0 = x1 - float(obj['depth_m'])
            lo, hi = np.array([x0, yc - width / 2, floor]), np.array([x1, yc + width / 2, top])
            if view is not None:
                corners = np.array([[a[0], b[1], c[2]] for a in (lo, hi) for b in (lo, hi)
                                    for c in (lo, hi)])
                corners = view.inverse().apply(corners)
                lo, hi = corners.min(axis=0), corners.max(axis=0)
            self.box = (lo, hi)
            self.proximity_fp = bool(obj.get('proximity_fp', False))
        else:
            self.proximity_fp = False
        # dynamic state
        self.last = None               # last reported positions
        self.hold = None               # last position reported while TRACKED
        self.occ = None                # active random occlusion episode
        self.fps_eps: List[Dict] = []  # active false positives
        self.turn = None               # active turn episode
        self.mirrored = False
        self.cf: Dict[str, Optional[Dict]] = {k: None for k in CONFIDENT_FAILURES}
        self.te: Optional[Dict] = None  # active small tracked error (class e)
        self.floor = -self.height
        self.events: List[Dict] = list(getattr(self, 'turn_events', []))
        self.frame_index = 0
        self.fp_joints = [JOINT_INDEX[n] for n in self.sc.get('fp_joints', [])]
        w = np.asarray(self.sc.get('limb_weights', [1, 1, 1, 1]), float)
        self.limb_p = w / w.sum() if w.sum() > 0 else np.full(4, 0.25)
        # what the tracker reports for what it cannot see (``reporting``): a per-joint state and
        # the joint held (Kinect SDK, NiTE2), or every joint TRACKED and an unseen one predicted
        # (Azure Kinect body tracking). The prediction error has its own random stream, so the
        # held-joint model's draws are unchanged.
        rep = self.p.get('reporting', {})
        self.states = bool(rep.get('tracking_states', True))
        self.predict = rep.get('unseen', 'hold') == 'predict'
        if self.predict:
            self.pred_rng = np.random.default_rng((seed * 7919 + 17) % (2 ** 31))
            self.pred_sigma = float(rep.get('predicted_error_mm', 0.0)) * 1e-3
            self.pred_rho = float(rep.get('predicted_rho', 0.95))
            self.e_pred = self.pred_rng.standard_normal((NUM_JOINTS, 3)) * self.pred_sigma

    # -------------------------------------------------------------------------------------
    def _per_frame(self, rate_per_min: float) -> float:
        return float(rate_per_min) / 60.0 / self.fps

    def _duration(self, rng_pair) -> int:
        return max(1, int(round(self.rng.uniform(*rng_pair) * self.fps)))

    def _turn_step(self, truth: np.ndarray, rng, fi: int) -> np.ndarray:
        """The user turning away: maybe begin a turn episode, apply the current one's yaw."""
        p, sc = self.p, self.sc
        if self.turn is None and rng.random() < self._per_frame(sc.get('turn_per_min', 0.0)):
            n = max(1, int(round(rng.uniform(*p['turn']['duration_s']) * self.fps)))
            peak = np.deg2rad(rng.uniform(*p['turn']['peak_deg'])) * rng.choice([-1.0, 1.0])
            prof = peak * 0.5 * (1 - np.cos(2 * np.pi * (np.arange(n) + 1) / (n + 1)))
            self.turn = {'profile': prof, 'k': 0}
            self.events.append({'type': 'turn', 'cause': 'random', 'frame': fi, 'joints': [],
                                'duration': n, 'peak_deg': float(np.rad2deg(peak))})
        if self.turn is not None:
            yaw = self.turn['profile'][self.turn['k']]
            self.turn['k'] += 1
            if self.turn['k'] >= len(self.turn['profile']):
                self.turn = None
            root = truth[HIP_CENTER].copy()
            truth = (truth - root) @ yaw_matrix(yaw).T + root
        return truth

    def _turned(self, truth_all: np.ndarray, rng) -> np.ndarray:
        """Several views: every frame's turn drawn ahead from ``rng`` (the same for every view)."""
        self.events, self.turn = [], None
        out = np.stack([self._turn_step(t, rng, i) for i, t in enumerate(truth_all)])
        self.turn_events = self.events
        self.turns_drawn = True
        return out

    def step(self, i: int):
        """Process truth frame ``i`` (of the placed clip); returns (positions, state, truth, clean)."""
        rng, p, sc = self.rng, self.p, self.sc
        fi = self.frame_index
        truth = self.truth_all[i].copy()
        clean = np.ones(NUM_JOINTS, bool)

        # --- the user turning away (changes the truth) ------------------------------------
        if not self.turns_drawn:
            truth = self._turn_step(truth, rng, fi)
        body_yaw = float(facing_yaw(truth))
        to_sensor = float(np.arctan2(-truth[HIP_CENTER, 1], -truth[HIP_CENTER, 0]))
        rel = abs(float(_wrap(body_yaw - to_sensor)))
        rel_deg = np.rad2deg(rel)
        tp = p['turn']
        gain = 1.0
        if rel_deg > tp['degrade_deg']:
            ramp = min(1.0, (rel_deg - tp['degrade_deg']) / max(90.0 - tp['degrade_deg'], 1e-6))
            gain = 1.0 + (float(tp['jitter_gain']) - 1.0) * ramp
            clean[:] = False

        # --- noise ------------------------------------------------------------------------
        depth = np.maximum(truth[:, 0], 0.1)
        sig = np.repeat((self.base * gain)[:, None], 3, axis=1)
        sig[:, 0] = np.hypot(sig[:, 0], float(p['jitter']['depth_coeff_mm']) * 1e-3 * depth ** 2)
        rho = float(p['jitter']['rho'])
        rs = float(p['slow_drift']['rho'])
        if self.first:
            self.e_fast = rng.standard_normal((NUM_JOINTS, 3)) * sig
            self.first = False
        else:
            self.e_fast = rho * self.e_fast + np.sqrt(1 - rho ** 2) * sig * \
                rng.standard_normal((NUM_JOINTS, 3))
        self.e_slow = rs * self.e_slow + np.sqrt(1 - rs ** 2) * self.slow_sigma[:, None] * \
            rng.standard_normal((NUM_JOINTS, 3))
        pos = truth + self.sys_offset @ yaw_matrix(body_yaw).T + self.e_fast + self.e_slow
        state = np.full(NUM_JOINTS, TRACKED, np.uint8)
        if self.hold is None:
            self.hold = pos.copy()
            self.last = pos.copy()
        hold_noise = float(p['occlusion_geometry']['hold_noise_mm']) * 1e-3

        if self.predict:
            r = self.pred_rho
            self.e_pred = r * self.e_pred + np.sqrt(1 - r ** 2) * self.pred_sigma * \
                self.pred_rng.standard_normal((NUM_JOINTS, 3))
        seen = pos.copy()   # what a predicting tracker reports before the unseen error

        def make_inferred(mask, st=INFERRED):
            idx = np.flatnonzero(mask)
            if len(idx) and self.predict:
                pos[idx] = seen[idx] + self.e_pred[idx]
                state[idx] = np.minimum(state[idx], st)
                clean[idx] = False
            elif len(idx):
                pos[idx] = self.hold[idx] + rng.standard_normal((len(idx), 3)) * hold_noise / 3
                state[idx] = np.minimum(state[idx], st)
                clean[idx] = False

        # --- field of view and range -------------------------------------------------------
        pl = p['placement']
        hang = np.abs(np.arctan2(truth[:, 1], truth[:, 0]))
        vang = np.abs(np.arctan2(truth[:, 2], truth[:, 0]))
        out = ((truth[:, 0] < pl['min_range_m']) | (truth[:, 0] > pl['max_range_m']) |
               (hang > np.deg2rad(pl['horizontal_fov_deg']) / 2) |
               (vang > np.deg2rad(pl['vertical_fov_deg']) / 2))
        make_inferred(out, NOT_TRACKED)

        # --- geometric occlusion ------------------------------------------------------------
        occluded = np.zeros(NUM_JOINTS, bool)
        if sc.get('self_occlusion'):
            occluded |= self._self_occluded(truth)
        if self.box is not None:
            occluded |= _ray_box(truth, *self.box)
        # turned away: the far-side limbs are inferred
        if rel_deg > tp['degrade_deg']:
            left_far = (np.linalg.norm(truth[SHOULDER_LEFT]) > np.linalg.norm(truth[SHOULDER_RIGHT]))
            side = ('left' if left_far else 'right')
            for limb in (side + '_arm', side + '_leg'):
                occluded[list(LIMB_JOINTS[limb][1:])] = True
        make_inferred(occluded & ~out)

        # --- random occlusion episodes ------------------------------------------------------
        if self.occ is None and rng.random() < self._per_frame(sc.get('occlusion_per_min', 0.0)):
            limb = LIMBS[rng.choice(4, p=self.limb_p)]
            chain = LIMB_JOINTS[limb]  # shoulder/hip, elbow/knee, wrist/ankle, hand/foot
            joints = list(chain[2:])
            if rng.random() < float(p['episodes']['elbow_knee_probability']):
                joints = [chain[1]] + joints
            u = rng.random()
            ntf = float(sc.get('not_tracked_fraction', 0.0))
            mode = 'not_tracked' if u < ntf else (
                'collapse' if rng.random() < float(sc.get('collapse_fraction', 0.5)) else 'freeze')
            n = self._duration(p['episodes']['duration_s'])
            self.occ = {'joints': joints, 'mode': mode, 'left': n, 'k': 0, 'limb': limb,
                        'start': self.last[joints].copy()}
            self.events.append({'type': 'occlusion', 'cause': 'random', 'frame': fi,
                                'joints': joints, 'duration': n, 'mode': mode, 'limb': limb})
        if self.occ is not None:
            o = self.occ
            j = o['joints']
            if self.predict:   # a predicting tracker fills a lost limb with its prediction
                target = self._collapse_targets(truth, o['limb'], j) if o['mode'] == 'collapse' \
                    else None
                pos[j] = seen[j] + self.e_pred[j] if target is None else target + self.e_pred[j]
                state[j] = INFERRED
            elif o['mode'] == 'not_tracked':
                pos[j] = self.hold[j]
                state[j] = NOT_TRACKED
            elif o['mode'] == 'freeze':
                pos[j] = o['start'] + rng.standard_normal((len(j), 3)) * hold_noise / 3
                state[j] = INFERRED
            else:  # collapse: arms fall onto the hip/spine side, legs straight under the hip
                target = self._collapse_targets(truth, o['limb'], j)
                a = min(1.0, (o['k'] + 1) / max(1, int(p['episodes']['collapse_frames'])))
                pos[j] = (1 - a) * o['start'] + a * target + \
                    rng.standard_normal((len(j), 3)) * hold_noise / 3
                state[j] = INFERRED
            clean[j] = False
            o['k'] += 1
            o['left'] -= 1
            if o['left'] <= 0:
                self.occ = None

        # --- false positives ----------------------------------------------------------------
        fpp = p['false_positive']
        active = {j for e in self.fps_eps for j in e['joints']}
        cands = [j for j in self.fp_joints if j not in active]
        onset = None
        if cands and rng.random() < self._per_frame(sc.get('false_positive_per_min', 0.0)):
            onset = ('random', int(rng.choice(cands)), None)
        elif cands and self.proximity_fp and self.box is not None:
            d, closest = _box_distance(truth[cands], *self.box)
            near = np.flatnonzero(d < float(fpp['proximity_m']))
            if len(near) and rng.random() < float(fpp['proximity_per_s']) / self.fps * len(near):
                k = int(rng.choice(near))
                onset = ('proximity', cands[k], closest[k])
        if onset is not None:
            cause, j, point = onset
            joints = [j]
            par = PARENTS[j]
            if (JOINT_GROUP[j] in ('hand', 'foot') and par not in active and
                    rng.random() < float(fpp['parent_probability'])):
                joints.append(par)
            if point is None:
                d = rng.standard_normal(3)
                d[2] *= 0.5
                d /= np.linalg.norm(d)
                point = truth[j] + d * rng.uniform(*fpp['offset_m'])
            n = self._duration(fpp['duration_s'])
            pts = np.array([point + (truth[k] - truth[j]) * 0.3 for k in joints])
            self.fps_eps.append({'joints': joints, 'points': pts, 'left': n})
            self.events.append({'type': 'false_positive', 'cause': cause, 'frame': fi,
                                'joints': joints, 'duration': n})
        vib = float(fpp['vibration_mm']) * 1e-3
        for e in self.fps_eps:
            j = e['joints']
            pos[j] = e['points'] + rng.standard_normal((len(j), 3)) * vib
            state[j] = TRACKED
            clean[j] = False
            e['left'] -= 1
        self.fps_eps = [e for e in self.fps_eps if e['left'] > 0]

        # --- left/right confusion when facing away ----------------------------------------
        h = tp['hysteresis_deg']
        if not self.mirrored and rel_deg > tp['confusion_deg']:
            self.mirrored = True
            self.events.append({'type': 'mirror', 'cause': 'turn', 'frame': fi, 'joints': [],
                                'duration': 0})
        elif self.mirrored and rel_deg < tp['confusion_deg'] - h:
            self.mirrored = False
        if self.mirrored:
            pos = pos[list(MIRROR)]
            state = state[list(MIRROR)]
            clean[:] = False

        # --- confident failures (class d): wrong places reported TRACKED ---------------------
        self._confident_failures(fi, i, truth, pos, state, clean, rel_deg)
        # --- small persistent errors of TRACKED joints (class e) -----------------------------
        self._tracked_error(fi, truth, pos, state, clean)

        tracked = state == TRACKED
        self.hold[tracked] = pos[tracked]
        self.last = pos.copy()
        self.frame_index += 1
        if not self.states:   # no per-joint state in the tracker's message: all TRACKED
            state = np.full(NUM_JOINTS, TRACKED, np.uint8)
        return pos, state, truth, clean

    def _collapse_targets(self, truth, limb, joints):
        """Where the SDK puts a collapsed limb: an arm folded onto the side of the trunk (joints
        spread from the spine down to the hip), a leg hanging straight under its hip (joints at
        their bone-length distances below it, not below the floor)."""
        if limb.endswith('arm'):
            hip = truth[HIP_LEFT if limb.startswith('left') else HIP_RIGHT]
            spine = truth[SPINE]
            a = (np.arange(len(joints)) + 1.0) / len(joints)
            return (1 - a)[:, None] * spine + a[:, None] * hip
        hip_j = HIP_LEFT if limb.startswith('left') else HIP_RIGHT
        hip = truth[hip_j]
        floor = float(truth[:, 2].min())
        bone = self.body.bone_lengths_by_joint()
        out = []
        for j in joints:
            drop, k = 0.0, j
            while k != hip_j and k > 0:
                drop += bone[k] if JOINT_GROUP[k] != 'foot' else 0.0
                k = PARENTS[k]
            out.append([hip[0], hip[1], max(hip[2] - drop, floor)])
        return np.array(out)

    def _self_occluded(self, truth: np.ndarray) -> np.ndarray:
        x = np.maximum(truth[:, 0], 1e-3)
        uv = truth[:, 1:] / x[:, None]
        a = uv[SEGMENT_PARENT_INDEX]
        b = uv[SEGMENT_CHILD_INDEX]
        d, t = _point_segment_2d(uv, a, b)                     # (20, 19)
        xa = truth[SEGMENT_PARENT_INDEX, 0]
        xb = truth[SEGMENT_CHILD_INDEX, 0]
        xs = xa[None] + t * (xb - xa)[None]                     # depth of the closest point
        rad = self.radii[None] / np.maximum(xs, 1e-3)           # angular radius
        occ = (d < rad) & (xs + self.radii[None] * 0.5 < x[:, None]) & _OCCLUDABLE
        return occ.any(axis=1)
