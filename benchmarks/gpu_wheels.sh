#!/usr/bin/env bash
# What benchmarks/gpu_fast_path.sh needs on a bare GPU machine with Python 3.12, torch (CUDA), numpy, pandas and no
# package registry, fetched here into the ignored folder .gpu_wheels/ (carry it: run(carry=[".gpu_wheels"])):
#
# - wheels/: Python 3.12 x86-64 wheels of the packages that machine lacks, at the versions of this checkout's .venv
#   (SB3, Gymnasium, MuJoCo and its GLFW / PyOpenGL bindings, gymnasium-robotics and PettingZoo, which it imports; the
#   RL Zoo and what its train command imports: SB3-Contrib, huggingface_sb3 and wasabi, Optuna and colorlog);
#   gymnasium-robotics without the Adroit-hand and Franka-kitchen meshes (24 MB the Fetch and maze tasks never load);
# - gl/: the GL vendor-neutral dispatch libraries (libglvnd: libEGL, libOpenGL, libGL, libGLX, libGLES) as Debian
#   packages, which MuJoCo's EGL rendering loads; NVIDIA's own EGL library comes with the machine's driver.
#
# Usage (from the repository root): bash benchmarks/gpu_wheels.sh   (prints the sizes; the carried total must stay
# under the device's 64 MiB with the working tree)
set -euo pipefail
cd "$(dirname "$0")/.."
DEST=.gpu_wheels
PIP=${PIP:-.venv/bin/pip}
PY=${PY:-.venv/bin/python}
PACKAGES="stable_baselines3 gymnasium Farama-Notifications mujoco glfw PyOpenGL gymnasium-robotics pettingzoo
    rl_zoo3 sb3_contrib sb3-team-hf-integration wasabi optuna colorlog"
GL_PACKAGES="libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2"

rm -rf "$DEST"
mkdir -p "$DEST/wheels" "$DEST/gl"
# pinned to this checkout's versions
freeze=$("$PIP" freeze 2>/dev/null)
pins=()
for package in $PACKAGES; do
    pattern=$(echo "$package" | sed 's/[-_]/[-_]/g')
    pin=$(echo "$freeze" | grep -i "^${pattern}==" || true)
    if [ -z "$pin" ]; then
        echo "$package is not installed in .venv" >&2
        exit 1
    fi
    pins+=("$pin")
done
echo "wheels: ${pins[*]}"
"$PIP" download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 --platform manylinux1_x86_64 -d "$DEST/wheels" "${pins[@]}"

# gymnasium-robotics without the meshes of tasks the package never makes (their RECORD lines dropped too)
"$PY" - "$DEST/wheels" <<'EOF'
import pathlib, sys, zipfile

SKIPPED = ("gymnasium_robotics/envs/assets/adroit_hand/", "gymnasium_robotics/envs/assets/kitchen_franka/")
(wheel,) = pathlib.Path(sys.argv[1]).glob("gymnasium_robotics-*.whl")
slim = wheel.with_suffix(".slim")
with zipfile.ZipFile(wheel) as source, zipfile.ZipFile(slim, "w", zipfile.ZIP_DEFLATED) as target:
    for item in source.infolist():
        if item.filename.startswith(SKIPPED):
            continue
        data = source.read(item)
        if item.filename.endswith(".dist-info/RECORD"):
            lines = data.decode().splitlines(keepends=True)
            data = "".join(line for line in lines if not line.startswith(SKIPPED)).encode()
        target.writestr(item, data)
slim.replace(wheel)
EOF

# libglvnd's libraries, as the device notes fetch them (for x86-64, whatever this machine is)
APT_LISTS=$(mktemp -d)
mkdir -p "$APT_LISTS/partial"
apt_options=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$APT_LISTS")
apt-get "${apt_options[@]}" update -qq
(cd "$DEST/gl" && apt-get "${apt_options[@]}" download $GL_PACKAGES 2>&1 | grep -v "^W: Download is performed unsandboxed" || true)

ls -l "$DEST/wheels" "$DEST/gl"
# what travels besides: tracked files that exist, untracked ones that git does not ignore
tree_bytes=$( (git ls-files -z; git ls-files -z --others --exclude-standard) | "$PY" -c '
import os, sys
paths = set(sys.stdin.buffer.read().split(b"\0")) - {b""}
print(sum(os.path.getsize(path) for path in paths if os.path.isfile(path)))')
carried_bytes=$(du -sb "$DEST" | cut -f1)
echo "working tree $((tree_bytes / 1048576)) MiB + $DEST $((carried_bytes / 1048576)) MiB = $(((tree_bytes + carried_bytes) / 1048576)) MiB (device limit: 64 MiB)"
