"""The pages under docs/ as a reader meets them: every code block runs or type-checks.

A page's fenced blocks are of four kinds:

* ``python title="name.py"`` and ``toml title="name.toml"``: files, written under
  their titles into a fresh folder (one per page, where ``apps`` and ``examples``
  of this repository are at hand); every Python file of a page is type-checked
  with ``mypy --strict``;
* ``console``: commands (``$ ...``) run in that folder by bash, in order, each
  followed by what it prints (stdout and stderr together): a line ``...`` stands
  for any lines, and ``...`` within a line for any text;
* ``text``: output shown as it is (checked where the behaviour is tested).

Nothing else is allowed, so a page cannot show code that no test runs.
"""

from __future__ import annotations

import inspect
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import pytest

ROOT: Final = Path(__file__).resolve().parents[1]
DOCS: Final = ROOT / "docs"
PAGES: Final = sorted(DOCS.glob("*.md"))
FENCE: Final = re.compile(r"^```(\w*)([^\n]*)\n(.*?)^```[ \t]*$", re.S | re.M)
TITLE: Final = re.compile(r'title="([^"]+)"')
LIMIT: Final = 120


@dataclass(frozen=True)
class Block:
    kind: str
    title: str | None
    text: str
    line: int


def blocks(page: Path) -> list[Block]:
    text = page.read_text(encoding="utf-8")
    found = []
    for match in FENCE.finditer(text):
        title = TITLE.search(match.group(2))
        line = text.count("\n", 0, match.start()) + 1
        found.append(Block(match.group(1), title and title.group(1), match.group(3), line))
    return found


def written(page: Path, folder: Path) -> list[Block]:
    """The page's files, written into ``folder`` (with the repository's apps and examples)."""
    for name in ("apps", "examples"):
        (folder / name).symlink_to(ROOT / name)
    found = blocks(page)
    for block in found:
        if block.title is not None:
            (folder / block.title).write_text(block.text, encoding="utf-8")
    return found


def ids(pages: list[Path]) -> list[str]:
    return [page.name for page in pages]


def test_there_are_pages() -> None:
    assert {"app-contract.md", "embedding.md", "errors.md"} <= {page.name for page in PAGES}


@pytest.mark.parametrize("page", PAGES, ids=ids(PAGES))
def test_every_block_is_of_a_kind_a_test_runs(page: Path) -> None:
    for block in blocks(page):
        where = f"{page.name}:{block.line}"
        assert block.kind in {"python", "toml", "console", "text"}, where
        if block.kind in {"python", "toml"}:
            assert block.title is not None, f'{where}: a file block needs title="name"'
        if block.kind == "console":
            assert block.text.startswith("$ "), f"{where}: a console block starts with $"


def expected_output(lines: list[str]) -> re.Pattern[str]:
    parts = []
    for line in lines:
        if line == "...":
            parts.append(r"(?:[^\n]*\n)*?")
        else:
            parts.append(".*".join(map(re.escape, line.split("..."))) + r"\n")
    return re.compile("".join(parts))


def commands(block: Block) -> list[tuple[str, list[str]]]:
    """``(command, expected lines)`` of a console block."""
    found: list[tuple[str, list[str]]] = []
    for line in block.text.splitlines():
        if line.startswith("$ "):
            found.append((line[2:], []))
        else:
            found[-1][1].append(line)
    return found


CONSOLE_PAGES: Final = [page for page in PAGES if any(b.kind == "console" for b in blocks(page))]


@pytest.mark.slow
@pytest.mark.parametrize("page", CONSOLE_PAGES, ids=ids(CONSOLE_PAGES))
def test_console_blocks_print_what_the_page_shows(page: Path, tmp_path: Path) -> None:
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
        "PYTHONIOENCODING": "utf-8",
        "COLUMNS": "100",
    }
    for block in written(page, tmp_path):
        if block.kind != "console":
            continue
        for command, lines in commands(block):
            if "--processes" in command:
                pytest.importorskip("zenoh", reason="runs across processes need the zenoh extra")
            done = subprocess.run(
                ["bash", "-c", command], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, text=True, encoding="utf-8", timeout=LIMIT,
                check=False,
            )  # fmt: skip
            assert expected_output(lines).fullmatch(done.stdout), (
                f"{page.name}:{block.line}: $ {command}\nprinted:\n{done.stdout}"
                f"\nexpected:\n" + "\n".join(lines)
            )


PYTHON_PAGES: Final = [page for page in PAGES if any(b.kind == "python" for b in blocks(page))]


@pytest.mark.slow
@pytest.mark.parametrize("page", PYTHON_PAGES, ids=ids(PYTHON_PAGES))
def test_python_blocks_type_check_strictly(page: Path, tmp_path: Path) -> None:
    pytest.importorskip("mypy", reason="mypy comes with the dev extra (CI installs it)")
    files = [
        str(tmp_path / b.title) for b in written(page, tmp_path) if b.kind == "python" and b.title
    ]
    done = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "--cache-dir", str(tmp_path / ".cache"),
         "--config-file", str(ROOT / "pyproject.toml"), *files],
        cwd=tmp_path, env={**os.environ, "MYPYPATH": str(ROOT)}, capture_output=True,
        text=True, timeout=240, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr


def test_the_contract_page_shows_the_protocol_whole(tmp_path: Path) -> None:
    from cas_async.scenario import SimulationApp

    (block,) = [b for b in blocks(DOCS / "app-contract.md") if b.title == "contract.py"]
    shown: dict[str, object] = {}
    # Annotations as texts, as in the real module (which defers them), to compare alike.
    source = "from __future__ import annotations\n" + block.text
    exec(compile(source, "contract.py", "exec", dont_inherit=True), shown)
    page_protocol = shown["SimulationApp"]
    assert isinstance(page_protocol, type)

    def members(protocol: type) -> dict[str, str]:
        found = {name: str(kind) for name, kind in protocol.__annotations__.items()}
        for name, value in vars(protocol).items():
            if callable(value) and not name.startswith("_"):
                found[name] = str(inspect.signature(value))
        return found

    real, page = members(SimulationApp), members(page_protocol)
    assert page.keys() == real.keys()
    assert page == real
