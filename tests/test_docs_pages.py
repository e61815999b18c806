"""The pages under docs/ as a reader meets them: every code block runs or type-checks.

A page's fenced blocks (in a list item too) are of four kinds:

* ``python title="name.py"`` and ``toml title="name.toml"``: files, written under
  their titles into a fresh folder (one per page, where ``apps``, ``examples`` and
  ``benchmarks`` of this repository are at hand); every Python file of a page is
  type-checked with ``mypy --strict``; a TOML file that no command of its page
  names must load as a scenario;
* ``python title="path/in/the/repository.py"`` (a title with a ``/``): an excerpt of
  that file of this repository, found in it verbatim (its lines in order; a line
  ``...`` leaves lines out), so the file's own checks cover it;
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
import textwrap
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import pytest

ROOT: Final = Path(__file__).resolve().parents[1]
DOCS: Final = ROOT / "docs"
PAGES: Final = sorted(DOCS.rglob("*.md"))
FENCE: Final = re.compile(r"^([ \t]*)```(\w*)([^\n]*)\n(.*?)^\1```[ \t]*$", re.S | re.M)
TITLE: Final = re.compile(r'title="([^"]+)"')
LINKED: Final = ("apps", "examples", "benchmarks")
LIMIT: Final = 120
NEEDS: Final = {
    "live.md": ("websockets",),
    "rl.md": ("pettingzoo", "gymnasium"),
    "ros.md": ("zenoh", "rosbags"),
}
"""What a page's code imports beyond the core: its checks skip where it is missing."""


@dataclass(frozen=True)
class Block:
    kind: str
    title: str | None
    text: str
    line: int

    @property
    def excerpt(self) -> bool:
        """Whether the block is an excerpt of a file of this repository (not a page's file)."""
        return self.title is not None and "/" in self.title


def blocks(page: Path) -> list[Block]:
    text = page.read_text(encoding="utf-8")
    found = []
    for match in FENCE.finditer(text):
        indent, kind, options, body = match.groups()
        title = TITLE.search(options)
        line = text.count("\n", 0, match.start()) + 1
        body = textwrap.dedent(body) if indent else body
        found.append(Block(kind, title and title.group(1), body, line))
    return found


def page_name(page: Path) -> str:
    return page.relative_to(DOCS).as_posix()


def needs(page: Path) -> None:
    for module in NEEDS.get(page_name(page), ()):
        pytest.importorskip(module, reason=f"{page_name(page)} needs {module} (in the dev extra)")


def written(page: Path, folder: Path) -> list[Block]:
    """The page's files, written into ``folder`` (with the repository's apps and examples)."""
    for linked in LINKED:
        (folder / linked).symlink_to(ROOT / linked)
    found = blocks(page)
    for block in found:
        if block.title is not None and not block.excerpt:
            (folder / block.title).write_text(block.text, encoding="utf-8")
    return found


def ids(pages: list[Path]) -> list[str]:
    return [page_name(page) for page in pages]


def test_there_are_pages() -> None:
    assert {"app-contract.md", "embedding.md", "errors.md", "tutorial.md"} <= set(ids(PAGES))


@pytest.mark.parametrize("page", PAGES, ids=ids(PAGES))
def test_every_block_is_of_a_kind_a_test_runs(page: Path) -> None:
    for block in blocks(page):
        where = f"{page_name(page)}:{block.line}"
        assert block.kind in {"python", "toml", "console", "text"}, where
        if block.kind in {"python", "toml"}:
            assert block.title is not None, f'{where}: a file block needs title="name"'
        if block.kind == "console":
            assert block.text.startswith("$ "), f"{where}: a console block starts with $"


def excerpt_of(block: str, text: str) -> bool:
    """Whether ``block`` is in ``text``: its parts between ``...`` lines, in order."""
    at = 0
    for part in re.split(r"^[ \t]*\.\.\.[ \t]*$", block, flags=re.M):
        found = text.find(part.strip(), at)
        if found < 0:
            return False
        at = found + len(part.strip())
    return True


EXCERPTS: Final = [(page, b) for page in PAGES for b in blocks(page) if b.excerpt]


@pytest.mark.parametrize(
    ("page", "block"), EXCERPTS, ids=[f"{page_name(p)}:{b.line}" for p, b in EXCERPTS]
)
def test_an_excerpt_is_the_file_s_own_code(page: Path, block: Block) -> None:
    assert block.title is not None
    source = ROOT / block.title
    assert source.is_file(), f"{page_name(page)}:{block.line}: no file {block.title}"
    assert excerpt_of(block.text, source.read_text(encoding="utf-8")), (
        f"{page_name(page)}:{block.line}: not found verbatim in {block.title}"
    )


def expected_output(lines: list[str]) -> re.Pattern[str]:
    """What a console block's output lines match: ``...`` lines and texts, and column gaps.

    A run of two or more spaces (a gap between columns) matches any run of spaces:
    the words and their order are checked, not the widths, which a real-time run
    changes (a makespan of 103 s on a loaded machine is one character wider than
    one of 21.9 s, and shifts the column after it). The summary's layout itself is
    checked with fixed values (``tests/scenario_output/test_report.py``).
    """
    parts = []
    for line in lines:
        if line == "...":
            parts.append(r"(?:[^\n]*\n)*?")
        else:
            parts.append(".*".join(map(_literal, line.split("..."))) + r"\n")
    return re.compile("".join(parts))


