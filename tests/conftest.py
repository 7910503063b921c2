"""Test-session settings: off-screen MuJoCo rendering (OSMesa) and one torch thread per test process."""

import os

os.environ.setdefault("MUJOCO_GL", "osmesa")
os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import torch as th  # after the rendering variables, which MuJoCo reads when first imported

# pytest -n 2 runs two processes on a 2-core machine: more threads per process only oversubscribe it
th.set_num_threads(1)
