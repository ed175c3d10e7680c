"""Posture reconstruction (Shum et al. 2013): per-joint reliability, database completion and the natural-posture-space optimizer."""
import os as _os

# The per-frame work is many small matrix products: a multi-threaded BLAS only adds contention on a
# shared machine (and stalls of tens of ms). Applies when this package is imported before numpy.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    _os.environ.setdefault(_var, '1')
