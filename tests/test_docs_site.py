"""The documentation site builds offline, with warnings as errors, and is complete.

``mkdocs build --strict`` (as ``.ci/run`` does) with the network cut (a network
namespace of its own where ``unshare`` allows one; otherwise proxies that lead
nowhere), then the built pages are read: every page is in the navigation, the API
reference has every public name of every face, and nothing is fetched from
elsewhere when a page is opened (no remote script, stylesheet, image or font).
"""

from __future__ import annotations

import importlib
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Final

import pytest

pytest.importorskip("mkdocs", reason="the docs extra builds the site (the dev extra has it)")
pytest.importorskip("material", reason="the docs extra builds the site (the dev extra has it)")
pytest.importorskip("mkdocstrings_handlers.python", reason="the docs extra builds the site")
yaml = pytest.importorskip("yaml")

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

ROOT: Final = Path(__file__).resolve().parents[1]
DOCS: Final = ROOT / "docs"
FACES: Final = {
    "cas_async": "api/cas_async",
    "cas_async.scenario": "api/scenario",
    "cas_async.scenario.output": "api/scenario-output",
    "cas_async.scenario.sweeps": "api/scenario-sweeps",
    "cas_async.sim": "api/sim",
    "cas_async.transport": "api/transport",
    "cas_async.transport.zenoh": "api/transport-zenoh",
    "cas_async.testing": "api/testing",
    "cas_async.live": "api/live",
    "cas_async.ros": "api/ros",
    "cas_async.rl": "api/rl",
}
NOWHERE: Final = "http://127.0.0.1:9"  # the discard port: nothing listens there
REMOTE: Final = re.compile(
    r"""<(?:script|img|iframe|source)\b[^>]*\bsrc=["']?(?:https?:)?//"""
    r"""|<link\b[^>]*\bhref=["']?(?:https?:)?//"""
    r"""|url\(\s*["']?(?:https?:)?//|@import\s+["']?(?:https?:)?//""",
    re.I,
)


def _offline() -> list[str]:
    """A command prefix that cuts the network, where this machine allows it."""
    unshare = shutil.which("unshare")
    if unshare is None:
        return []
    tried = subprocess.run([unshare, "-rn", "true"], capture_output=True, check=False)
    return [unshare, "-rn"] if tried.returncode == 0 else []


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("site")
    proxies = {name: NOWHERE for name in ("http_proxy", "https_proxy", "all_proxy")}
    env = {
        **os.environ,
        **proxies,
        **{name.upper(): value for name, value in proxies.items()},
        "NO_MKDOCS_2_WARNING": "1",
    }
    env.pop("no_proxy", None)
    env.pop("NO_PROXY", None)
    done = subprocess.run(
        [*_offline(), sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
         str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=540, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert "WARNING" not in done.stderr, done.stderr
    return out


def _nav_pages(nav: object) -> set[str]:
    if isinstance(nav, str):
        return {nav}
    if isinstance(nav, list):
        return set().union(*(_nav_pages(item) for item in nav))
    if isinstance(nav, dict):
        return set().union(*(_nav_pages(item) for item in nav.values()))
    return set()


def test_every_page_is_in_the_navigation() -> None:
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    pages = {page.relative_to(DOCS).as_posix() for page in DOCS.rglob("*.md")}
    assert _nav_pages(config["nav"]) == pages


def test_every_face_has_a_reference_page() -> None:
    for face, page in FACES.items():
        assert (DOCS / f"{page}.md").read_text(encoding="utf-8").count(f"::: {face}\n") == 1


def test_the_site_is_built_with_every_page(site: Path) -> None:
    for page in DOCS.rglob("*.md"):
        name = page.relative_to(DOCS).with_suffix("")
        built = site / "index.html" if name.name == "index" else site / name / "index.html"
        assert built.is_file(), f"{page} was not built"


@pytest.mark.parametrize("face", FACES)
def test_the_reference_has_every_public_name(site: Path, face: str) -> None:
    try:
        module = importlib.import_module(face)
    except ImportError as exc:  # an extra's face: the names are read from its source
        pytest.skip(f"{face} needs its extra to be imported: {exc}")
    html = (site / FACES[face] / "index.html").read_text(encoding="utf-8")
    anchors = set(re.findall(r'\bid="([^"]+)"', html))
    missing = [name for name in module.__all__ if f"{face}.{name}" not in anchors]
    assert missing == [], f"{face}: not in the API reference: {missing}"
    assert not re.search(r":(?:class|meth|func|mod|attr|exc):<code>", html), "a Sphinx role"


def test_no_page_fetches_anything_from_elsewhere(site: Path) -> None:
    fetching = [
        f"{path.relative_to(site)}: {match.group(0)}"
        for path in [*site.rglob("*.html"), *site.rglob("*.css")]
        for match in REMOTE.finditer(path.read_text(encoding="utf-8", errors="replace"))
    ]
    assert fetching == []
