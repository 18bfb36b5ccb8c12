"""The explorer as a user meets it (`python -m survey explore`): on a map of 10^4 cells,
the time from the command to a page that answers (its map drawn, its document live), and
from a click on a cell to that cell's orbit drawn, beside the same orbit run by the
`orbit` command (the page's baseline: what the click would cost without the explorer)."""
from __future__ import annotations

import contextlib
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

from .common import timed_command
from .surveys import _map

FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run"]


def explorer_latency(cells: int = 10_000, t_orbit: float = 2000.0, clicks: int = 3,
                     folder="results/bench", out=print, browser=None):
    """Command -> interactive page, and click -> drawn orbit (to t_orbit; the first click
    loads the kernels, the others are warm), in headless Chromium driven by Playwright (or
    in `browser`, a Playwright browser already open)."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        chromium = None
    out("")
    out(f"The explorer on a {cells}-cell (delta, energy) map: command to an interactive page, "
        f"a click to the cell's orbit (t = {t_orbit:g}) drawn")
    if chromium is None:
        out("  skipped: needs Playwright (pip install -e '.[test]') and Chromium (Debian: "
            "apt-get install chromium)")
        return None
    from ..pipeline.config import load_config
    from ..pipeline.sweep import run_survey
    cfg = _map(cells, 5.0, folder)
    archive = Path(cfg["survey"]["output"])
    if not archive.exists():
        out(f"  making the archive {archive} (t = 5 a cell) ...")
        run_survey(cfg, progress=False)
    config = load_config(cfg, check_output=False)
    cell = config.n_cells // 2 + config.shape[1] // 2          # mid-map
    stored = Path(folder) / "explore-config.toml"
    stored.write_text(config.text)
    for _ in range(2):          # (the first loads, or compiles, the kernels)
        orbit = timed_command([sys.executable, "-m", "survey", "orbit", str(stored),
                               "--cell", str(cell), "--t-final", f"{t_orbit:g}"])
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    with contextlib.ExitStack() as stack:
        if browser is None:     # open before the command, as a user's is
            pw = stack.enter_context(sync_playwright())
            browser = pw.chromium.launch(executable_path=chromium, args=FLAGS)
            stack.callback(browser.close)
        page = browser.new_page(viewport={"width": 1400, "height": 1900})
        stack.callback(page.close)
        start = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "survey", "explore", str(archive),
                                 "--port", "0", "--no-browser"], stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, env=env)
        try:
            url = re.search(r"http://\S+/", proc.stdout.readline()).group(0)
            listening = time.perf_counter() - start
            page.goto(url)
            page.wait_for_function("(() => { const d = Bokeh.documents[0]; return d && "
                                   "d.get_model_by_name('map') != null; })()",
                                   timeout=120_000)
            page.locator("canvas").first.wait_for(timeout=120_000)
            ready = time.perf_counter() - start
            box = page.locator("canvas").first.bounding_box()
            model = "Bokeh.documents[0].get_model_by_name"
            page.evaluate(f"{model}('t_final').value = {t_orbit}")
            times = []
            for k in range(clicks):
                page.evaluate(f"{model}('notice').text = ''")
                page.mouse.click(box["x"] + box["width"] * (0.45 + 0.05 * k),
                                 box["y"] + box["height"] * 0.5)
                began = time.perf_counter()
                page.wait_for_function(
                    f"{model}('notice').text.includes('integrated to t')", timeout=300_000)
                times.append(time.perf_counter() - began)
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    out(f"  command to interactive page: {ready:6.2f} s (target 3 s warm), of which to the "
        f"server listening {listening:.2f} s")
    out(f"  click to drawn orbit:        first {times[0]:6.2f} s (loads the kernels), then "
        + ", ".join(f"{t:.2f}" for t in times[1:]) + " s (target 2 s)")
    out(f"  baseline, the same kind of orbit from the command line (`orbit --cell {cell} "
        f"--t-final {t_orbit:g}`, a process of its own, warm): {orbit.total:6.2f} s; "
        f"warm click / command = {min(times[1:] or times) / orbit.total:.2f}")
    return ready, times, orbit.total
