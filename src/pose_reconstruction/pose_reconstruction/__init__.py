"""Posture reconstruction (Shum et al. 2013): per-joint reliability, database completion and the natural-posture-space optimizer."""
