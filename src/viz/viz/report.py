"""Offline report of a recorded pipeline run (an MCAP bag), or of in-memory series.

    ros2 run viz report --bag out/demo.mcap --out out/

writes, for the user with the most frames (``--user`` to pick another):

* ``<name>_animation.gif`` — three panels side by side: raw sensor (unreliable joints marked by
  red squares sized by 1 - reliability) / reconstructed (ground truth in grey when recorded) /
  physics character (capsules), front and side views, ~12 fps, at most 300 frames;
* ``<name>_frame.png`` — a still of the same panels (the frame with the most unreliable joints);
* ``<name>_errors.png`` — mean joint position error over time of raw / completed /
  reconstructed / character against ``/kinect/ground_truth`` (when the bag has it);
* ``<name>_reliability.png`` — per-joint reliability and tracking state, joints x time;
* ``<name>_summary.md`` and ``<name>_summary.json`` — frames per topic, mean errors, jitter,
  reliability statistics.

Whatever is missing from the bag shows as "no data"; the report never fails because a topic is
absent. Errors are compared at equal header stamps (nearest within ``--tolerance``), so the
pipeline must preserve stamps end to end (it does). The character is the retargeted physics body:
its error includes the size difference between the user and the character.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from skeleton_core.model import INFERRED, JOINT_NAMES, NOT_TRACKED, NUM_JOINTS, ROOT, TRACKED

from .render import Panel, render_frames
from .series import METHOD_ROLES, ROLE_TOPICS, BagData, SkeletonSeries, load_bag, primary_user
from skeleton_core.bagio import BagError
from skeleton_core.model import segment_lengths

DEFAULT_TOLERANCE_S = 0.02


# --------------------------------------------------------------------------------------------
# Metrics
# --------------------------------------------------------------------------------------------
def position_errors(method: SkeletonSeries, truth: SkeletonSeries, tolerance_s: float
                    = DEFAULT_TOLERANCE_S, root_aligned: bool = False):
    """Per matched frame: (times_s, mean joint error (K,), per-joint error (K, 20)), metres.
    Frames of ``method`` without a ground-truth frame within the tolerance are skipped. With
    ``root_aligned`` both skeletons are first moved so that their HipCenter is at the origin
    (pose error, independent of where the character stands)."""
    idx = truth.index_at(method.stamps_ns, int(tolerance_s * 1e9))
    ok = idx >= 0
    a, b = method.positions[ok], truth.positions[idx[ok]]
    if root_aligned:
        a = a - a[:, ROOT:ROOT + 1]
        b = b - b[:, ROOT:ROOT + 1]
    d = np.linalg.norm(a - b, axis=-1)
    return method.times_s[ok], d.mean(axis=1) if d.size else np.zeros(0), d


def jitter(series: SkeletonSeries, max_gap_s: float = 0.2) -> float:
    """Mean joint acceleration magnitude (m/s^2) from consecutive frames (gaps > max_gap_s are
    skipped): a noisy, jittery skeleton has a much higher value than smooth motion."""
    if len(series) < 3:
        return float('nan')
    t = series.times_s
    p = series.positions
    dt = np.diff(t)
    ok = (dt[:-1] > 0) & (dt[1:] > 0) & (dt[:-1] <= max_gap_s) & (dt[1:] <= max_gap_s)
    if not ok.any():
        return float('nan')
    i = np.flatnonzero(ok)   # only triples of frames with two positive, short steps
    v0 = (p[i + 1] - p[i]) / dt[i, None, None]
    v1 = (p[i + 2] - p[i + 1]) / dt[i + 1, None, None]
    a = (v1 - v0) / (0.5 * (dt[i] + dt[i + 1]))[:, None, None]
    return float(np.linalg.norm(a, axis=-1).mean())


def _f(x) -> Optional[float]:
    x = float(x)
    return round(x, 6) if math.isfinite(x) else None


def summarize(data: BagData, user: Optional[int], tolerance_s: float = DEFAULT_TOLERANCE_S
              ) -> Dict:
    """The numbers of the report (JSON-ready)."""
    series = {role: pick(data, role, user) for role in ROLE_TOPICS}
    out: Dict = {
        'user_id': user,
        'users': sorted({u for by in data.series.values() for u in by}),
        'topics': {t: {'type': ty, 'messages': n}
                   for t, (ty, n) in sorted(data.topic_counts.items())},
        'roles': {role: {'topic': data.topics.get(role),
                         'frames': len(s) if s is not None else 0}
                  for role, s in series.items()},
        'dropped_skeletons': dict(data.dropped),
        # frames of this user with the stamp of a later frame (the later one is used)
        'duplicate_stamps': {role: s.duplicates for role, s in series.items()
                             if s is not None and s.duplicates},
    }
    if any(s is not None for s in series.values()):
        stamps = [s.stamps_ns for s in series.values() if s is not None and len(s)]
        out['duration_s'] = _f((max(int(x[-1]) for x in stamps) - min(int(x[0]) for x in stamps))
                               * 1e-9)
    gt = series.get('ground_truth')
    errors = {}
    for role in METHOD_ROLES:
        s = series.get(role)
        e = {'frames': len(s) if s is not None else 0,
             'jitter_m_s2': _f(jitter(s)) if s is not None else None}
        if s is not None and len(s) >= 2:
            # std over time of each segment's length (cm): 0 for a rigid skeleton
            with np.errstate(invalid='ignore'):
                per_seg = np.nanstd(segment_lengths(s.positions) * 100.0, axis=0)
            ok = np.isfinite(per_seg)
            e['bone_length_std_cm'] = _f(per_seg[ok].mean() if ok.any() else float('nan'))
            e['bone_length_std_per_segment_cm'] = [_f(v) for v in per_seg]
        if s is not None and gt is not None:
            _, err, per_joint = position_errors(s, gt, tolerance_s)
            e['matched_frames'] = int(err.size)
            if err.size:
                e['mean_error_m'] = _f(err.mean())
                e['median_error_m'] = _f(np.median(err))
                e['p95_error_m'] = _f(np.percentile(err, 95))
                e['max_error_m'] = _f(err.max())
                e['per_joint_mean_error_m'] = {JOINT_NAMES[j]: _f(per_joint[:, j].mean())
                                               for j in range(NUM_JOINTS)}
                e['mean_pose_error_m'] = _f(position_errors(s, gt, tolerance_s, True)[1].mean())
        errors[role] = e
    out['methods'] = errors
    if gt is not None:
        out['ground_truth_jitter_m_s2'] = _f(jitter(gt))
    rel = series.get('reliability')
    if rel is not None and np.isfinite(rel.reliability).any():
        r = rel.reliability
        out['reliability'] = {
            'frames': len(rel),
            'mean': _f(np.nanmean(r)),
            'fraction_below_0.5': _f(np.mean(r[np.isfinite(r)] < 0.5)),
            'fraction_unknown': _f(np.mean(~np.isfinite(r))),
            'per_joint_mean': {JOINT_NAMES[j]: _f(np.nanmean(r[:, j]))
                               if np.isfinite(r[:, j]).any() else None
                               for j in range(NUM_JOINTS)},
        }
    else:
        out['reliability'] = None
    raw = series.get('raw') if series.get('raw') is not None else series.get('reliability')
    if raw is not None and len(raw):
        ts = raw.tracking_state
        out['tracking_state_fraction'] = {'tracked': _f(np.mean(ts == TRACKED)),
                                          'inferred': _f(np.mean(ts == INFERRED)),
                                          'not_tracked': _f(np.mean(ts == NOT_TRACKED))}
    return out


def pick(data: BagData, role: str, user: Optional[int]) -> Optional[SkeletonSeries]:
    """The role's series of ``user``; when the role has exactly one other user (e.g. a character
    numbered differently), that one."""
    by_user = data.series.get(role, {})
    if user in by_user:
        return by_user[user]
    if len(by_user) == 1 and role in ('character',):
        return next(iter(by_user.values()))
    return None


# --------------------------------------------------------------------------------------------
# Plots
# --------------------------------------------------------------------------------------------
METHOD_COLORS = {'raw': (0.58, 0.20, 0.80), 'completed': (0.20, 0.55, 1.0),
                 'reconstructed': (0.10, 0.70, 0.20), 'character': (0.85, 0.55, 0.30)}


def _figure(w, h, dpi=100):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(w, h), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def plot_errors(data: BagData, user: Optional[int], path, tolerance_s=DEFAULT_TOLERANCE_S):
    fig = _figure(8, 6.0)
    gt = pick(data, 'ground_truth', user)
    t0 = _t0(data, user)
    for k, (aligned, what) in enumerate(((False, 'Position error against ground truth'),
                                         (True, 'Pose error (HipCenter aligned)'))):
        ax = fig.add_subplot(2, 1, k + 1)
        drawn = 0
        if gt is not None:
            for role in METHOD_ROLES:
                s = pick(data, role, user)
                if s is None:
                    continue
                t, err, _ = position_errors(s, gt, tolerance_s, aligned)
                if err.size == 0:
                    continue
                ax.plot(t - t0, err * 100.0, lw=1.0, color=METHOD_COLORS[role],
                        label=f'{role} (mean {err.mean() * 100:.1f} cm)')
                drawn += 1
        if drawn:
            ax.legend(fontsize=8, loc='upper right')
        else:
            why = 'no ground truth in the bag' if gt is None else 'no frames match the ground truth'
            ax.text(0.5, 0.5, f'no data ({why})', transform=ax.transAxes, ha='center',
                    va='center', color='0.4')
        ax.set_xlabel('time (s)')
        ax.set_ylabel('mean joint error (cm)')
        ax.set_title(what, fontsize=10)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    return str(path)


def plot_reliability(data: BagData, user: Optional[int], path):
    fig = _figure(8, 6.4)
    axr = fig.add_subplot(2, 1, 1)
    axt = fig.add_subplot(2, 1, 2)
    t0 = _t0(data, user)
    rel = pick(data, 'reliability', user)
    if rel is None or not np.isfinite(rel.reliability).any():
        rel = None
    raw = pick(data, 'raw', user)
    if raw is None:
        raw = pick(data, 'reliability', user)
    for ax, s, what in ((axr, rel, 'reliability'), (axt, raw, 'tracking state')):
        ax.set_yticks(range(NUM_JOINTS))
        ax.set_yticklabels(JOINT_NAMES, fontsize=6)
        ax.set_title(f'Per-joint {what}', fontsize=10)
        if s is None or len(s) == 0:
            ax.text(0.5, 0.5, 'no data', transform=ax.transAxes, ha='center', va='center',
                    color='0.4')
            continue
        t = s.times_s - t0
        extent = (t[0], t[-1] if len(t) > 1 else t[0] + 1e-3, NUM_JOINTS - 0.5, -0.5)
        if what == 'reliability':
            import matplotlib
            cmap = matplotlib.colormaps['RdYlGn'].with_extremes(bad='0.85')
            im = ax.imshow(np.ma.masked_invalid(s.reliability.T), aspect='auto', cmap=cmap,
                           vmin=0, vmax=1, interpolation='nearest', extent=extent)
            fig.colorbar(im, ax=ax, fraction=0.03, pad=0.01, label='reliability')
        else:
            from matplotlib.colors import ListedColormap
            cmap = ListedColormap([(0.85, 0.2, 0.2), (0.95, 0.75, 0.2), (0.3, 0.7, 0.3)])
            im = ax.imshow(s.tracking_state.T.astype(float), aspect='auto', cmap=cmap, vmin=-0.5,
                           vmax=2.5, interpolation='nearest', extent=extent)
            cb = fig.colorbar(im, ax=ax, fraction=0.03, pad=0.01, ticks=[0, 1, 2])
            cb.ax.set_yticklabels(['not tracked', 'inferred', 'tracked'], fontsize=7)
        ax.set_xlabel('time (s)')
    fig.tight_layout()
    fig.savefig(path)
    return str(path)


def _t0(data: BagData, user) -> float:
    ts = [s.times_s[0] for role in ROLE_TOPICS for s in (pick(data, role, user),)
          if s is not None and len(s)]
    return min(ts) if ts else 0.0


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------
def panels_for(data: BagData, user: Optional[int]) -> List[Panel]:
    rel = pick(data, 'reliability', user)
    raw = rel if rel is not None else pick(data, 'raw', user)
    rec = pick(data, 'reconstructed', user)
    rec_title = 'reconstructed'
    if rec is None and pick(data, 'completed', user) is not None:
        rec, rec_title = pick(data, 'completed', user), 'completed'
    return [Panel('raw sensor', raw, 'raw'),
            Panel(rec_title, rec, 'reconstructed' if rec_title == 'reconstructed' else 'completed',
                  ghost=pick(data, 'ground_truth', user)),
            Panel('physics character', pick(data, 'character', user), 'character')]


def summary_markdown(summary: Dict, files: Dict[str, str], source: str) -> str:
    def cm(x):
        return '—' if x is None else f'{x * 100:.2f}'

    lines = [f'# Pipeline report: {source}', '']
    lines.append(f"User {summary.get('user_id')} (users seen: {summary.get('users')}); "
                 f"duration {summary.get('duration_s') or 0:.2f} s.")
    lines += ['', '## Topics', '', '| topic | type | messages |', '|---|---|---|']
    for t, v in summary['topics'].items():
        lines.append(f"| `{t}` | {v['type']} | {v['messages']} |")
    if not summary['topics']:
        lines.append('| (none) | | |')
    lines += ['', '## Methods against ground truth', '',
              '| method | frames | matched | mean error (cm) | median (cm) | p95 (cm) | '
              'pose error (cm) | jitter (m/s²) | bone-length std (cm) |',
              '|---|---|---|---|---|---|---|---|---|']
    for role, e in summary['methods'].items():
        lines.append(f"| {role} | {e['frames']} | {e.get('matched_frames', '—')} | "
                     f"{cm(e.get('mean_error_m'))} | {cm(e.get('median_error_m'))} | "
                     f"{cm(e.get('p95_error_m'))} | {cm(e.get('mean_pose_error_m'))} | "
                     f"{'—' if e['jitter_m_s2'] is None else format(e['jitter_m_s2'], '.2f')} | "
                     f"{'—' if e.get('bone_length_std_cm') is None else format(e['bone_length_std_cm'], '.3f')} |")
    if summary['roles'].get('ground_truth', {}).get('frames', 0) == 0:
        lines += ['', 'No `/kinect/ground_truth` in the bag: errors cannot be computed.']
    else:
        lines += ['', f"Ground-truth jitter: {summary.get('ground_truth_jitter_m_s2')} m/s². "
                  'Pose error: both skeletons moved to put HipCenter at the origin. The character '
                  'errors include the size difference between the user and the retargeted '
                  'character.']
    rel = summary.get('reliability')
    lines += ['', '## Reliability', '']
    if rel:
        lines.append(f"Mean {rel['mean']:.3f}; {100 * rel['fraction_below_0.5']:.1f} % of joint "
                     f"samples below 0.5; {100 * rel['fraction_unknown']:.1f} % unknown.")
        worst = sorted(((v, k) for k, v in rel['per_joint_mean'].items() if v is not None))[:5]
        lines.append('Least reliable joints: ' + ', '.join(f'{k} ({v:.2f})' for v, k in worst))
    else:
        lines.append('no data')
    tsf = summary.get('tracking_state_fraction')
    if tsf:
        lines.append('')
        lines.append(f"Tracking states: {100 * tsf['tracked']:.1f} % tracked, "
                     f"{100 * tsf['inferred']:.1f} % inferred, "
                     f"{100 * tsf['not_tracked']:.1f} % not tracked.")
    if summary.get('dropped_skeletons'):
        lines += ['', f"Malformed skeletons skipped: {summary['dropped_skeletons']}"]
    lines += ['', '## Files', '']
    for k, v in files.items():
        if v and k != 'summary_md':
            lines.append(f'- {k}: `{Path(v).name}`')
    if files.get('frame'):
        lines += ['', f"![frame]({Path(files['frame']).name})"]
    return '\n'.join(lines) + '\n'


def write_report(data: BagData, out_dir, name: str = 'report', user: Optional[int] = None,
                 fps: float = 12.0, max_frames: int = 300, gif: bool = True,
                 tolerance_s: float = DEFAULT_TOLERANCE_S, source: str = '') -> Dict[str, str]:
    """Write every report file into ``out_dir``; returns {'animation', 'frame', 'errors',
    'reliability', 'summary_md', 'summary_json'} -> path (None for what was not written)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if user is None:
        user = primary_user(data)
    files: Dict[str, Optional[str]] = {}
    panels = panels_for(data, user)
    title = f"{source or name} — user {user if user is not None else '?'}"
    r = render_frames(panels, out_gif=out / f'{name}_animation.gif' if gif else None,
                      out_png=out / f'{name}_frame.png', fps=fps, max_frames=max_frames,
                      title=title)
    files['animation'] = r['gif']
    files['frame'] = r['png']
    files['errors'] = plot_errors(data, user, out / f'{name}_errors.png', tolerance_s)
    files['reliability'] = plot_reliability(data, user, out / f'{name}_reliability.png')
    summary = summarize(data, user, tolerance_s)
    summary['animation'] = {'frames': r['frames'], 'fps': fps, 'playback_speedup': r['speed']}
    files['summary_json'] = str(out / f'{name}_summary.json')
    files['summary_md'] = str(out / f'{name}_summary.md')
    summary['files'] = {k: (Path(v).name if v else None) for k, v in files.items()}
    Path(files['summary_json']).write_text(json.dumps(summary, indent=2, allow_nan=False) + '\n')
    Path(files['summary_md']).write_text(summary_markdown(summary, files, source or name))
    return files