def _literal(text: str) -> str:
    """``text`` as a pattern, each gap of two or more spaces as one or more spaces."""
    return " +".join(re.escape(piece) for piece in re.split(r" {2,}", text))


@pytest.mark.parametrize(
    ("shown", "printed", "matches"),
    [
        pytest.param(
            "makespan              ... s simulated    (wall ... s)",
            "makespan              21.9 s simulated    (wall 5.2 s)",
            True,
            id="as-shown",
        ),
        pytest.param(
            "makespan              ... s simulated    (wall ... s)",
            "makespan              103.2 s simulated   (wall 5.2 s)",
            True,
            id="a-wider-value-on-a-loaded-machine",
        ),
        pytest.param(
            "buckets delivered     20 of 20            (created 25, exchanges ...)",
            "buckets delivered     20 of 20 (created 25, exchanges 97)",
            True,
            id="any-gap",
        ),
        pytest.param(
            "makespan              ... s simulated    (wall ... s)",
            "makespan              103.2 s simulated(wall 5.2 s)",
            False,
            id="a-gap-is-not-nothing",
        ),
        pytest.param(
            "buckets delivered     20 of 20",
            "buckets delivered     19 of 20",
            False,
            id="the-words-count",
        ),
        pytest.param("exit 2", "exit  2", False, id="one-space-is-one-space"),
    ],
)
def test_expected_output_holds_the_words_not_the_column_widths(
    shown: str, printed: str, matches: bool
) -> None:
    assert bool(expected_output([shown]).fullmatch(printed + "\n")) is matches


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
@pytest.mark.timeout(5 * LIMIT)  # a page may run several commands, each within LIMIT
@pytest.mark.parametrize("page", CONSOLE_PAGES, ids=ids(CONSOLE_PAGES))
def test_console_blocks_print_what_the_page_shows(page: Path, tmp_path: Path) -> None:
    needs(page)
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
                f"{page_name(page)}:{block.line}: $ {command}\nprinted:\n{done.stdout}"
                f"\nexpected:\n" + "\n".join(lines)
            )


PYTHON_PAGES: Final = [
    page for page in PAGES if any(b.kind == "python" and not b.excerpt for b in blocks(page))
]


@pytest.mark.slow
@pytest.mark.parametrize("page", PYTHON_PAGES, ids=ids(PYTHON_PAGES))
def test_python_blocks_type_check_strictly(
    page: Path, tmp_path: Path, tmp_path_factory: pytest.TempPathFactory
) -> None:
    pytest.importorskip("mypy", reason="mypy comes with the dev extra (CI installs it)")
    needs(page)
    cache = tmp_path_factory.getbasetemp() / "mypy-cache"  # cas_async analysed once a session
    files = [
        str(tmp_path / b.title)
        for b in written(page, tmp_path)
        if b.kind == "python" and b.title and not b.excerpt
    ]
    done = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "--cache-dir", str(cache),
         "--config-file", str(ROOT / "pyproject.toml"), *files],
        cwd=tmp_path, env={**os.environ, "MYPYPATH": str(ROOT)}, capture_output=True,
        text=True, timeout=240, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr


TOML_PAGES: Final = [page for page in PAGES if any(b.kind == "toml" for b in blocks(page))]


@pytest.mark.parametrize("page", TOML_PAGES, ids=ids(TOML_PAGES))
def test_toml_files_parse_and_load_unless_a_command_runs_them(
    page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from cas_async.scenario import load_scenario

    found = written(page, tmp_path)
    said = "\n".join(b.text for b in found if b.kind == "console")
    monkeypatch.chdir(tmp_path)  # a scenario's app is imported as the CLI would, from here
    monkeypatch.syspath_prepend(str(tmp_path))
    for block in found:
        if block.kind != "toml" or block.excerpt or block.title is None:
            continue
        tomllib.loads(block.text)
        if block.title not in said:
            load_scenario(tmp_path / block.title)


RUNNABLE: Final = re.compile(r"python -m ([\w.]+)")
EXTRAS: Final = re.compile(r"""pip install (?:-e )?["']?(?:\.|cas_async)\[([\w,-]+)\]""")


@pytest.mark.parametrize("page", [*PAGES, ROOT / "README.md"], ids=[*ids(PAGES), "README.md"])
def test_the_modules_and_extras_a_page_names_exist(page: Path) -> None:
    """What a page names in prose and ``text`` blocks (which no test runs) is there."""
    text = page.read_text(encoding="utf-8")
    ours = {path.name for path in ROOT.iterdir() if path.is_dir()}
    for module in set(RUNNABLE.findall(text)):
        if module.split(".")[0] not in ours:
            continue  # pytest, mypy, cProfile: not this repository's
        path = ROOT.joinpath(*module.split("."))
        assert path.with_suffix(".py").is_file() or (path / "__main__.py").is_file(), (
            f"{page.name}: python -m {module}: no such module to run"
        )
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    for extras in EXTRAS.findall(text):
        unknown = set(extras.split(",")) - declared["optional-dependencies"].keys()
        assert not unknown, f"{page.name}: no extra {sorted(unknown)} in pyproject.toml"


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
