"""Shum & Ho 2012 Fig. 5 (PCA dimensions vs nearest-posture matching error and search time, on
the motion database) and Shum et al. 2013 Fig. 8 (a method's error and frame time vs one
parameter: database size, K, PCA dimensions, optimisation steps, samples, through factory keyword
overrides)."""
from __future__ import annotations

import time
from typing import Dict, List, Optional, Sequence

import numpy as np

from skeleton_core.geometry import normalize, retarget
from skeleton_core.model import NUM_JOINTS, standard_body
from .evaluation import evaluate_streams, make_streams, run_meta
from .registry import make_method
from .sensor_model import SensorModel


# ------------------------------------------------------------------------------------------
# Fig. 5 (Shum & Ho 2012 Sec. 8.4): PCA dimensions vs matching error and search time
# ------------------------------------------------------------------------------------------
def _database_postures(database=None, clips=None) -> np.ndarray:
    """(N, 20, 3) normalised postures of a MotionDatabase (several attribute names tried) or of
    clips (normalised and retargeted to the standard body here, as the database does)."""
    if database is not None:
        for attr in ('positions', 'postures', 'normalized_positions', 'poses'):
            arr = getattr(database, attr, None)
            if arr is not None:
                arr = np.asarray(arr, float)
                if arr.ndim == 2 and arr.shape[1] == 3 * NUM_JOINTS:
                    arr = arr.reshape(-1, NUM_JOINTS, 3)
                if arr.ndim == 3 and arr.shape[1:] == (NUM_JOINTS, 3):
                    return arr
    if clips is None:
        raise ValueError('fig5 needs a database with a positions array or clips')
    pos = np.concatenate([np.asarray(c.positions, float) for c in clips])
    return retarget(normalize(pos)[0], standard_body())


def fig5(database_postures: np.ndarray, query_postures: np.ndarray,
         dims: Sequence[int] = tuple(range(1, 61)), repeats: int = 3) -> Dict:
    """Shum & Ho 2012 Eq. 5-6: nearest database posture found in r PCA dimensions; the full-space
    squared error of the match e_r, its excess over the 60-D match in %, and the search time."""
    db = np.asarray(database_postures, float).reshape(len(database_postures), -1)
    q = np.asarray(query_postures, float).reshape(len(query_postures), -1)
    mean = db.mean(axis=0)
    _, _, vt = np.linalg.svd(db - mean, full_matrices=False)
    full_dim = db.shape[1]
    rows = []
    errs = {}
    for r in sorted(set(int(d) for d in dims if 1 <= d <= full_dim)):
        basis = vt[:r].T
        dbr = (db - mean) @ basis
        best_t = np.inf
        for _ in range(max(1, repeats)):
            t0 = time.perf_counter()
            qr = (q - mean) @ basis
            d2 = (qr ** 2).sum(1)[:, None] - 2 * qr @ dbr.T + (dbr ** 2).sum(1)[None]
            idx = np.argmin(d2, axis=1)
            best_t = min(best_t, time.perf_counter() - t0)
        e = ((q - db[idx]) ** 2).sum(axis=1)  # Eq. 5 (squared error in the full space)
        errs[r] = e
        rows.append({'dims': r, 'error_m2': float(e.mean()),
                     'search_ms_per_query': best_t * 1e3 / len(q)})
    e_full = errs[max(errs)].sum()
    for row in rows:
        row['error_pct'] = float((errs[row['dims']].sum() - e_full) / max(e_full, 1e-12) * 100)
    return {'experiment': 'fig5', 'rows': rows, 'database_size': len(db), 'queries': len(q)}


# ------------------------------------------------------------------------------------------
# Fig. 8: parameter sweeps
# ------------------------------------------------------------------------------------------
FIG8_SWEEPS = {
    'db_size': (250, 500, 1000, 2000, 4000),
    'k': (5, 10, 20, 30, 50, 80),
    'pca_dims': (2, 5, 10, 15, 20, 30, 40),
    'steps': (1, 5, 10, 20, 30, 40),
    'samples': (10, 25, 50, 100, 200),
}


def fig8(method: str, clips, params: Sequence[str] = tuple(FIG8_SWEEPS), seed: int = 0,
         max_frames: Optional[int] = 300, scenario: str = 'a', sensor_params=None,
         sweeps: Optional[Dict] = None, data_source: str = '', progress=None) -> Dict:
    """Error (Eq. 18) and frame time of ``method`` as each parameter varies (others at defaults).
    A value the factory rejects (TypeError/ValueError) is recorded as skipped with the reason."""
    sweeps = {**FIG8_SWEEPS, **(sweeps or {})}
    sensor = SensorModel(sensor_params, seed=seed)
    streams = make_streams(clips, (scenario,), seed, max_frames, sensor)
    out: Dict[str, List] = {}
    for param in params:
        rows = []
        for v in sweeps[param]:
            try:
                make_method(method, **{param: v})
            except (TypeError, ValueError) as exc:
                rows.append({'value': v, 'skipped': str(exc)})
                continue
            r = evaluate_streams([(method, {param: v})], streams, progress=progress)
            res = r['results'][method][scenario]
            rows.append({'value': v, 'eq18_cm': res['metrics']['eq18_cm']['overall'],
                         'mpjpe_cm': res['metrics']['mpjpe_cm']['overall'],
                         'frame_ms': res['time']['mean_ms']})
        out[param] = rows
    return {'experiment': 'fig8', 'method': method, 'scenario': scenario, 'sweeps': out,
            'meta': run_meta(clips, seed, sensor, max_frames, data_source)}
