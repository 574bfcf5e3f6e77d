"""Every ```python block in docs/*.md and README.md runs, so the documentation cannot rot.

Each document's blocks run in order in one namespace (a later block may use
names from an earlier one, as a reader would), with the working directory a
fresh temporary folder so that examples can write files freely. A block is
compiled under the document's path, padded so that a traceback points at the
real line of the Markdown file.
"""

import textwrap
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parents[1]

FENCE_OPENING = "```python"
FENCE_CLOSING = "```"


def documents() -> list[Path]:
    """The Markdown files whose Python examples are executed."""
    found = sorted((REPOSITORY / "docs").glob("*.md"))
    readme = REPOSITORY / "README.md"
    if readme.is_file():
        found.append(readme)
    return found


def python_blocks(path: Path) -> list[tuple[int, str]]:
    """The ```python blocks of a Markdown file: (1-based line of the first code line, code).

    Fences may be indented (inside a list); the code is dedented accordingly.
    Blocks in other languages (```console, ```toml) are left alone.
    """
    blocks = []
    code_lines = None  # None while outside a python block
    first_line = 0
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        stripped = line.strip()
        if code_lines is None:
            if stripped == FENCE_OPENING:
                code_lines, first_line = [], number + 1
        elif stripped == FENCE_CLOSING:
            blocks.append((first_line, textwrap.dedent("\n".join(code_lines))))
            code_lines = None
        else:
            code_lines.append(line)
    if code_lines is not None:
        raise AssertionError(f"{path}:{first_line - 1}: a ```python block is never closed")
    return blocks


@pytest.mark.parametrize("path", documents(), ids=lambda p: str(p.relative_to(REPOSITORY)))
def test_python_examples_run(path, tmp_path, monkeypatch):
    blocks = python_blocks(path)
    if not blocks:
        pytest.skip(f"{path.name} has no python examples")
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__main__"}
    for first_line, code in blocks:
        # Blank lines in front keep the traceback's line numbers those of the file.
        compiled = compile("\n" * (first_line - 1) + code, str(path), "exec")
        exec(compiled, namespace)


def test_block_finder(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(
        "# Title\n"
        "```python\n"
        "x = 1\n"
        "```\n"
        "```console\n"
        "$ scattertrack demo\n"
        "```\n"
        "1. a step\n"
        "   ```python\n"
        "   y = x + 1\n"
        "   ```\n"
    )
    assert python_blocks(page) == [(3, "x = 1"), (10, "y = x + 1")]


def test_documents_include_the_guide():
    names = [path.name for path in documents()]
    assert "simulator.md" in names
    assert "guide.md" in names
