"""`tetc view` in a real browser: headless Chromium driven by selenium.

Starts `tetc view FILE --no-browser` in its own process, opens the page, waits for the first
full-quality frame, drags to rotate, shift-drags to pan, zooms with the wheel, adds an opacity point
in the transfer-function editor and changes the colormap, moves a time series' step slider and
presses play, and reads the stats the page exposes in ``window.tetcStats``. Needs Debian's ``chromium`` and ``chromium-driver`` (``make test`` installs
them) and the pip packages ``selenium`` and ``aiohttp`` (the ``test`` extra); skips, saying which is
missing, where they cannot be had.
"""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("aiohttp", reason="the viewer's server needs aiohttp (pip install 'gatun_py[view]')")
selenium = pytest.importorskip("selenium", reason="the browser test needs selenium (pip install selenium)")
from selenium import webdriver  # noqa: E402
from selenium.common.exceptions import WebDriverException  # noqa: E402
from selenium.webdriver.chrome.options import Options  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.action_chains import ActionChains  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.common.keys import Keys  # noqa: E402
from selenium.webdriver.support.ui import Select, WebDriverWait  # noqa: E402

from conftest import load_sample  # noqa: E402
from gatun_py.codec import LevelPayload, write_tetc  # noqa: E402
from gatun_py.mesh.validate import validate_tets  # noqa: E402
from gatun_py.pipeline.series import write_series  # noqa: E402
from gatun_py.simplify import build_levels, decimate  # noqa: E402

TOKEN = "browsertest0123456789"
CHROMIUM = next((p for p in (shutil.which("chromium"), shutil.which("chromium-browser"), shutil.which("google-chrome"))
                 if p), None)
DRIVER = shutil.which("chromedriver")

pytestmark = pytest.mark.skipif(
    CHROMIUM is None or DRIVER is None,
    reason="no headless Chromium here: install Debian's chromium and chromium-driver (make test does)")


