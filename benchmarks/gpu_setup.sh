# Sourced (from the repository root) by the scripts that run on a bare GPU machine with Python 3.12, torch (CUDA),
# numpy and pandas but no SB3 / Gymnasium / MuJoCo / RL Zoo and no package registry (benchmarks/gpu_fast_path.sh,
# benchmarks/gpu_image_recipe.sh):
#
#   1. installs the wheels of .gpu_wheels/wheels (made here by benchmarks/gpu_wheels.sh) with pip --no-index into
#      a temporary folder, put on PYTHONPATH with the checkout (the machine's python3 is itself a venv, whose torch
#      a --system-site-packages venv would not see); OMP_NUM_THREADS=1, PYTHONUNBUFFERED=1;
#   2. sets up EGL: unpacks libglvnd's libraries (.gpu_wheels/gl) onto /, points glvnd at NVIDIA's EGL vendor file,
#      MUJOCO_GL=egl PYOPENGL_PLATFORM=egl.
#
# Returns 1 (the caller exits) when the wheels are missing or do not install.
if [ ! -d .gpu_wheels/wheels ]; then
    echo "no .gpu_wheels/wheels: run benchmarks/gpu_wheels.sh here and carry .gpu_wheels" >&2
    return 1
fi
SITE=$(mktemp -d)
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" .gpu_wheels/wheels/*.whl || return 1
export PYTHONPATH="$SITE:$PWD"
export OMP_NUM_THREADS=1 PYTHONUNBUFFERED=1

for deb in .gpu_wheels/gl/*.deb; do dpkg -x "$deb" /; done
ldconfig
for vendor in /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json /usr/share/glvnd/egl_vendor.d/10_nvidia.json; do
    if [ -f "$vendor" ]; then
        export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
        break
    fi
done
export MUJOCO_GL=egl PYOPENGL_PLATFORM=egl
echo "__EGL_VENDOR_LIBRARY_FILENAMES=${__EGL_VENDOR_LIBRARY_FILENAMES:-unset}"
