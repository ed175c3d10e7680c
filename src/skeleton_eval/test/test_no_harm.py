"""The per-segment "no harm" table (skeleton_eval.no_harm) on constructed inputs: which
segment-frames it scores, the angles it sums, and the comparison against the raw sensor."""
import numpy as np
import pytest

from skeleton_core.model import (ELBOW_LEFT, INFERRED, KNEE_RIGHT, NUM_JOINTS, NUM_SEGMENTS,
                                 SEGMENT_CHILD_INDEX, SEGMENT_CHILDREN, TRACKED, WRIST_LEFT,
                                 standard_body)
from skeleton_eval import evaluation as E
from skeleton_eval import metrics as M
from skeleton_eval import no_harm as NH
from skeleton_eval.clips import toy_clip
from skeleton_eval.report import to_markdown
from skeleton_eval.sensor_model import SensorModel


def _seq(T=6):
    return np.repeat(standard_body().rest_positions()[None], T, axis=0)


def _rotate_child(p, seg, deg):
    """``p`` with segment ``seg`` turned by ``deg`` about its parent, the joints below it moved
    along: that segment's direction error is ``deg``, every other segment's 0."""
    from skeleton_core.model import PARENTS, SEGMENT_PARENT_INDEX
    q = p.copy()
    a, c = SEGMENT_PARENT_INDEX[seg], SEGMENT_CHILD_INDEX[seg]
    t = np.radians(deg)
    R = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
    v = q[:, c] - q[:, a]
    # a segment along z does not turn about z: turn about x instead
    if np.allclose(v[:, :2], 0):
        R = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    d = q[:, a] + v @ R.T - q[:, c]
    for j in range(NUM_JOINTS):
        k = j
        while k is not None and k >= 0 and k != c:
            k = PARENTS[k]
        if k == c:
            q[:, j] += d
    return q


def test_mask_needs_both_ends_tracked_and_clean():
    T = 4
    st = np.full((T, NUM_JOINTS), TRACKED, np.uint8)
    st[1, ELBOW_LEFT] = INFERRED
    clean = np.ones((T, NUM_JOINTS), bool)
    clean[2, KNEE_RIGHT] = False
    m = NH.segment_mask(st, clean)
    assert m.shape == (T, NUM_SEGMENTS)
    up = SEGMENT_CHILDREN.index(ELBOW_LEFT)        # shoulder -> elbow
    fore = SEGMENT_CHILDREN.index(WRIST_LEFT)      # elbow -> wrist
    thigh = SEGMENT_CHILDREN.index(KNEE_RIGHT)
    assert not m[1, up] and not m[1, fore] and m[0, up] and m[2, up]
    assert not m[2, thigh] and m[1, thigh]
    assert m[3].all() and m[0].all()
    # without a clean mask (real recordings) only the tracking state counts
    assert NH.segment_mask(st)[2, thigh]


def test_direction_sums_are_the_angles_on_the_masked_frames_only():
    truth = _seq()
    seg = SEGMENT_CHILDREN.index(WRIST_LEFT)
    pred = _rotate_child(truth, seg, 10.0)
    mask = np.ones((len(truth), NUM_SEGMENTS), bool)
    mask[:2, seg] = False
    s, n = NH.direction_sums(pred, truth, mask)
    assert n[seg] == len(truth) - 2
    assert s[seg] / n[seg] == pytest.approx(10.0, abs=1e-6)
    # the same numbers as the unmasked metric on those frames
    per, _ = M.bone_direction_error(pred[2:], truth[2:])
    assert s[seg] / n[seg] == pytest.approx(per[seg])
    # NaN frames (a method without output) are not counted
    pred2 = pred.copy()
    pred2[3] = np.nan
    s2, n2 = NH.direction_sums(pred2, truth, mask)
    assert n2[seg] == n[seg] - 1 and s2[seg] == pytest.approx(s[seg] - 10.0, abs=1e-6)


