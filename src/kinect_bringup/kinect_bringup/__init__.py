"""Launch files, parameter files, the one-process pipeline, the demo, benchmark and soak commands."""
