"""Off-screen MuJoCo rendering without a GPU (OSMesa), set before MuJoCo is first imported."""

import os

os.environ.setdefault("MUJOCO_GL", "osmesa")
os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
