"""viz.report: the offline report on tiny synthetic input (in memory and a small MCAP bag)."""
import json

import numpy as np
import pytest

from skeleton_core.model import ELBOW_LEFT, HAND_LEFT, NUM_JOINTS, WRIST_LEFT, standard_body
from viz import report
from viz.render import Panel, render_frames
from viz.series import ROLE_TOPICS, SkeletonSeries

N = 24  # frames at 30 Hz


def _truth():
    p = np.repeat((standard_body().rest_positions() + (2.5, 0.0, 0.0))[None], N, 0)
    t = np.arange(N) / 30.0
    p[:, [ELBOW_LEFT, WRIST_LEFT, HAND_LEFT], 2] += 0.3 * np.sin(2 * np.pi * t)[:, None]
    return p


def _series():
    rng = np.random.default_rng(1)
    gt = _truth()
    stamps = 1_000_000_000 + np.round(np.arange(N) * 1e9 / 30).astype(np.int64)
    raw = gt + rng.normal(0, 0.03, gt.shape)
    ts = np.full((N, NUM_JOINTS), 2, np.uint8)
    ts[5:15, HAND_LEFT] = 1
    rel = np.ones((N, NUM_JOINTS), np.float32)
    rel[5:15, HAND_LEFT] = 0.1
    return {
        'raw': SkeletonSeries.from_arrays(raw, stamps, ts, None, user_id=1),
        'reliability': SkeletonSeries.from_arrays(raw, stamps, ts, rel, user_id=1),
        'reconstructed': SkeletonSeries.from_arrays(gt + 0.01, stamps, user_id=1),
        'ground_truth': SkeletonSeries.from_arrays(gt, stamps, user_id=1),
    }


def test_errors_and_jitter_numbers():
    s = _series()
    t, err, per_joint = report.position_errors(s['reconstructed'], s['ground_truth'])
    assert err.shape == (N,) and per_joint.shape == (N, NUM_JOINTS)
    assert np.allclose(err, 0.01 * np.sqrt(3))  # every joint shifted by (1, 1, 1) cm
    # a constant-velocity series has no jitter; noise has a lot
    lin = SkeletonSeries.from_arrays(_truth()[:1] + np.arange(N)[:, None, None] * 0.01 * np.ones(3))
    assert report.jitter(lin) == pytest.approx(0.0, abs=1e-6)
    assert report.jitter(s['raw']) > 20 * report.jitter(s['ground_truth'])
    # stamps off by more than the tolerance are not matched
    shifted = SkeletonSeries.from_arrays(s['ground_truth'].positions,
                                         s['ground_truth'].stamps_ns + 15_000_000)
    assert report.position_errors(s['reconstructed'], shifted, 0.01)[1].size == 0


def test_report_from_memory_with_missing_topics(tmp_path):
    data = report.data_from_series(_series())  # no completed / character
    files = report.write_report(data, tmp_path, name='mem', fps=10, max_frames=8)
    for key in ('animation', 'frame', 'errors', 'reliability', 'summary_md', 'summary_json'):
        assert files[key] and (tmp_path / files[key].split('/')[-1]).stat().st_size > 0, key
    from PIL import Image
    with Image.open(files['animation']) as im:
        assert im.n_frames == 8  # 0.77 s at 10 fps = 8 frames
    summary = json.loads((tmp_path / 'mem_summary.json').read_text())
    m = summary['methods']
    assert m['reconstructed']['mean_error_m'] == pytest.approx(0.01 * np.sqrt(3), rel=1e-4)
    assert m['raw']['mean_error_m'] > m['reconstructed']['mean_error_m']
    assert m['character']['frames'] == 0 and 'mean_error_m' not in m['character']
    assert summary['reliability']['per_joint_mean']['HandLeft'] == pytest.approx(
        (10 * 0.1 + 14) / 24, rel=1e-4)
    assert summary['animation']['frames'] == 8
    md = (tmp_path / 'mem_summary.md').read_text()
    assert '| reconstructed | 24 | 24 | 1.73 |' in md
    # the bone-length std beside the jitter (the moving arm's upper segment changes length in
    # this toy 'reconstruction', the 3 cm sensor noise far more)
    rec_std = m['reconstructed']['bone_length_std_cm']
    assert 0.0 < rec_std < 0.5 * m['raw']['bone_length_std_cm']
    assert len(m['raw']['bone_length_std_per_segment_cm']) == NUM_JOINTS - 1
    assert [ln for ln in md.splitlines()
            if ln.startswith('| reconstructed')][0].endswith(f'| {rec_std:.3f} |')
    line = report.bone_length_line(summary)
    assert line.startswith('bone-length std') and f'reconstructed {rec_std:.4f}' in line


