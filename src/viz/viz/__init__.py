"""RViz markers for raw, reconstructed and simulated skeletons, and the offline demo report."""
