#!/bin/bash
# The packages the device machine lacks (it has torch, numpy, pandas 3 and no network), for Python 3.12, slimmed to
# fit the 64 MiB a device call may carry: .dev/site.tar.xz (11.5 MB), which device.sh unpacks. From the repository root.
set -e
source .venv/bin/activate
P="--no-deps --only-binary=:all: --python-version 3.12 --implementation cp --platform manylinux_2_28_x86_64
   --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d .whl"
for p in stable_baselines3==2.9.2 sb3_contrib==2.9.2 gymnasium==1.4.0 gymnasium_robotics==1.4.2 mujoco==3.11.0 \
    rl_zoo3==2.9.2 optuna==5.0.0 alembic==1.20.1 SQLAlchemy==2.1.9 colorlog==6.12.0 Mako==1.4.3 \
    Farama-Notifications==0.0.6 pettingzoo==1.27.0 glfw==2.11.0 PyOpenGL==3.1.10 sb3-team-hf-integration==3.2 \
    Shimmy==2.0.1 pytablewriter==1.2.1 cloudpickle==3.1.3 arch==7.2.0 greenlet wasabi; do
  python -m pip download -q $P $p
done
rm -rf /tmp/site && mkdir -p /tmp/site .dev
for w in .whl/*.whl; do unzip -q -o "$w" -d /tmp/site; done
cp -r .venv/lib/python3.11/site-packages/rliable /tmp/site/  # pure Python (imported by the challenge runner)
cd /tmp/site
rm -rf gymnasium_robotics/envs/assets/{kitchen_franka,adroit_hand,stls/hand} mujoco/{experimental,testdata,include} \
    mujoco/*_test.py OpenGL/raw/GL/NV* *.dist-info/RECORD
cd - > /dev/null && tar cJf .dev/site.tar.xz -C /tmp/site .
