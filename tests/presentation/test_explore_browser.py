"""The explorer's page in a real browser: headless Chromium (Debian's package, which
.ci/run installs) driven by Playwright. The page loads with no console error; the cell a
pointer names is the cell a click integrates, and its orbit is what `survey orbit --cell K`
prints; the exported config starts at that cell's archived start; the layers recolour the
map; a one-shell archive's section turns; a page's address opens a cell, and a cell that
cannot be integrated says so while the page goes on. Screenshots are written to
$SURVEY_SCREENSHOTS (if set) to be looked at."""
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from survey.cli import main
from survey.pipeline.cells import build_starts
from survey.pipeline.config import parse_config
from survey import explore
from survey.bench.explorer import FLAGS

playwright = pytest.importorskip("playwright.sync_api", reason="Playwright is not installed "
                                 "(pip install -e '.[test]')")
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
if CHROMIUM is None:
    pytest.skip("no Chromium on this machine (Debian: apt-get install chromium; .ci/run "
                "installs it)", allow_module_level=True)

RESULTS = Path(__file__).resolve().parents[2] / "results"


class Server:
    def __init__(self, path):
        self.running = explore.serve_in_thread(path, port=0)

    def close(self):
        self.running.stop()


@pytest.fixture(scope="module")
def browser():
    with playwright.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        yield b
        b.close()


@pytest.fixture(scope="module")
def map_server():
    server = Server(RESULTS / "delta_energy_map_areal.nc")
    yield server
    server.close()


class Page:
    """A browser tab on a server, its console errors collected."""

    def __init__(self, browser, url):
        self.page = browser.new_page(viewport={"width": 1400, "height": 1900})
        self.errors = []
        self.page.on("console", lambda m: self.errors.append(m.text) if m.type == "error"
                     else None)
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.goto(url)
        self.page.locator("canvas").first.wait_for(timeout=60_000)

    def model(self, name, expression):
        """`expression` of the Bokeh model named `name`, evaluated in the page (m: it)."""
        return self.page.evaluate(f"(() => {{ const m = Bokeh.documents[0]"
                                  f".get_model_by_name('{name}'); return {expression}; }})()")

    def until(self, name, condition, timeout=30_000):
        self.page.wait_for_function(f"(() => {{ const m = Bokeh.documents[0]"
                                    f".get_model_by_name('{name}'); return {condition}; }})()",
                                    timeout=timeout)

    def status(self, pattern, timeout=120_000) -> str:
        self.page.get_by_text(re.compile(pattern)).first.wait_for(timeout=timeout)
        return self.page.get_by_text(re.compile(pattern)).first.inner_text()

    def shot(self, name):
        folder = os.environ.get("SURVEY_SCREENSHOTS")
        if folder:
            Path(folder).mkdir(parents=True, exist_ok=True)
            self.page.screenshot(path=str(Path(folder) / f"{name}.png"), full_page=True)


def _printed(text):
    return [re.sub(r", [0-9.]+ s$", "", line) for line in text.splitlines() if line.strip()]


def test_a_click_integrates_the_cell_the_pointer_names(browser, map_server, tmp_path, capsys):
    page = Page(browser, map_server.running.url)
    box = page.page.locator("canvas").first.bounding_box()
    at = (box["x"] + box["width"] * 0.3, box["y"] + box["height"] * 0.4)
    page.page.mouse.move(*at)
    tip = page.page.get_by_text(re.compile(r"cell:\s*\d+")).first
    tip.wait_for(timeout=30_000)
    cell = int(re.search(r"cell:\s*(\d+)", tip.inner_text()).group(1))
    page.page.mouse.click(*at)
    page.status(rf"cell {cell} \(.*\): integrated to t")
    shown = page.page.locator("pre").first.inner_text()
    view = explore.CellView.open(RESULTS / "delta_energy_map_areal.nc")
    config = tmp_path / "stored.toml"
    config.write_text(view.ds.attrs["config"])
    assert main(["orbit", str(config), "--cell", str(cell)]) == 0
    printed = _printed(capsys.readouterr().out)
    assert _printed(shown)[:len(printed)] == printed      # then the archive's frequencies
    exported = page.page.locator("textarea").first.input_value()
    start = build_starts(parse_config(exported, "export", check_output=False), [0])[0]
    assert np.array_equal(start, view.flat_state(cell))
    page.shot("explore_map_orbit")
    assert page.errors == []


