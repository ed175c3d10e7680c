"""Launch files, parameter files, the one-process pipeline and the user tools (demo, recorder,
process_bag, recover_bag, calibrate_extrinsics)."""
import skeleton_core  # noqa: E402,F401  (first: single-threaded BLAS, see there)