def test_render_frames_api_without_bag_and_no_data_panels(tmp_path):
    gt = _truth()
    r = render_frames({'raw sensor': gt, 'reconstructed': None, 'physics character': gt - 2.5},
                      out_gif=tmp_path / 'a.gif', out_png=tmp_path / 'a.png', fps=15,
                      max_frames=5)
    assert r['frames'] == 5 and r['speed'] > 1.0  # 0.77 s at 15 fps = 12 frames -> compressed
    assert (tmp_path / 'a.gif').stat().st_size > 1000 and (tmp_path / 'a.png').stat().st_size > 1000
    with pytest.raises(ValueError):
        render_frames([], out_png=tmp_path / 'b.png')
    # all panels empty still renders (every panel says "no data")
    r = render_frames([Panel('raw', None), Panel('character', None, 'character')],
                      out_png=tmp_path / 'c.png')
    assert r['png'] and (tmp_path / 'c.png').stat().st_size > 1000


def test_report_cli_on_a_small_bag(tmp_path, capsys):
    pytest.importorskip('skeleton_msgs.msg', reason='skeleton_msgs not built')
    from skeleton_core import bagio
    from skeleton_core.conversions import SkeletonFrame, frames_to_array_msg
    s = _series()
    bag = tmp_path / 'tiny.mcap'
    with bagio.BagWriter(bag) as w:
        for i in range(N):
            stamp = int(s['raw'].stamps_ns[i])
            for role in ('raw', 'reliability', 'ground_truth'):
                f = SkeletonFrame(positions=s[role].positions[i],
                                  tracking_state=s[role].tracking_state[i],
                                  reliability=s[role].reliability[i], user_id=1,
                                  stamp_ns=stamp, frame_id='kinect_link')
                w.write(ROLE_TOPICS[role], frames_to_array_msg([f], stamp, 'kinect_link'),
                        stamp + 1000)
            if i % 2 == 0:  # the character runs at half rate, numbered differently
                f = SkeletonFrame(positions=s['ground_truth'].positions[i] - (2.5, 0, 0),
                                  tracking_state=np.full(NUM_JOINTS, 2, np.uint8), user_id=9,
                                  stamp_ns=stamp, frame_id='world')
                w.write(ROLE_TOPICS['character'], frames_to_array_msg([f], stamp, 'world'),
                        stamp + 2000)
    out = tmp_path / 'out'
    assert report.main(['--bag', str(bag), '--out', str(out), '--fps', '10',
                        '--max-frames', '6']) == 0
    printed = capsys.readouterr().out
    assert 'tiny_animation.gif' in printed and 'tiny_summary.md' in printed
    summary = json.loads((out / 'tiny_summary.json').read_text())
    assert summary['topics']['/kinect/skeletons']['messages'] == N
    assert summary['roles']['character']['frames'] == N // 2
    assert summary['methods']['raw']['mean_error_m'] == pytest.approx(
        np.linalg.norm(s['raw'].positions - s['ground_truth'].positions, axis=-1).mean(), rel=1e-3)
    assert summary['methods']['reconstructed']['frames'] == 0
    ch = summary['methods']['character']
    assert ch['matched_frames'] == N // 2
    assert ch['mean_error_m'] == pytest.approx(2.5, rel=1e-6)     # stands 2.5 m away ...
    assert ch['mean_pose_error_m'] == pytest.approx(0.0, abs=1e-9)  # ... in the same pose
    assert summary['reliability']['fraction_below_0.5'] == pytest.approx(10 / (N * NUM_JOINTS),
                                                                       rel=1e-4)
    for f in ('tiny_animation.gif', 'tiny_frame.png', 'tiny_errors.png', 'tiny_reliability.png',
              'tiny_summary.md'):
        assert (out / f).stat().st_size > 0
    # a missing / non-MCAP bag is a one-line error, not a traceback
    assert report.main(['--bag', str(tmp_path / 'nope.mcap'), '--out', str(out)]) == 1
    (tmp_path / 'junk.mcap').write_text('not a bag')
    assert report.main(['--bag', str(tmp_path / 'junk.mcap'), '--out', str(out)]) == 1
    assert '[ERROR]' in capsys.readouterr().err


def test_series_frame_lookup_nearest_and_held():
    s = SkeletonSeries.from_arrays(np.zeros((3, NUM_JOINTS, 3)), np.array([0, 100, 300]))
    assert s.index_at(np.array([-5, 40, 60, 210, 330, 400]), 50).tolist() == [0, 0, 1, -1, 2, -1]
    assert s.index_held(np.array([-5, 40, 99, 100, 250, 301, 500]), 150).tolist() == \
        [-1, 0, 0, 1, 1, 2, -1]


def test_report_on_input_without_any_skeleton_topic(tmp_path):
    files = report.write_report(report.data_from_series({}), tmp_path, name='empty', max_frames=2)
    summary = json.loads((tmp_path / 'empty_summary.json').read_text())
    assert summary['user_id'] is None and summary['reliability'] is None
    assert all(m['frames'] == 0 for m in summary['methods'].values())
    assert 'no data' in (tmp_path / 'empty_summary.md').read_text()
    assert files['frame'] and files['animation']