def _view(path, tmp):
    """Run `tetc view path` until the test is done; yields its URL."""
    launcher = "import sys; from gatun_py.cli.main import main; sys.exit(main())"
    env = dict(os.environ, TETC_CACHE_DIR=str(tmp / "cache"))
    proc = subprocess.Popen([sys.executable, "-c", launcher, "view", str(path), "--no-browser", "-q", "--token", TOKEN],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:"), (url, proc.stderr.read() if proc.poll() is not None else "")
        yield url
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    mesh, _ = load_sample("post")
    levels = build_levels(mesh, decimate(mesh))
    tmp = tmp_path_factory.mktemp("browser")
    path = tmp / "post.tetc"
    write_tetc(path, [LevelPayload(lv.level, lv.ratio, lv.n_merges, lv.mesh, (lv.forest.parent, lv.forest.rank))
                      for lv in levels])
    for url in _view(path, tmp):
        yield url, path


@pytest.fixture(scope="module")
def series_server(tmp_path_factory):
    """The committed solver run (scikit-fem heat conduction, 40 steps) as a series with levels."""
    with np.load(Path(__file__).parent / "data" / "series_heat.npz") as z:
        run = {k: z[k] for k in z.files}
    meshes = [validate_tets(run["points"], None, run["tets"], scalar_name="temperature",
                            point_data={"temperature": run["temperature"][k]})[0] for k in range(len(run["times"]))]
    tmp = tmp_path_factory.mktemp("browser_series")
    path = tmp / "run.tetc"
    write_series(path, meshes, [float(t) for t in run["times"]], levels=2)
    for url in _view(path, tmp):
        yield url, len(meshes), [float(t) for t in run["times"]]


@pytest.fixture(scope="module")
def browser():
    opts = Options()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1100,800"):
        opts.add_argument(arg)
    try:
        driver = webdriver.Chrome(service=Service(DRIVER), options=opts)
    except WebDriverException as e:
        pytest.skip(f"headless Chromium would not start: {e.msg}")
    driver.set_script_timeout(30)
    try:
        yield driver
    finally:
        driver.quit()


def stats(driver):
    return driver.execute_script("return window.tetcStats")


def wait_for(driver, cond, timeout=60, what="the condition"):
    try:
        return WebDriverWait(driver, timeout, poll_frequency=0.05).until(lambda d: cond(d))
    except Exception:
        raise AssertionError(f"timed out waiting for {what}; last stats: {json.dumps(stats(driver))}") from None


def final_after(driver, frame_id, what):
    """Wait for a full-quality frame newer than ``frame_id``; return its stats."""
    return wait_for(driver, lambda d: (s := stats(d)) and s["final"] and s["id"] > frame_id and s, what=what)


def test_page_needs_the_token(server, browser):
    url, _ = server
    browser.get(url.replace(TOKEN, "wrong-token"))
    assert "invalid or missing token" in browser.find_element(By.TAG_NAME, "body").text
    browser.get(url.split("?")[0])
    assert "invalid or missing token" in browser.find_element(By.TAG_NAME, "body").text


def test_drag_zoom_pan_and_edit_the_transfer_function(server, browser):
    browser.get(server[0])
    first = final_after(browser, 0, "the first full-quality frame")
    assert first["level"] == 0 and first["full_quality"] and first["tets_rendered"] > 0
    for key in ("decode_s", "filter_s", "render_s", "encode_s", "transfer_s", "latency_s", "fps", "tets_rendered",
                "level", "merges", "cut"):
        assert key in first, key
    assert "tets rendered" in browser.find_element(By.ID, "stats").text

    view = browser.find_element(By.ID, "view")
    frames_before = first["frames"]
    # Drag to rotate: several moves, then release; the still frame follows after the still delay.
    chain = ActionChains(browser, duration=30).move_to_element(view).click_and_hold()
    for _ in range(8):
        chain.move_by_offset(12, 4).pause(0.05)
    chain.release().perform()
    cam = browser.execute_script("return window.tetcViewer.state.camera")
    assert cam["azimuth"] < -20 and cam["elevation"] > 5  # VTK trackball: right drag = negative azimuth
    dragged = final_after(browser, first["id"], "the still frame after the drag")
    assert dragged["frames"] > frames_before + 1  # interactive frames came before the still one
    assert dragged["camera"]["azimuth"] == cam["azimuth"]

    # Shift-drag pans, the wheel zooms.
    ActionChains(browser, duration=30).move_to_element(view).key_down(Keys.SHIFT).click_and_hold() \
        .move_by_offset(30, 0).release().key_up(Keys.SHIFT).perform()
    browser.execute_script("arguments[0].dispatchEvent(new WheelEvent('wheel', {deltaY: -300, bubbles: true, "
                           "cancelable: true}))", view)
    cam = browser.execute_script("return window.tetcViewer.state.camera")
    assert cam["pan_x"] < 0 and cam["zoom"] > 1.2
    moved = final_after(browser, dragged["id"], "the still frame after pan and zoom")
    before = browser.execute_script("return document.getElementById('view').toDataURL()")

    # The transfer-function editor: a click adds an opacity point; the frame follows it.
    n_points = len(browser.execute_script("return window.tetcViewer.transferFunction().opacity"))
    editor = browser.find_element(By.ID, "tf-editor")
    ActionChains(browser).move_to_element_with_offset(editor, 20, -40).click().perform()
    tf = browser.execute_script("return window.tetcViewer.transferFunction()")
    assert len(tf["opacity"]) == n_points + 1 and tf["absolute"]
    edited = final_after(browser, moved["id"], "the still frame after the opacity edit")
    Select(browser.find_element(By.ID, "colormap")).select_by_index(1)
    recoloured = final_after(browser, edited["id"], "the still frame after the colormap change")
    after = browser.execute_script("return document.getElementById('view').toDataURL()")
    assert after != before and recoloured["full_quality"]
    assert browser.find_element(By.ID, "error").get_attribute("hidden") is not None  # no error shown


def test_interactive_frames_respect_the_budget_setting(server, browser):
    browser.get(server[0])
    first = final_after(browser, 0, "the first frame")
    budget = browser.find_element(By.ID, "budget")
    budget.clear()
    budget.send_keys("0.05")
    view = browser.find_element(By.ID, "view")
    seen = []
    chain = ActionChains(browser, duration=20).move_to_element(view).click_and_hold()
    for _ in range(6):
        chain.move_by_offset(-10, 0).pause(0.1)
    chain.perform()
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < 1.0:
        s = stats(browser)
        if s and not s["final"] and not s["preview"]:
            seen.append(s)
        time.sleep(0.02)
    ActionChains(browser).release().perform()
    final_after(browser, first["id"], "the still frame")
    assert seen and all(s["budget_s"] == 0.05 for s in seen)


def test_a_vanished_file_shows_an_error_and_the_server_stays_up(server, browser, tmp_path):
    url, path = server
    browser.get(url)
    first = final_after(browser, 0, "the first frame")
    error = browser.find_element(By.ID, "error")
    shutil.move(path, tmp_path / "away.tetc")
    try:
        browser.execute_script("window.tetcViewer.requestFrame(); window.tetcViewer.endInteraction();")
        wait_for(browser, lambda d: error.is_displayed() and "gone" in error.text, what="the error in the page")
    finally:
        shutil.move(tmp_path / "away.tetc", path)
    browser.execute_script("window.tetcViewer.requestFrame(); window.tetcViewer.endInteraction();")
    final_after(browser, first["id"], "a frame once the file is back")
    assert not error.is_displayed()


def test_step_slider_and_play(series_server, browser):
    url, n_steps, times = series_server
    browser.get(url)
    first = final_after(browser, 0, "the first frame of the series")
    assert first["time_step"] == 0
    slider = browser.find_element(By.ID, "step")
    assert browser.find_element(By.ID, "steps").is_displayed() and slider.get_attribute("max") == str(n_steps - 1)
    # the slider moved with the keyboard: three steps on, a frame of that step, then its still frame
    slider.click()
    browser.execute_script("arguments[0].value = '0'; arguments[0].dispatchEvent(new Event('input'));", slider)
    slider.send_keys(Keys.RIGHT, Keys.RIGHT, Keys.RIGHT)
    moved = wait_for(browser, lambda d: (s := stats(d)) and s["final"] and s["time_step"] == 3 and s,
                     what="the still frame of step 3")
    assert moved["time"] == times[3]
    assert browser.find_element(By.ID, "step-label").text.startswith(f"3 / {n_steps - 1} · t = ")
    # play: frames of the following steps arrive one after another, within the budget's plan
    browser.find_element(By.ID, "play").click()
    seen = set()
    t0 = time.perf_counter()
    while len(seen) < 6 and time.perf_counter() - t0 < 60:
        s = stats(browser)
        if s and not s["final"]:
            seen.add(s["time_step"])
            assert s["budget_s"] is not None
        time.sleep(0.02)
    assert len(seen) >= 6, seen
    browser.find_element(By.ID, "play").click()  # pause: the step stays, a full-quality frame follows
    state = browser.execute_script("return window.tetcViewer.state")
    assert not state["playing"] and browser.find_element(By.ID, "play").text == "play"
    paused = wait_for(browser, lambda d: (s := stats(d)) and s["final"] and s["id"] > moved["id"] and s,
                      what="the still frame after pausing")
    assert paused["time_step"] == browser.execute_script("return window.tetcViewer.state.step")
    assert browser.find_element(By.ID, "error").get_attribute("hidden") is not None
