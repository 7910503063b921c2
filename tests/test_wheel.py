"""
The wheel (``pip install .``, not editable): what it holds, and that it works installed, outside the checkout.

The wheel is built from a copy of the files ``setup.cfg`` reads (no ``build/`` nor ``*.egg-info`` left in the checkout)
and installed, without downloads, into a fresh virtual environment that finds the dependencies in this interpreter's
``site-packages``. The checks that run a challenge and the demo from it take minutes: they run when
``SB3_PILOT_TEST_WHEEL=1`` is set (``SB3_PILOT_TEST_WHEEL=1 python -m pytest tests/test_wheel.py``).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

from sb3_pilot.experiments import demo
from sb3_pilot.experiments.challenges.stages import Shipped

ROOT = Path(__file__).resolve().parents[1]
#: What the build reads: the package, its data and its metadata.
BUILD_INPUTS = ("setup.cfg", "pyproject.toml", "README.md", "sb3_pilot", "hyperparams")
#: Set to 1 to run the installed wheel's challenge and demo (minutes).
RUN_INSTALLED = os.environ.get("SB3_PILOT_TEST_WHEEL") == "1"
needs_time = pytest.mark.skipif(not RUN_INSTALLED, reason="minutes: set SB3_PILOT_TEST_WHEEL=1 to run")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel ``pip wheel`` builds from the checkout's package files."""
    build = tmp_path_factory.mktemp("wheel")
    source = build / "source"
    source.mkdir()
    for name in BUILD_INPUTS:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy(ROOT / name, source / name)
    command = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q"]
    subprocess.run([*command, "-w", str(build / "dist"), str(source)], check=True, capture_output=True)
    (path,) = (build / "dist").glob("sb3_pilot-*.whl")
    return path


@pytest.fixture(scope="module")
def installed(wheel: Path) -> Path:
    """A fresh virtual environment with the wheel installed; its Python finds the dependencies in this interpreter's."""
    venv = wheel.parents[1] / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    install = [sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index", "-q"]
    subprocess.run([*install, str(wheel)], check=True, capture_output=True)
    purelib = "import sysconfig; print(sysconfig.get_path('purelib'))"
    site_packages = Path(subprocess.check_output([str(python), "-c", purelib], text=True).strip())
    # the dependencies: this interpreter's site-packages, after the new environment's own (a path line of a .pth file
    # is not itself searched for .pth files, so an editable install of sb3_pilot there is not picked up)
    dependencies = {sysconfig.get_path("purelib"), sysconfig.get_path("platlib")}
    (site_packages / "_sb3_pilot_test_dependencies.pth").write_text("\n".join(sorted(dependencies)) + "\n")
    return python


def run_installed(python: Path, cwd: Path, *args: str, timeout: float) -> subprocess.CompletedProcess[str]:
    """Run the installed environment's Python in ``cwd`` (outside the checkout), one thread, off-screen rendering."""
    env = {key: value for key, value in os.environ.items() if key != "PYTHONPATH"}
    env |= {"OMP_NUM_THREADS": "1", "MUJOCO_GL": "osmesa", "PYOPENGL_PLATFORM": "osmesa"}
    cwd.mkdir(parents=True, exist_ok=True)
    return subprocess.run([str(python), *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout, check=False)


def test_wheel_holds_the_package_and_every_preset(wheel: Path) -> None:
    """The wheel holds ``sb3_pilot`` with its task assets and every YAML file of ``hyperparams/`` (setup.cfg's
    ``data_files`` name each folder: a new folder must be added there), nothing of ``benchmarks/``, ``tests/`` or
    ``zoo_runs/``."""
    names = zipfile.ZipFile(wheel).namelist()
    data = next(name.split("/")[0] for name in names if name.split("/")[0].endswith(".data"))
    shipped = {name.removeprefix(f"{data}/data/share/sb3_pilot/") for name in names if name.startswith(f"{data}/")}
    presets = {path.relative_to(ROOT).as_posix() for path in (ROOT / "hyperparams").rglob("*") if path.is_file()}
    assert "hyperparams/cpu/udpo.yml" in presets
    assert sorted(presets - shipped) == [], "hyperparams files left out of the wheel: add their folder to data_files"
    assert "sb3_pilot/experiments/challenges/__main__.py" in names
    assert any(name.startswith("sb3_pilot/envs/assets/") and name.endswith(".xml") for name in names)
    assert [name for name in names if name.split("/")[0] in ("benchmarks", "tests", "zoo_runs")] == []


def test_installed_package_reads_its_own_presets(installed: Path, tmp_path: Path) -> None:
    """Installed, ``sb3_pilot`` and ``hyperparams_dir()`` resolve inside the environment, not in the checkout."""
    code = (
        "import json, sb3_pilot; from sb3_pilot.experiments.zoo import hyperparams_dir; "
        "print(json.dumps([sb3_pilot.__file__, str(hyperparams_dir())]))"
    )
    result = run_installed(installed, tmp_path, "-c", code, timeout=300)
    assert result.returncode == 0, result.stderr
    package, presets = (Path(path) for path in json.loads(result.stdout.splitlines()[-1]))
    venv = installed.parents[1]
    assert package.is_relative_to(venv) and presets.is_relative_to(venv), (package, presets)
    assert (presets / "cpu" / "udpo.yml").is_file()


@needs_time
def test_installed_smoke_challenge_runs_outside_the_checkout(installed: Path, tmp_path: Path) -> None:
    """``python -m sb3_pilot.experiments.challenges high-dim-action --budget smoke`` from the wheel, in an empty folder."""
    args = ["-m", "sb3_pilot.experiments.challenges", "high-dim-action", "--budget", "smoke", "--no-progress"]
    result = run_installed(installed, tmp_path, *args, timeout=3600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    summary = json.loads((tmp_path / "runs" / "high-dim-action" / "summary.json").read_text())
    assert summary["seeds"] == [0] and len(summary["methods"]) == 2


@needs_time
def test_installed_demo_runs_what_needs_no_shipped_file(installed: Path, tmp_path: Path) -> None:
    """The demo from the wheel, tiny budgets: the planner transfer runs; the reward bonus, which reads the repository's
    shipped planner, is skipped with a message naming the clone."""
    steps = ["--source-steps", "300", "--steps", "300", "--bonus-steps", "300", "--bonus-seeds", "1"]
    result = run_installed(installed, tmp_path, "-m", "sb3_pilot.experiments.demo", *steps, timeout=3600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "Target Pilot/FetchReachHighDim-v0" in result.stdout
    assert "clone of the repository" in result.stdout
    assert (tmp_path / "runs" / "demo" / "high-dim-action" / "summary.json").is_file()


def test_demo_without_the_shipped_planner_skips_the_bonus(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Where the shipped planner is missing (an install from the wheel), the demo says why it skips the reward bonus,
    before any of its work, and ends normally."""
    missing = Shipped("distill", tmp_path / "zoo_runs" / "maze2d_planner.pt")
    stages = (missing, *(stage for stage in demo.BONUS_CHALLENGE.stages if stage.name != "distill"))
    monkeypatch.setattr(demo, "BONUS_CHALLENGE", dataclasses.replace(demo.BONUS_CHALLENGE, stages=stages))
    monkeypatch.setattr(demo, "planner_transfer", lambda *args: [])
    demo.main(["--root", str(tmp_path / "runs"), "--bonus-seeds", "1"])
    out = capsys.readouterr().out
    assert "Reward bonus skipped: The shipped file" in out and "clone of the repository" in out and "Wall time" in out
    assert not (tmp_path / "runs" / demo.BONUS_CHALLENGE.name / "models").exists()