def test_compare_flags_a_segment_more_than_half_a_degree_worse():
    truth = _seq()
    seg = SEGMENT_CHILDREN.index(WRIST_LEFT)
    other = SEGMENT_CHILDREN.index(KNEE_RIGHT)
    mask = np.ones((len(truth), NUM_SEGMENTS), bool)
    raw = _rotate_child(_rotate_child(truth, seg, 2.0), other, 8.0)
    # the method: worse on the forearm by 1 deg, better on the shin by 6, within 0.5 elsewhere
    meth = _rotate_child(_rotate_child(truth, seg, 3.0), other, 2.0)
    acc_m = NH.add(NH.empty(), *NH.direction_sums(meth, truth, mask))
    acc_r = NH.add(NH.empty(), *NH.direction_sums(raw, truth, mask))
    bad = NH.violations(acc_m, acc_r)
    assert [b['segment'] for b in bad] == [NH.SEGMENT_NAMES[seg]]
    assert bad[0]['diff'] == pytest.approx(1.0, abs=1e-6)
    assert NH.worst(acc_m, acc_r)['segment'] == NH.SEGMENT_NAMES[seg]
    # within tolerance: 2.4 vs 2.0 deg is no harm
    meth_ok = _rotate_child(_rotate_child(truth, seg, 2.4), other, 2.0)
    acc_ok = NH.add(NH.empty(), *NH.direction_sums(meth_ok, truth, mask))
    assert NH.violations(acc_ok, acc_r) == []
    # accumulators pool streams by adding
    both = NH.merge([acc_m, acc_m])
    assert both['count'][seg] == 2 * acc_m['count'][seg]
    assert NH.means(both)[seg] == pytest.approx(NH.means(acc_m)[seg])
    md = NH.to_markdown({'a': {'C': acc_m, 'raw': acc_r}})
    assert '1 of 19 segment-class cells' in md
    assert f'a {NH.SEGMENT_NAMES[seg]} +1.0 ({acc_m["count"][seg]} frames)' in md


def test_evaluate_streams_reports_the_no_harm_sums_per_method():
    """Through the harness: raw on a stream scores its own errors on the masked segments; the
    truth as a method scores zero there, and the report prints the table."""
    clip = toy_clip(seconds=3.0)
    streams = E.make_streams([clip], ('a',), seed=0, sensor=SensorModel(seed=0))
    s = streams['a'][0]

    class Truth:
        name = 'C'

        def reset(self):
            self.i = 0

        def process(self, f):
            out = f.copy(positions=s.truth[self.i].copy())
            self.i += 1
            return out
    res = E.evaluate_streams(['raw', Truth], streams)
    nh_raw = res['results']['raw']['a']['no_harm']
    nh_c = res['results']['C']['a']['no_harm']
    mask = NH.segment_mask(s.tracking_state, s.clean)
    assert nh_raw['count'] == list(mask.sum(axis=0))
    assert NH.overall(nh_raw) > 1.0 and NH.overall(nh_c) == pytest.approx(0.0, abs=1e-6)
    md = to_markdown({'experiment': 'table4', 'results': res['results']})
    assert 'No harm: C against raw' in md and '0 of 19 segment-class cells' in md
    # the bone-length std per segment beside the jitter: the truth's (toy clip: rigid) ~0, the
    # sensor's not
    rows = {ln.split(' | ')[0]: ln for ln in md.splitlines() if ln.startswith('| ')}
    assert 'Bone-length std per segment' in md and '| HipCenter-Spine' in rows
    raw_mean, c_mean = [float(x) for x in rows['| **mean**'].strip(' |').split(' | ')[1:]]
    assert raw_mean > 0.3 and c_mean < 0.01
    assert rows['| jitter m/s²'].count('|') == 4


def test_root_relative_mpjpe_ignores_a_shift_of_the_whole_body():
    truth = _seq()
    pred = truth + np.array([0.3, -0.2, 0.1])
    assert M.mpjpe(pred, truth)[1] == pytest.approx(np.linalg.norm([30, 20, 10]))
    per, tot = M.mpjpe_root_relative(pred, truth)
    assert tot == pytest.approx(0.0, abs=1e-9) and np.isnan(per[0])
    pred[:, WRIST_LEFT] += [0.0, 0.0, 0.19]
    assert M.mpjpe_root_relative(pred, truth)[1] == pytest.approx(19.0 / (NUM_JOINTS - 1))
