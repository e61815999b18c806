"""The clone's folder taken for the package (issue 30, finding 6): said, with what to do.

Python run from the folder that contains a clone named ``cas_async`` imports the
clone, a folder without ``__init__.py``, as an empty namespace package; with an
editable install the real package is only consulted after it. ``python -m
cas_async`` and the pytest plugin still run there (through the editable install)
and say what happened. Real subprocesses in a folder that holds such a clone.
"""

from __future__ import annotations

import importlib.machinery
import subprocess
import sys
import types
from pathlib import Path

import pytest

from cas_async._cli._shadow import explain, shadowed

LIMIT = 120


def python(cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *args], cwd=cwd, capture_output=True, text=True, timeout=LIMIT,
        check=False,
    )  # fmt: skip


@pytest.fixture
def above_a_clone(tmp_path: Path) -> Path:
    """A folder holding ``cas_async/``, a clone without ``__init__.py``; skips if it shadows not."""
    (tmp_path / "cas_async" / "cas_async").mkdir(parents=True)
    (tmp_path / "cas_async" / "pyproject.toml").write_text("")
    found = python(tmp_path, "-c", "import cas_async; print(cas_async.__file__)")
    if found.stdout.strip() != "None":
        pytest.skip("only an editable install is shadowed by a folder on the path")
    return tmp_path


@pytest.mark.slow
def test_python_m_cas_async_says_what_happened_and_what_to_do(above_a_clone: Path) -> None:
    done = python(above_a_clone, "-m", "cas_async", "run", "scenario.toml")
    assert done.returncode == 2
    clone = above_a_clone / "cas_async"
    assert done.stderr == f"error: {explain(clone)}\n"
    assert "Traceback" not in done.stderr


@pytest.mark.slow
def test_a_failing_test_is_told_why(above_a_clone: Path) -> None:
    (above_a_clone / "test_user.py").write_text(
        "import cas_async\n\ndef test_layer():\n    assert cas_async.Layer\n"
    )
    (above_a_clone / "test_imports.py").write_text(
        "from cas_async import Layer\n\ndef test_layer():\n    assert Layer\n"
    )
    for test in ("test_user.py", "test_imports.py"):
        done = python(above_a_clone, "-m", "pytest", "-p", "no:cacheprovider", test)
        assert done.returncode != 0
        assert f"cas_async is the folder {above_a_clone / 'cas_async'}, not the package" in (
            done.stdout
        ), done.stdout
        assert "Run pytest from inside the clone" in done.stdout


@pytest.mark.slow
def test_a_passing_session_is_left_alone(above_a_clone: Path) -> None:
    (above_a_clone / "test_plain.py").write_text("def test_nothing():\n    pass\n")
    done = python(above_a_clone, "-m", "pytest", "-p", "no:cacheprovider", "test_plain.py")
    assert done.returncode == 0, done.stdout
    assert "cas_async is the folder" not in done.stdout


def test_shadowed_names_the_folder_of_a_namespace_package(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    assert shadowed() is None  # this session's cas_async is the package
    namespace = types.ModuleType("cas_async")
    spec = importlib.machinery.ModuleSpec("cas_async", None, is_package=True)
    spec.submodule_search_locations = [str(tmp_path / "cas_async")]
    namespace.__spec__ = spec
    monkeypatch.setitem(sys.modules, "cas_async", namespace)
    assert shadowed() == tmp_path / "cas_async"
    text = explain(tmp_path / "cas_async")
    assert f"Run Python from inside the clone (cd {tmp_path / 'cas_async'})" in text
