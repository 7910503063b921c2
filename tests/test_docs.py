"""
Every Python code block of the docs (``docs/**/*.md``, ``docs/**/*.rst``) and of the README runs, page by page, in
the order written (the blocks of one page share a namespace, as a reader's session would). The docs themselves are
built with warnings as errors by ``make test`` / ``make docs`` (``sphinx-build -W``), not here.
"""

import importlib.util
import re
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

MARKDOWN_BLOCK = re.compile(r"^( *)```python\n(.*?)^\1```$", re.MULTILINE | re.DOTALL)  # fences in list items too
RST_BLOCK = re.compile(r"^\.\. code-block:: python\n((?:\n|   .*\n)+)", re.MULTILINE)


def python_blocks(path: Path) -> list[str]:
    """The Python code blocks of a Markdown (```python fences) or reStructuredText (``.. code-block:: python``) page."""
    text = path.read_text()
    if path.suffix == ".md":
        return [textwrap.dedent(block) for _, block in MARKDOWN_BLOCK.findall(text)]
    return ["\n".join(line[3:] for line in block.splitlines()) for block in RST_BLOCK.findall(text)]


PAGES = sorted(
    path
    for path in [*DOCS.rglob("*.md"), *DOCS.rglob("*.rst"), ROOT / "README.md"]
    if "_build" not in path.parts and python_blocks(path)
)


COMMANDS = re.compile(r"python -m ((?:sb3_pilot|benchmarks)[a-z0-9_.]*)")  # lower case: not a placeholder such as ...X
CONF_FILES = re.compile(r"--conf-file (?:hyperparams/)?([\w/]+\.yml)")


def test_commands_name_what_exists() -> None:
    """Every ``python -m sb3_pilot...`` or ``python -m benchmarks...`` module and ``--conf-file`` named in the docs, the
    README and the results folders' READMEs exists (commands stay true after moves)."""
    texts = [path.read_text() for path in [*DOCS.rglob("*.md"), *DOCS.rglob("*.rst"), *ROOT.glob("zoo_runs/**/README.md")]]
    texts = [*texts, (ROOT / "README.md").read_text()]
    modules = {module.rstrip(".") for text in texts for module in COMMANDS.findall(text)}
    conf_files = {name for text in texts for name in CONF_FILES.findall(text)}
    assert {"sb3_pilot.experiments.challenges", "benchmarks.sources"} <= modules and "cpu/udpo.yml" in conf_files
    assert [module for module in sorted(modules) if importlib.util.find_spec(module) is None] == []
    assert [name for name in sorted(conf_files) if not (ROOT / "hyperparams" / name).is_file()] == []


def test_extraction_finds_the_pages() -> None:
    """The extraction sees the pages that have examples (a broken pattern would silently test nothing)."""
    names = {path.relative_to(ROOT).as_posix() for path in PAGES}
    assert {"README.md", "docs/guide/quickstart.md", "docs/guide/algos.md", "docs/modules/udpo.rst"} <= names
    assert len(python_blocks(DOCS / "guide" / "quickstart.md")) >= 6


@pytest.mark.parametrize("page", PAGES, ids=lambda path: path.relative_to(ROOT).as_posix())
def test_code_blocks_run(page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The page's blocks run in order, in one namespace, in an empty working directory (files they save land there)."""
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": f"docs_{page.stem}"}
    for index, block in enumerate(python_blocks(page)):
        code = compile(block, f"{page.relative_to(ROOT)} (block {index + 1})", "exec")
        exec(code, namespace)
