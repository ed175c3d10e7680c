"""Launch files, parameter files, the one-process pipeline, the demo, benchmark and soak commands."""
import skeleton_core  # noqa: E402,F401  (first: single-threaded BLAS, see there)
