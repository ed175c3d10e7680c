"""Pure-Python core of the Kinect posture pipeline (no rclpy). See :mod:`skeleton_core.model`."""
import os as _os

# Every per-frame computation here is many small matrix products: a multi-threaded BLAS adds
# nothing but its spinning threads (a node's CPU doubles: 176 % -> 91 % for the one-process graph
# at one user). Takes effect when this package is imported before numpy; every package of the
# workspace imports it first, and scripts/env.sh and the launch files set it for every process.
for _var in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
    _os.environ.setdefault(_var, '1')

# Nothing of the workspace renders with MuJoCo: without this, `import mujoco` loads its OpenGL
# backend (glfw), which probes each libglfw it finds in a Python subprocess (~0.04 s CPU and
# 0.05-0.2 s in the physics node's start). An explicit MUJOCO_GL (egl, osmesa, glfw) still applies.
_os.environ.setdefault('MUJOCO_GL', 'disable')
