"""The page in a real browser: headless Chromium (Debian's) loads the live view and the replay.

The test reads what the page drew through ``window.casView.state()``, checks it
against ``trace.csv``, and checks the screenshot's pixels at three robots: each is
drawn in its group's colour. The screenshots are kept under the test's temporary
directory (pytest keeps the last runs' ``/tmp/pytest-of-<user>/``), named in the output.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from .cdp import Page, chromium, launch
from .helpers import FIRE, cli, finish, read_trace, results_of, url_of

pytest.importorskip("websockets")
Image = pytest.importorskip("PIL.Image")  # matplotlib's own dependency

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        chromium() is None,
        reason="no browser: install Debian's chromium (apt-get install chromium; "
        ".ci/run does, as root) to run the page in a real browser",
    ),
]

PICK = """(() => {
  const s = window.casView.state();
  const canvas = document.getElementById('world');
  const free = s.drawn.robots.filter((r) => {
    const x = s.canvas.left + r.px / s.dpr, y = s.canvas.top + r.py / s.dpr;
    if (document.elementFromPoint(x, y) !== canvas) return false;  // under the HUD
    return s.drawn.robots.every((o) => o === r ||  // no other disc within 2 radii of its centre
      Math.hypot(o.px - r.px, o.py - r.py) > 3 * s.drawn.radius);
  });
  return {state: s, free};
})()"""


@pytest.fixture
def screenshots(tmp_path: Path) -> Iterator[Path]:
    folder = tmp_path / "screenshots"
    folder.mkdir()
    yield folder
    print(f"screenshots kept in {folder}")  # shown with -rP, or on failure


def _rgb(color: str) -> tuple[int, int, int]:
    return int(color[1:3], 16), int(color[3:5], 16), int(color[5:7], 16)


async def _check_pixels(page: Page, shot: Path) -> dict[str, Any]:
    """Screenshots the page; three robots' centres must be their group's colour."""
    picked = await page.evaluate(PICK)
    state, free = picked["state"], picked["free"]
    groups = {robot["group"] for robot in free}
    chosen = [next(r for r in free if r["group"] == g) for g in sorted(groups)]
    chosen += [r for r in free if r not in chosen][: max(0, 3 - len(chosen))]
    assert len(chosen) == 3, f"three robots drawn apart from the others: {len(free)} found"
    await page.screenshot(shot)
    with Image.open(shot) as image:
        pixels = image.convert("RGB")
        dpr = state["dpr"]
        for robot in chosen:
            x = round((state["canvas"]["left"] + robot["px"] / dpr) * dpr)
            y = round((state["canvas"]["top"] + robot["py"] / dpr) * dpr)
            got = pixels.getpixel((x, y))
            want = _rgb(robot["color"])
            assert max(abs(a - b) for a, b in zip(got, want, strict=True)) <= 6, (
                f"robot {robot['id']} ({robot['group']}) at ({x}, {y}): {got}, expected {want}"
            )
    assert len({robot["color"] for robot in state["drawn"]["robots"]}) == 3  # coloured by role
    return state


def _positions_match(state: dict[str, Any], trace: Any) -> None:
    drawn = state["drawn"]
    k = trace.at(drawn["t"])
    assert [r["id"] for r in drawn["robots"]] == trace.robots
    xy = np.array([[r["x"], r["y"]] for r in drawn["robots"]])
    assert np.array_equal(xy, trace.xy[k])
    assert [r["carrying"] for r in drawn["robots"]] == trace.carrying[k].tolist()


def test_the_live_page_draws_the_run_as_it_goes(tmp_path: Path, screenshots: Path) -> None:
    out = tmp_path / "run"
    args = ("run", FIRE / "thesis_5_8_2.toml", "--virtual", "--no-plots", "--out", out)
    with cli(*args, "--live", "127.0.0.1:0", "--live-wait", "--live-pace", "15") as process:
        url = url_of(process, "live view:")

        async def look() -> dict[str, Any]:
            async with launch(tmp_path / "profile") as browser:
                page = await browser.open(url)
                running = await page.wait_for(
                    "(() => { const s = casView.state(); return s.frames > 1 && !s.ended && s; })()"
                )
                assert running["mode"] == "live"
                assert running["connected"] is True
                await page.screenshot(screenshots / "live_running.png")
                await page.wait_for("casView.state().ended !== null", limit=60)
                await asyncio.sleep(1.5)  # the last events' flashes fade
                return await _check_pixels(page, screenshots / "live_end.png")

        state = asyncio.run(look())
        code, _, stderr = finish(process)
    assert code == 0, stderr
    results = results_of(out)
    trace = read_trace(out / "trace.csv")
    _positions_match(state, trace)
    assert state["ended"]["status"] == "completed"
    assert state["frame"]["done"] <= results["delivered"]
    assert state["events"] > results["exchanges"]  # every exchange, delivery and progress


def test_the_replay_page_scrubs_to_a_time_and_plays(
    fire_run: Path, tmp_path: Path, screenshots: Path
) -> None:
    trace = read_trace(fire_run / "trace.csv")
    with cli("view", fire_run, "--port", "0") as process:
        url = url_of(process, "replay:")

        async def look() -> tuple[dict[str, Any], dict[str, Any]]:
            async with launch(tmp_path / "profile") as browser:
                page = await browser.open(url)
                await page.wait_for("casView.state().frame !== null")
                # as a person does: drag the scrubber to 12.3 s
                await page.evaluate(
                    "(() => { const s = document.getElementById('scrubber'); s.value = '12.3';"
                    " s.dispatchEvent(new Event('input')); })()"
                )
                await page.wait_for("casView.state().drawn && casView.state().drawn.t === 12")
                scrubbed = await _check_pixels(page, screenshots / "replay_12s.png")
                await page.evaluate("casView.speed(10); document.getElementById('play').click()")
                played = await page.wait_for(
                    "(() => { const s = casView.state(); return s.drawn.t >= 16 && s; })()"
                )
                await page.evaluate("document.getElementById('play').click()")
                return scrubbed, played

        scrubbed, played = asyncio.run(look())
        process.send_signal(2)
        code, _, _ = finish(process)
    assert code == 0
    assert scrubbed["mode"] == "replay"
    _positions_match(scrubbed, trace)
    assert played["playing"] is True
    _positions_match(played, trace)
