"""One-way imports between the package's folders: the tasks and the pixel agents stand on the leaf modules alone (the
argument checks, the optimizer settings), which import nothing of the package; and no module imports, at any depth of
its code, one that imports it back."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "sb3_pilot"
#: The package's leaf modules: any module may import them.
LEAVES = ("sb3_pilot.checks", "sb3_pilot.optimizers")


def package_imports(path: Path) -> set[str]:
    """The ``sb3_pilot`` modules a source file imports (at any depth of its code)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return {name for name in names if name.split(".")[0] == "sb3_pilot"}


@pytest.mark.parametrize(("folder", "allowed"), [("envs", ("sb3_pilot.envs",)), ("pixels", ("sb3_pilot.pixels",))])
def test_folder_imports_only_itself_and_the_checks(folder: str, allowed: tuple[str, ...]) -> None:
    """No arrow from envs/ (or pixels/) up into common/ or any other folder: only their own modules and the checks."""
    for path in sorted((PACKAGE / folder).glob("*.py")):
        foreign = {name for name in package_imports(path) if name not in LEAVES and not name.startswith(allowed)}
        assert not foreign, f"{path.name} imports {sorted(foreign)}"


def test_the_leaves_import_nothing_of_the_package() -> None:
    for name in LEAVES:
        assert not package_imports(PACKAGE.parent / f"{name.replace('.', '/')}.py"), name


def test_the_sac_core_knows_no_pixel_policy() -> None:
    """The lean SAC step reaches a pixel policy through its extension point (StepHooks), never by importing it."""
    for path in [PACKAGE / "common" / "lean.py", *sorted((PACKAGE / "sac").glob("*.py"))]:
        assert not {name for name in package_imports(path) if "pixels" in name or "torch_layers" in name}, path.name


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def test_no_import_cycles() -> None:
    """
    No circle of imports between the package's modules, counting those inside functions (a lazy import only hides
    one): ``from package import name`` is an arrow to ``package.name`` where that is a module, else to ``package``.
    """
    modules = {_module_name(path): path for path in PACKAGE.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        targets: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets.update(
                    f"{node.module}.{alias.name}" if f"{node.module}.{alias.name}" in modules else node.module
                    for alias in node.names
                )
            elif isinstance(node, ast.Import):
                targets.update(alias.name for alias in node.names)
        graph[name] = {target for target in targets if target in modules and target != name}
    done: set[str] = set()

    def visit(module: str, path: list[str]) -> None:
        for target in sorted(graph[module]):
            assert target not in path, "import cycle: " + " -> ".join([*path[path.index(target) :], target])
            if target not in done:
                visit(target, [*path, target])
        done.add(module)

    for module in sorted(graph):
        if module not in done:
            visit(module, [module])
