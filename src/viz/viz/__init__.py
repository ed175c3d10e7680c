"""RViz markers for raw, reconstructed and simulated skeletons, and the offline demo report."""
import skeleton_core  # noqa: E402,F401  (first: single-threaded BLAS, see there)
