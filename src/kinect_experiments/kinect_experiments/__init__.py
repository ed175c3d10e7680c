"""Evaluation and experiment tools: accuracy tables, real-data LOSO, benchmarks, soak, fuzzing,
the parameter reference."""
import skeleton_core  # noqa: E402,F401  (first: single-threaded BLAS, see there)
