"""Posture reconstruction (Shum et al. 2013): per-joint reliability, database completion and the
natural-posture-space optimizer."""
import skeleton_core  # noqa: F401  (first: single-threaded BLAS, see there)
