#!/usr/bin/env bash
# Creates .venv (if missing) with everything sb3-pilot needs, CPU only.
# Off-screen rendering (image tasks) needs OSMesa: Debian package libosmesa6, MUJOCO_GL=osmesa.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-python3}

if ! dpkg -s libosmesa6 >/dev/null 2>&1; then
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "[setup] installing libosmesa6 (off-screen MuJoCo rendering without a GPU)"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libosmesa6 >/dev/null
  else
    echo "[setup] WARNING: libosmesa6 is missing and cannot be installed here (need root + apt-get);" \
      "image tasks will not render. Install it with: sudo apt-get install libosmesa6" >&2
  fi
fi

[ -x "$VENV/bin/python" ] || "$PYTHON" -m venv "$VENV"
"$VENV/bin/python" -m pip install -q --upgrade pip
# The CPU wheel first, pinned, so that no multi-GB CUDA build is pulled by a dependency.
"$VENV/bin/python" -m pip install -q torch==2.13.0
"$VENV/bin/python" -m pip install -q -e ".[tests]"
touch "$VENV/.installed"
