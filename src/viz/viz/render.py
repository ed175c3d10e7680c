"""Offscreen (Agg) rendering of side-by-side skeleton panels to an animated GIF and a still PNG.

Each panel shows one :class:`viz.series.SkeletonSeries` in a front view (as seen from the sensor:
right of the image = -y, up = +z) over a side view (depth x to the right, up = +z), with equal
scales in every panel. Raw panels draw the papers' colours (purple joints, yellow bones, INFERRED
joints faded, NOT_TRACKED hidden) and a red square on every joint sized by ``1 - reliability``
(Shum et al. 2013, Fig. 3); the character panel draws capsules with the standard body's radii.
A panel without data says "no data". Usable without a bag::

    render_frames({'raw sensor': raw, 'reconstructed': rec, 'physics character': None},
                  out_gif='out/demo.gif', out_png='out/demo.png')
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

from skeleton_core.model import (INFERRED, NOT_TRACKED, NUM_JOINTS, SEGMENTS, estimate_height,
                                 standard_body)

from .series import SkeletonSeries

RAW_JOINT = (0.58, 0.20, 0.80)
RAW_BONE = (0.95, 0.80, 0.05)
RECON = (0.10, 0.70, 0.20)
COMPLETED = (0.20, 0.55, 1.0)
CHARACTER = (0.85, 0.62, 0.42)
GROUND_TRUTH = (0.55, 0.55, 0.55)
RED = (0.9, 0.0, 0.0)

STYLE_OF = {'raw': 'raw', 'reliability': 'raw', 'completed': 'completed',
            'reconstructed': 'reconstructed', 'character': 'character'}


@dataclass
class Panel:
    """One panel: a title, a series (None = no data) and how to draw it."""

    title: str
    series: Optional[SkeletonSeries]
    style: str = 'raw'  # raw | reconstructed | completed | character
    ghost: Optional[SkeletonSeries] = None  # e.g. ground truth, drawn faint underneath


def _views(p: np.ndarray) -> Dict[str, np.ndarray]:
    """(..., 20, 3) -> front (-y, z) and side (x, z) projections, (..., 20, 2) each."""
    return {'front': np.stack([-p[..., 1], p[..., 2]], -1),
            'side': np.stack([p[..., 0], p[..., 2]], -1)}


def _limits(series: Optional[SkeletonSeries], span: float):
    """Per view centre +- span/2 (robust to outliers), from a series' positions."""
    if series is None or len(series) == 0:
        return {'front': ((-span / 2, span / 2), (0.0, span)),
                'side': ((2.5 - span / 2, 2.5 + span / 2), (0.0, span))}
    out = {}
    for view, xy in _views(series.positions).items():
        lo = np.nanpercentile(xy.reshape(-1, 2), 2, axis=0)
        hi = np.nanpercentile(xy.reshape(-1, 2), 98, axis=0)
        c = 0.5 * (lo + hi)
        out[view] = ((c[0] - span / 2, c[0] + span / 2), (c[1] - span / 2, c[1] + span / 2))
    return out


def _floor(series: Optional[SkeletonSeries]) -> Optional[float]:
    """Floor height estimated from the lowest joint of every frame (sensor frames have the floor
    below z = 0, a physics world has it at 0)."""
    if series is None or len(series) == 0:
        return None
    return float(np.nanpercentile(series.positions[..., 2].min(axis=1), 5)) - 0.02


def _span(panels: Sequence[Panel]) -> float:
    span = 1.0
    for pn in panels:
        for s in (pn.series, pn.ghost):
            if s is None or len(s) == 0:
                continue
            for xy in _views(s.positions).values():
                ext = (np.nanpercentile(xy.reshape(-1, 2), 98, axis=0)
                       - np.nanpercentile(xy.reshape(-1, 2), 2, axis=0))
                span = max(span, float(np.max(ext)))
    return min(span * 1.25, 6.0)