def data_from_series(series: Dict[str, SkeletonSeries]) -> BagData:
    """In-memory input for :func:`write_report`: role ('raw', 'reliability', 'completed',
    'reconstructed', 'character', 'ground_truth') -> series."""
    unknown = set(series) - set(ROLE_TOPICS)
    if unknown:
        raise ValueError(f'unknown roles {sorted(unknown)}; use {list(ROLE_TOPICS)}')
    by_role = {role: {} for role in ROLE_TOPICS}
    counts = {}
    for role, s in series.items():
        if s is None:
            continue
        by_role[role][s.user_id] = s
        counts[ROLE_TOPICS[role]] = ('skeleton_msgs/msg/SkeletonArray', len(s))
    return BagData(by_role, counts, {}, dict(ROLE_TOPICS))


def bone_length_line(summary: Dict) -> str:
    """One line: the bone-length std (cm, mean of the 19 segments' std over time) and the
    jitter of the raw sensor and the reconstruction ('' without both)."""
    m = summary.get('methods', {})
    raw, rec = m.get('raw', {}), m.get('reconstructed', {})
    r, o = raw.get('bone_length_std_cm'), rec.get('bone_length_std_cm')
    if r is None or o is None:
        return ''
    pct = f' ({100.0 * (o - r) / r:+.1f} %)' if r > 0 else ''
    jr, jo = raw.get('jitter_m_s2'), rec.get('jitter_m_s2')
    jit = f'; jitter raw {jr:.2f} -> reconstructed {jo:.2f} m/s²' if jr is not None and \
        jo is not None else ''
    return (f'bone-length std (cm, mean of 19 segments): raw {r:.3f} -> reconstructed '
            f'{o:.4f}{pct}{jit}')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog='report', description='Offline report of a recorded pipeline bag: animation (GIF), '
        'still frame, error and reliability plots, summary (Markdown + JSON).')
    ap.add_argument('--bag', required=True, help='MCAP bag file (or rosbag2 directory)')
    ap.add_argument('--out', default='out', help='output directory (default: out)')
    ap.add_argument('--name', default='', help='file name prefix (default: the bag name)')
    ap.add_argument('--user', type=int, default=None, help='user id (default: most frames)')
    ap.add_argument('--fps', type=float, default=12.0, help='animation frame rate (default 12)')
    ap.add_argument('--max-frames', type=int, default=300,
                    help='animation frames at most; longer runs play faster (default 300)')
    ap.add_argument('--no-gif', action='store_true', help='skip the animation')
    ap.add_argument('--tolerance', type=float, default=DEFAULT_TOLERANCE_S,
                    help='stamp matching tolerance against ground truth, s (default 0.02)')
    ap.add_argument('--topic', action='append', default=[], metavar='ROLE=TOPIC',
                    help=f'override a topic; roles: {", ".join(ROLE_TOPICS)}')
    a = ap.parse_args(argv)
    topics = dict(ROLE_TOPICS)
    for t in a.topic:
        role, sep, topic = t.partition('=')
        if not sep or role not in ROLE_TOPICS or not topic:
            print(f'[ERROR] --topic {t!r}: expected ROLE=TOPIC with ROLE one of '
                  f'{list(ROLE_TOPICS)}', file=sys.stderr)
            return 1
        topics[role] = topic
    if not (0 < a.fps <= 60) or a.max_frames < 1 or a.tolerance <= 0:
        print('[ERROR] --fps must be in (0, 60], --max-frames >= 1, --tolerance > 0',
              file=sys.stderr)
        return 1
    try:
        data = load_bag(a.bag, topics)
    except (BagError, OSError) as e:
        print(f'[ERROR] {e}', file=sys.stderr)
        return 1
    name = a.name or Path(a.bag).stem or 'report'
    if a.user is not None and not any(a.user in by for by in data.series.values()):
        print(f'[ERROR] user {a.user} is not in {a.bag}; users: '
              f'{sorted({u for by in data.series.values() for u in by})}', file=sys.stderr)
        return 1
    files = write_report(data, a.out, name=name, user=a.user, fps=a.fps,
                         max_frames=a.max_frames, gif=not a.no_gif, tolerance_s=a.tolerance,
                         source=Path(a.bag).name)
    line = bone_length_line(json.loads(Path(files['summary_json']).read_text()))
    if line:
        print(line)
    print(f'report of {a.bag} written:')
    for k, v in files.items():
        if v:
            print(f'  {k:13s} {v}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
