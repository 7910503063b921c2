"""The repository's layout: the library, the benchmarks and the results each in their place, and no machine paths."""

from __future__ import annotations

import ast
import configparser
import dataclasses
import re
import subprocess
from pathlib import Path

import pytest
from setuptools import find_packages

from benchmarks.zoo_runs_index import render
from sb3_pilot.experiments import guided_video
from sb3_pilot.experiments.challenges import REUSE_SHIPPED, run_challenge
from sb3_pilot.experiments.challenges.__main__ import main as challenges_main
from sb3_pilot.experiments.challenges.stages import Shipped, ShippedFileMissing

ROOT = Path(__file__).resolve().parents[1]
#: The home, workspace and temporary folders of the machines that made results (written apart here, so that this file
#: does not name them)
MACHINE_ROOTS = ("work", "root", "home", "tmp", "Users")
#: An absolute path into one of them, e.g. the temporary folder followed by a name (not a placeholder: ``/x/...``)
MACHINE_PATH = re.compile(r"(?<![\w.~<>/-])/(?:" + "|".join(MACHINE_ROOTS) + r")/(?=\w)")
CODE_SUFFIXES = (".py", ".sh", ".patch")


def repository_files() -> list[Path]:
    """The tracked files and the new ones git would track (not ignored), relative to the repository root."""
    try:
        listed = subprocess.run(
            ["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
            cwd=ROOT,
            capture_output=True,
            check=True,
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return sorted({Path(name) for name in listed.decode().split("\0") if name and (ROOT / name).is_file()})


def text_of(path: Path) -> str | None:
    """The file's text, or None for a binary file."""
    data = (ROOT / path).read_bytes()
    if b"\0" in data:
        return None
    try:
        return data.decode()
    except UnicodeDecodeError:
        return None


def tmp_allowed(path: Path) -> bool:
    """Example commands in the docs and in Markdown pages may write to ``/tmp``."""
    return path.parts[0] == "docs" or path.suffix == ".md"


def test_no_machine_paths() -> None:
    """No committed file names a folder of the machine that made it (results hold ``<run>``, ``<scratch>`` or
    repository-relative paths instead)."""
    found = []
    for path in repository_files():
        text = text_of(path)
        if text is None:
            continue
        for number, line in enumerate(text.splitlines(), start=1):
            for match in MACHINE_PATH.finditer(line):
                if match.group() == "/tmp/" and tmp_allowed(path):
                    continue
                found.append(f"{path}:{number}: {line.strip()[:160]}")
    assert not found, "machine paths in committed files:\n" + "\n".join(found[:50])


def test_machine_path_pattern() -> None:
    """The pattern finds a path alone, quoted or after ``=``, and leaves placeholders and relative paths alone."""
    work, tmp, home, root, users = (f"/{name}/" for name in ("work", "tmp", "home", "root", "Users"))
    hits = [f"{work}main/x", f"'{tmp}run/y'", f"folder={home}me", f"({root}a)", f"x {users}me"]
    misses = [f"{home}...", "<scratch>/fp3", "zoo_runs/tmp/x", "~/tmp/x", "https://x.org/home/page", "./tmp/x"]
    assert [text for text in hits if not MACHINE_PATH.search(text)] == []
    assert [text for text in misses if MACHINE_PATH.search(text)] == []


def test_zoo_runs_holds_no_code() -> None:
    code = [str(path) for path in repository_files() if path.parts[0] == "zoo_runs" and path.suffix in CODE_SUFFIXES]
    assert not code, f"zoo_runs/ holds results only; move these to benchmarks/ or delete them: {code}"


def imported_modules(path: Path) -> list[tuple[str, list[str]]]:
    """``(module, names)`` of every import in a Python file (names empty for ``import module``)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(alias.name, []) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.module, [alias.name for alias in node.names]))
    return found


def test_library_does_not_import_benchmarks() -> None:
    offenders = [
        f"{path.relative_to(ROOT)}: {module}"
        for path in sorted((ROOT / "sb3_pilot").rglob("*.py"))
        for module, _ in imported_modules(path)
        if module == "benchmarks" or module.startswith("benchmarks.")
    ]
    assert not offenders


def public_names(package: str) -> set[str]:
    """``__all__`` of a package's ``__init__.py``, read without importing it."""
    init = ROOT / package.replace(".", "/") / "__init__.py"
    for node in ast.parse(init.read_text()).body:
        if isinstance(node, ast.Assign) and any(getattr(target, "id", None) == "__all__" for target in node.targets):
            return set(ast.literal_eval(node.value))
    return set()


def test_benchmarks_use_the_public_api() -> None:
    """``benchmarks/`` imports what ``sb3_pilot`` and its subpackages export (and the ``sb3_pilot.experiments`` runners),
    never a library module's internals."""
    offenders = []
    for path in sorted((ROOT / "benchmarks").glob("*.py")):
        for module, names in imported_modules(path):
            if not (module == "sb3_pilot" or module.startswith("sb3_pilot.")) or module.startswith("sb3_pilot.experiments"):
                continue
            package = ROOT / module.replace(".", "/") / "__init__.py"
            private = set(names) - public_names(module) if package.is_file() and names else {module}
            offenders += [f"{path.name}: {module}.{name}" for name in sorted(private)]
    assert not offenders


def test_wheel_holds_the_library_only() -> None:
    """The packages ``setup.cfg`` selects: ``sb3_pilot`` and its subpackages, not ``benchmarks`` nor ``tests``."""
    config = configparser.ConfigParser()
    config.read(ROOT / "setup.cfg")
    include = config["options.packages.find"]["include"].split()
    packages = find_packages(where=str(ROOT), include=include)
    assert "sb3_pilot.experiments.challenges" in packages
    assert [package for package in packages if not package.startswith("sb3_pilot")] == []


def test_zoo_runs_index_is_current() -> None:
    """``zoo_runs/README.md`` is what ``python -m benchmarks.zoo_runs_index`` writes from the summaries and READMEs."""
    assert (ROOT / "zoo_runs" / "README.md").read_text() == render(ROOT / "zoo_runs"), (
        "zoo_runs/README.md is not current: run python -m benchmarks.zoo_runs_index"
    )


def test_missing_shipped_file_names_the_clone(tmp_path: Path) -> None:
    """Installed without the repository, ``--reuse-shipped`` says where the shipped files are, before any work."""
    missing = Shipped("distill", tmp_path / "zoo_runs" / "maze2d_planner.pt")
    challenge = REUSE_SHIPPED["maze-car"]
    challenge = dataclasses.replace(challenge, stages=(missing, *challenge.stages[1:]))
    root = tmp_path / "runs"
    with pytest.raises(ShippedFileMissing, match="clone of the repository"):
        run_challenge(challenge, "smoke", root=root)
    assert not root.exists() or not any(root.rglob("*.zip"))
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(REUSE_SHIPPED, "maze-car", challenge)
        with pytest.raises(SystemExit) as exit_info:
            challenges_main(["maze-car", "--reuse-shipped", "--budget", "smoke", "--root", str(root)])
    assert "maze-car-shipped: The shipped file" in str(exit_info.value.code)
    assert "not in the installed package" in str(exit_info.value.code)


def test_guided_video_without_the_shipped_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The video of the shipped guided Ant refuses to start, naming the clone, when the shipped files are not there."""
    stages = tuple(
        dataclasses.replace(stage, path=tmp_path / stage.path.name) if isinstance(stage, Shipped) else stage
        for stage in guided_video.CHALLENGES["v1"].stages
    )
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(guided_video.CHALLENGES, "v1", dataclasses.replace(guided_video.CHALLENGES["v1"], stages=stages))
        with pytest.raises(SystemExit):
            guided_video.main(["--output", str(tmp_path / "video.gif")])
    assert "clone of the repository" in capsys.readouterr().err
    assert not (tmp_path / "video.gif").exists()


def test_changelog_is_per_version_and_names_the_package_version() -> None:
    """``CHANGELOG.md`` has one section per version, newest first: at most one ``Unreleased`` section on top, then the
    version ``sb3_pilot.__version__`` says; each section split by kind of change only (Added, Changed, Removed...)."""
    from sb3_pilot.version import __version__

    text = (ROOT / "CHANGELOG.md").read_text()
    versions = re.findall(r"^## (.+)$", text, flags=re.MULTILINE)
    released = [version for version in versions if not version.startswith("Unreleased")]
    assert released and released[0] == __version__, f"CHANGELOG's latest release {released[:1]}, the package's {__version__}"
    assert versions.index(released[0]) == sum(version.startswith("Unreleased") for version in versions) <= 1
    kinds = set(re.findall(r"^### (.+)$", text, flags=re.MULTILINE))
    assert kinds <= {"Added", "Changed", "Deprecated", "Removed", "Fixed", "Security"}, kinds