def sample_times(panels: Sequence[Panel], fps: float, max_frames: int):
    """Animation sample stamps (ns) covering all panels, and the playback speed-up factor."""
    stamps = [s.stamps_ns for pn in panels for s in (pn.series,) if s is not None and len(s)]
    if not stamps:
        return np.zeros(1, np.int64), 1.0
    t0 = min(int(s[0]) for s in stamps)
    t1 = max(int(s[-1]) for s in stamps)
    step = 1e9 / fps
    n = int((t1 - t0) // step) + 1
    speed = 1.0
    if n > max_frames:
        speed = n / max_frames
        n = max_frames
        step = (t1 - t0) / max(n - 1, 1)
    return (t0 + np.round(np.arange(n) * step)).astype(np.int64), speed


class _PanelArtists:
    def __init__(self, fig, ax_front, ax_side, panel: Panel, limits, tolerance_ns: int):
        from matplotlib.collections import LineCollection
        self.panel = panel
        self.tol = tolerance_ns
        self.axes = {'front': ax_front, 'side': ax_side}
        self.bones, self.joints, self.squares, self.ghosts = {}, {}, {}, {}
        style = panel.style
        floor = _floor(panel.series if panel.series is not None else panel.ghost)
        self.height = None
        if panel.series is not None and len(panel.series) and style == 'character':
            h = estimate_height(panel.series.positions[len(panel.series) // 2])
            self.height = float(np.clip(h, 0.6, 2.5)) if np.isfinite(h) else 1.75
        for view, ax in self.axes.items():
            (x0, x1), (y0, y1) = limits[view]
            ax.set_xlim(x0, x1)
            ax.set_ylim(y0, y1)
            ax.set_aspect('equal', adjustable='box')
            ax.set_xticks([])
            ax.set_yticks([])
            for s in ax.spines.values():
                s.set_color('0.8')
            if floor is not None:
                ax.axhline(floor, color='0.75', lw=0.8, zorder=0)
            self.ghosts[view] = LineCollection([], colors=[GROUND_TRUTH + (0.6,)], linewidths=1.5,
                                               zorder=1)
            ax.add_collection(self.ghosts[view])
            width = 2.5 if style != 'character' else 1.0
            color = {'raw': RAW_BONE, 'reconstructed': RECON, 'completed': COMPLETED,
                     'character': CHARACTER}[style]
            self.bones[view] = LineCollection([], colors=[color], linewidths=width,
                                              capstyle='round', zorder=2)
            ax.add_collection(self.bones[view])
            jc = RAW_JOINT if style == 'raw' else color
            self.joints[view] = ax.scatter([], [], s=14, c=[jc], zorder=3, linewidths=0)
            self.squares[view] = ax.scatter([], [], marker='s', s=[], facecolors='none',
                                            edgecolors=[RED], linewidths=1.5, zorder=4)
        self.nodata = ax_front.text(0.5, 0.5, 'no data', transform=ax_front.transAxes,
                                    ha='center', va='center', color='0.4', fontsize=12)
        self.nodata.set_visible(panel.series is None or len(panel.series) == 0)
        ax_front.set_title(panel.title, fontsize=10)
        ax_front.text(0.02, 0.98, 'front', transform=ax_front.transAxes, va='top', fontsize=7,
                      color='0.5')
        ax_side.text(0.02, 0.98, 'side', transform=ax_side.transAxes, va='top', fontsize=7,
                     color='0.5')
        self._fig = fig
        self._pts_per_m = None
        self.animated = [a for view in self.axes for a in (
            self.ghosts[view], self.bones[view], self.joints[view], self.squares[view])]
        self.animated.append(self.nodata)

    def _points_per_metre(self, ax) -> float:
        bbox = ax.get_window_extent()
        x0, x1 = ax.get_xlim()
        return bbox.width * 72.0 / self._fig.dpi / (x1 - x0)

    def update(self, stamp_ns: int) -> int:
        """Draw the latest frame at or before ``stamp_ns`` (held for at most the tolerance);
        returns 1000 when the panel has data plus the number of red squares drawn."""
        s = self.panel.series
        n_squares = 0
        i = -1 if s is None else int(s.index_held(np.array([stamp_ns]), self.tol)[0])
        g = self.panel.ghost
        gi = -1 if g is None else int(g.index_held(np.array([stamp_ns]), self.tol)[0])
        self.nodata.set_visible(i < 0)
        has_data = 0 if i < 0 else 1000
        if self.panel.style == 'character' and self._pts_per_m is None:
            self._pts_per_m = self._points_per_metre(self.axes['front'])
        for view in self.axes:
            if gi >= 0:
                gv = _views(g.positions[gi])[view]
                self.ghosts[view].set_segments([gv[[a, b]] for a, b in SEGMENTS])
            else:
                self.ghosts[view].set_segments([])
            if i < 0:
                self.bones[view].set_segments([])
                self.joints[view].set_offsets(np.zeros((0, 2)))
                self.squares[view].set_offsets(np.zeros((0, 2)))
                continue
            xy = _views(s.positions[i])[view]
            ts = s.tracking_state[i] if self.panel.style == 'raw' else np.full(NUM_JOINTS, 2)
            visible = ts != NOT_TRACKED
            segs = [xy[[a, b]] for a, b in SEGMENTS if visible[a] and visible[b]]
            self.bones[view].set_segments(segs)
            if self.panel.style == 'character':
                radii = standard_body(self.height or 1.75).segment_radii
                lw = [2 * r * self._pts_per_m for (a, b), r in zip(SEGMENTS, radii)]
                self.bones[view].set_linewidths(lw)
                self.bones[view].set_alpha(0.85)
            base = np.array(RAW_JOINT if self.panel.style == 'raw' else
                            {'reconstructed': RECON, 'completed': COMPLETED,
                             'character': CHARACTER}[self.panel.style])
            cols = np.tile(np.append(base, 1.0), (NUM_JOINTS, 1))
            cols[ts == INFERRED, 3] = 0.35
            self.joints[view].set_offsets(xy[visible])
            self.joints[view].set_facecolors(cols[visible])
            r = s.reliability[i]
            bad = np.isfinite(r) & (r < 0.95) & visible
            if self.panel.style == 'raw' and bad.any():
                side_pts = 3.0 + 14.0 * (1.0 - np.clip(r[bad], 0, 1))  # side in points
                self.squares[view].set_offsets(xy[bad])
                self.squares[view].set_sizes(side_pts ** 2)
                n_squares = int(bad.sum())
            else:
                self.squares[view].set_offsets(np.zeros((0, 2)))
        return has_data + n_squares


def render_frames(panels, out_gif=None, out_png=None, fps: float = 12.0, max_frames: int = 300,
                  hold_s: float = 0.5, title: str = '', dpi: int = 72, png_dpi: int = 110,
                  still_stamp_ns: Optional[int] = None, colors: int = 64) -> Dict[str, object]:
    """Render panels side by side. ``panels``: list of :class:`Panel`, or a dict title ->
    SkeletonSeries / (N, 20, 3) array / None (style from the title: 'raw', 'character', else
    reconstructed). Writes an animated GIF (``out_gif``) and/or a still PNG (``out_png``, the frame
    at ``still_stamp_ns``, else one where the most panels have data and, among those, the raw
    panel shows the most red squares). A panel shows its latest frame at or before the sample
    time for at most ``hold_s``, then "no data".
    Returns {'frames', 'speed', 'gif', 'png', 'still_stamp_ns'}."""
    import matplotlib
    matplotlib.use('Agg', force=False)
    from matplotlib.figure import Figure
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    panels = _as_panels(panels)
    if not panels:
        raise ValueError('nothing to render: no panels')
    fps = float(fps)
    if not (0 < fps <= 60) or max_frames < 1:
        raise ValueError('fps must be in (0, 60] and max_frames >= 1')
    stamps, speed = sample_times(panels, fps, max_frames)
    span = _span(panels)
    fig = Figure(figsize=(2.9 * len(panels), 5.6), dpi=dpi)
    FigureCanvasAgg(fig)
    gs = fig.add_gridspec(2, len(panels), height_ratios=[1, 1], left=0.02, right=0.98,
                          bottom=0.08, top=0.9, wspace=0.06, hspace=0.08)
    tol = int(hold_s * 1e9)
    arts = []
    for k, pn in enumerate(panels):
        lim = _limits(pn.series if pn.series is not None and len(pn.series) else pn.ghost, span)
        arts.append(_PanelArtists(fig, fig.add_subplot(gs[0, k]), fig.add_subplot(gs[1, k]),
                                  pn, lim, tol))
    head = fig.suptitle(title, fontsize=11) if title else None
    clock = fig.text(0.5, 0.008, '', ha='center', fontsize=8, color='0.3')
    legend = ('purple/yellow: Kinect (faded = inferred), red squares: 1 - reliability, '
              'green: reconstructed, tan: character, grey: ground truth')
    fig.text(0.5, 0.045, legend, ha='center', fontsize=6.5, color='0.35')
    t0 = int(stamps[0])

    def draw(st):
        n = sum(a.update(int(st)) for a in arts)
        clock.set_text(f't = {(int(st) - t0) * 1e-9:6.2f} s'
                       + (f'   (playback x{speed:.1f})' if speed > 1.01 else ''))
        return n

    animated = [a for pa in arts for a in pa.animated] + [clock]

    def set_animated(flag):
        for a in animated:
            a.set_animated(flag)

    out = {'frames': 0, 'speed': speed, 'gif': None, 'png': None, 'still_stamp_ns': None}
    best = (-1, int(stamps[len(stamps) // 2]))
    if out_gif is not None:
        # blitting: the static part (axes, titles, legend) is drawn once, then only the moving
        # artists are drawn over a copy of it for every frame
        set_animated(True)
        canvas = fig.canvas
        canvas.draw()
        background = canvas.copy_from_bbox(fig.bbox)
        images = []
        for st in stamps:
            n = draw(st)
            if n > best[0]:
                best = (n, int(st))
            canvas.restore_region(background)
            for a in animated:
                fig.draw_artist(a)
            rgb = np.asarray(canvas.buffer_rgba())[..., :3]
            images.append(Image.fromarray(rgb).quantize(
                colors=colors, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE))
        set_animated(False)
        Path(out_gif).parent.mkdir(parents=True, exist_ok=True)
        images[0].save(out_gif, save_all=True, append_images=images[1:], loop=0,
                       duration=int(round(1000.0 / fps)), optimize=True, disposal=1)
        out['gif'] = str(out_gif)
        out['frames'] = len(images)
    if out_png is not None:
        if still_stamp_ns is None:
            if out_gif is None:
                fig.canvas.draw()  # lays the axes out (capsule widths need it)
                for st in stamps:
                    n = sum(a.update(int(st)) for a in arts)
                    if n > best[0]:
                        best = (n, int(st))
            still_stamp_ns = best[1] if best[0] > 0 else int(stamps[len(stamps) // 2])
        draw(still_stamp_ns)
        Path(out_png).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out_png, dpi=png_dpi)
        out['png'] = str(out_png)
        out['still_stamp_ns'] = int(still_stamp_ns)
    if head is not None:
        head.remove()
    return out


def _as_panels(panels) -> List[Panel]:
    if isinstance(panels, dict):
        out = []
        for title, s in panels.items():
            if s is not None and not isinstance(s, SkeletonSeries):
                s = SkeletonSeries.from_arrays(s)
            low = title.lower()
            style = ('raw' if ('raw' in low or 'sensor' in low or 'kinect' in low) else
                     'character' if ('character' in low or 'physics' in low) else
                     'completed' if 'complet' in low else 'reconstructed')
            out.append(Panel(title, s, style))
        return out
    return list(panels)
