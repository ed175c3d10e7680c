"""MuJoCo physics character PD-tracking reconstructed postures (Shum & Ho 2012), with virtual joints,
objects and pushes."""
import skeleton_core  # noqa: E402,F401  (first: single-threaded BLAS, see there)
