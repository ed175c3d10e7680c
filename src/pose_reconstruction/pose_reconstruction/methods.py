"""Reconstruction methods A, B and C for the evaluation harness.

Each factory returns a streaming, one-user :class:`~.reconstructor.Reconstructor` (``name``,
``reset()``, ``process(frame) -> frame``) and accepts keyword overrides of any parameter
(``k``, ``pca_dims``, ``steps``, ``samples``, ``solver``, the energy weights, the reliability
parameters, ...) and an optional ``db`` (a MotionDatabase or (N, 20, 3) array; default: the built-in
/ CMU database from ``skeleton_data.database.load_or_build_default``).

:func:`register` registers them with ``skeleton_eval.registry.register_method`` when that
harness is available (it is called on import, guarded).
"""
from __future__ import annotations

import functools
from typing import Callable, Dict, Optional

import numpy as np

from skeleton_core.params import defaults
from skeleton_core.params import load_preset as _load_preset

from .completion import CompletionConfig
from .optimizer import OptimizerConfig
from .posture_space import DatabaseArrays, as_database_arrays
from .reconstructor import Reconstructor, ReconstructorConfig
from .reliability import ReliabilityConfig
from pathlib import Path

_DEFAULT_DB = None


def default_database():
    """The default motion database (cached per process)."""
    global _DEFAULT_DB
    if _DEFAULT_DB is None:
        from skeleton_data.database import load_or_build_default
        _DEFAULT_DB = load_or_build_default()
    return _DEFAULT_DB


def subset(db, size: int):
    """``size`` postures of ``db`` evenly spread over it (Fig. 8a database-size sweeps)."""
    arr = as_database_arrays(db)
    size = int(size)
    if size < 2:
        raise ValueError('db_size must be >= 2')
    if size >= arr.size:
        return arr
    idx = np.linspace(0, arr.size - 1, size).round().astype(int)
    return DatabaseArrays(positions=arr.positions[idx], flat=arr.flat[idx],
                          orientations=None if arr.orientations is None else arr.orientations[idx],
                          twists=None if arr.twists is None else arr.twists[idx], body=arr.body)


def make_method(method: str, db=None, database: str = '', db_size: Optional[int] = None,
                **overrides) -> Reconstructor:
    """A method-``method`` reconstructor. ``db``: a database object; ``database``: a database file
    ('' = default); ``db_size``: use only that many postures of it. ``correction`` may be a
    :class:`~.correction.SensorCorrection` or a file name, ``profile`` a
    :class:`~.profile.UserProfile` or a profile file name."""
    corr = overrides.get('correction')
    if isinstance(corr, (str, Path)):
        from .correction import load as load_correction
        overrides['correction'] = load_correction(corr) if str(corr) else None
    prof = overrides.get('profile')
    if isinstance(prof, (str, Path)):
        from .profile import load as load_profile
        overrides['profile'] = load_profile(prof) if str(prof) else None
    if db is None:
        if database:
            from .node_common import load_database
            db = load_database(database)
        else:
            db = default_database()
    if db_size is not None:
        db = subset(db, db_size)
    r = Reconstructor(db, method=method, **overrides)
    r.name = method
    return r


make_method_a: Callable[..., Reconstructor] = functools.partial(make_method, 'A')
make_method_b: Callable[..., Reconstructor] = functools.partial(make_method, 'B')
make_method_c: Callable[..., Reconstructor] = functools.partial(make_method, 'C')

DESCRIPTIONS = {
    'A': 'Shum & Ho 2012: PCA database completion of unreliable joints',
    'B': 'Shum et al. 2013 natural-posture-space optimizer without reliability',
    'C': 'Shum et al. 2013 reliability-weighted natural-posture-space optimizer',
}
# the defaults the evaluation reports with each method, read from the parameter declarations
_OPT_DEFAULTS = defaults(OptimizerConfig, only=('k', 'pca_dims', 'steps', 'samples', 'w_control',
                                                'w_style', 'w_kinematics', 'w_continuity',
                                                'solver'))
DEFAULTS = {'A': defaults(CompletionConfig, only=('pca_dims', 'reliable_threshold')),
            'B': dict(_OPT_DEFAULTS), 'C': dict(_OPT_DEFAULTS)}

# what a preset file (config/presets/<name>.yaml) may set: any field of the reconstruction's
# configurations, public or not
PRESET_CLASSES = (ReliabilityConfig, CompletionConfig, OptimizerConfig, ReconstructorConfig)


def load_preset(path) -> Dict:
    """``{parameter: value}`` of a reconstruction preset file (every name and value checked
    against the declarations; ``skeleton_core.params.PresetError`` otherwise): keyword overrides
    of :func:`make_method` for methods A, B and C."""
    return _load_preset(path, PRESET_CLASSES)


FACTORIES: Dict[str, Callable[..., Reconstructor]] = {
    'A': make_method_a, 'B': make_method_b, 'C': make_method_c}


def register() -> bool:
    """Register A, B, C with the evaluation harness; False when the harness is not there."""
    try:
        from skeleton_eval.registry import register_method
    except ImportError:
        return False
    for name, factory in FACTORIES.items():
        register_method(name, factory, description=DESCRIPTIONS[name], defaults=DEFAULTS[name])
    return True


register()