def test_the_layers_recolour_the_map(browser, map_server):
    """Colour by MEGNO: the pixel under the pointer is the colour MEGNO's colour map gives
    the cell the pointer names (its range the registry's), the regimes' bar gone."""
    import io

    from matplotlib.colors import to_rgb
    from matplotlib.image import imread
    page = Page(browser, map_server.running.url)
    page.page.locator("select").first.select_option("megno")
    page.until("map", "m.title.text === 'megno'")
    assert page.model("colours", "[m.low, m.high]") == [0, 8]
    canvas = page.page.locator("canvas").first
    box = canvas.bounding_box()
    for fx, fy in ((0.3, 0.4), (0.1, 0.9)):
        at = (box["x"] + box["width"] * fx, box["y"] + box["height"] * fy)
        page.page.mouse.move(*at)
        tip = page.page.get_by_text(re.compile(r"cell:\s*\d+")).first
        tip.wait_for(timeout=30_000)
        cell = int(re.search(r"cell:\s*(\d+)", tip.inner_text()).group(1))
        page.page.mouse.move(box["x"] + 2, box["y"] + 2)      # the tooltip out of the way
        page.page.wait_for_timeout(300)
        pixels = imread(io.BytesIO(canvas.screenshot()))
        got = pixels[int(at[1] - box["y"]), int(at[0] - box["x"]), :3]
        layer = explore.CellView.open(RESULTS / "delta_energy_map_areal.nc").layers()["megno"]
        v = layer.values[cell]
        want = "#bbbbbb" if not np.isfinite(v) else layer.palette[
            int(np.clip((v - layer.low) / (layer.high - layer.low) * 256, 0, 255))]
        assert np.allclose(got, to_rgb(want), atol=0.02), (cell, v, got, want)
    page.shot("explore_map_megno")
    assert page.errors == []


def test_an_address_opens_a_cell_and_a_bad_one_is_said(browser, map_server):
    page = Page(browser, map_server.running.url + "?layer=ftle&cell=61&t=50")
    text = page.status(r"cell 61 \(delta = 1.25, energy = 10\): integrated to t = 50")
    assert "integrated to t = 50" in text
    page = Page(browser, map_server.running.url + "?cell=100000")
    page.status(r"cell 100000 could not be integrated.*not a cell of the grid")
    # the server goes on: another tab still integrates
    page = Page(browser, map_server.running.url + "?cell=3&t=20")
    page.status(r"cell 3 \(.*\): integrated to t = 20")
    assert page.errors == []


def test_a_one_shell_section_turns_in_3d(browser):
    server = Server(RESULTS / "section_map.nc")
    try:
        page = Page(browser, server.running.url)
        x = "m.renderers[0].data_source.data.x"
        u = "m.renderers[0].data_source.data.u"
        assert page.model("slice3d", f"Array.from({x}).every((v, i) => v === {u}[i])")
        handle = page.page.locator(".noUi-handle").first
        handle.focus()
        page.page.keyboard.press("End")
        page.until("azimuth", "m.value === 180")
        # turned half a turn about the vertical: the screen's x is -sigma (scaled)
        page.until("slice3d", f"Array.from({x}).every((v, i) => Math.abs(v + {u}[i]) < 1e-12)")
        page.shot("explore_section_turned")
        assert page.errors == []
    finally:
        server.close()


def test_the_bench_times_the_explorer_as_a_user_meets_it(browser, tmp_path):
    """`bench --only explore` in miniature: a small map made, the command started, the page
    timed to interactive and two clicks to their drawn orbits."""
    from survey import bench
    lines = []
    ready, clicks, command = bench.explorer_latency(cells=12, t_orbit=5.0, clicks=2,
                                                    folder=str(tmp_path), out=lines.append,
                                                    browser=browser)
    assert ready > 0 and len(clicks) == 2 and min(clicks) > 0 and command > 0
    text = "\n".join(lines)
    assert "command to interactive page" in text and "click to drawn orbit" in text
    assert "warm click / command" in text


def test_a_family_members_orbit_is_drawn_on_a_click(browser, families):
    server = Server(families["periodic"])
    try:
        page = Page(browser, server.running.url)
        box = page.page.locator("canvas").first.bounding_box()
        page.page.mouse.click(box["x"] + box["width"] * 0.5, box["y"] + box["height"] * 0.5)
        page.until("notice", "m.text.includes('integrated')", timeout=120_000)
        text = page.model("orbit-text", "m.text")
        assert "non-trivial Floquet multipliers" in text and "returns to its start" in text
        error = float(re.search(r"within ([0-9.e+-]+) of its size", text).group(1))
        assert error < 1e-9
        page.shot("explore_family")
        assert page.errors == []
    finally:
        server.close()


def test_a_scan_is_a_line_of_cells_named_by_regime(browser):
    server = Server(RESULTS / "default.nc")
    try:
        page = Page(browser, server.running.url + "?layer=ftle")
        label = ("(o => o instanceof Map ? o.get(4) : o[4])"
                 "(m.left[0].major_label_overrides)")
        page.until("map", "m.title.text === 'log10 ftle'")
        assert page.model("map", label) is None
        page.page.locator("select").first.select_option("regime")
        page.until("map", f"{label} === 'chaotic'")
        page.shot("explore_scan")
        assert page.errors == []
    finally:
        server.close()
