"""The click-to-focus page in a real headless browser (Debian's Chromium through Selenium;
skipped, saying why, where either is missing): it loads with no console error, the slider
changes the plane shown, a click on a point of known disparity focuses the plane of that
depth, and the frame scrubber and the keys change frames and planes."""

import json
import os
import shutil
import tempfile
import time

import numpy as np
import pytest

from lfstream.io._fs import prepare_output_dir
from lfstream.refocus import plane_spacing
from lfstream.stream import Pipeline, StreamConfig
from lfstream.synth import synth_clip
from lfstream.viewer import write_viewer

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")


@pytest.fixture(scope="module")
def browser():
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed (pip install '.[dev]')")
    if not (CHROMIUM and CHROMEDRIVER):
        pytest.skip("no Chromium/chromedriver here (Debian: apt-get install chromium chromium-driver)")
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync", "--disable-quic",
                f"--user-data-dir={tempfile.mkdtemp(prefix='lfstream-chromium-')}", "--window-size=900,800"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    yield driver
    driver.quit()


@pytest.fixture(scope="module")
def two_depths(tmp_path_factory):
    """A stream of a scene with two depths: a background and one shape in front."""
    clip = synth_clip(3, 5, (96, 128), seed=0, layers=1, disparity_range=(-1.0, 1.5), slanted_background=False,
                      motion=0.0, camera_pan=0.0)
    out = prepare_output_dir(tmp_path_factory.mktemp("view") / "out")
    summary = Pipeline(iter(clip.lf), StreamConfig(refocus="sas", mssim_every=0), out).run()
    page = write_viewer(out, fps=summary["fps"])
    return clip, out, page


def _wait(driver, script, timeout=5.0):
    deadline = time.time() + timeout
    while time.time() < deadline:
        if driver.execute_script(script):
            return True
        time.sleep(0.05)
    return False


def _click_at(driver, x, y):
    """Clicks image pixel (x, y) of #view, mapped through the element's box."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    view = driver.find_element(By.ID, "view")
    w, h = driver.execute_script("const b = document.getElementById('view').getBoundingClientRect();"
                                 "return [b.width, b.height]")
    scale = w / 128.0
    # Selenium 4 offsets are from the element's centre
    ActionChains(driver).move_to_element_with_offset(view, int((x + 0.5) * scale - w / 2),
                                                     int((y + 0.5) * scale - h / 2)).click().perform()


def test_page_is_self_contained_and_loads_without_errors(browser, two_depths):
    _, out, page = two_depths
    html = page.read_text()
    assert "http://" not in html and "https://" not in html and "<script src" not in html  # no network
    sprites = list((out / "viewer").glob("frame_*.jpg"))
    assert len(sprites) == 3  # one sprite per frame, not a copy per plane
    browser.get(page.resolve().as_uri())
    assert _wait(browser, "return window.lfview !== undefined")
    state = browser.execute_script("return window.lfview")
    assert state["frames"] == 3 and len(state["planes"]) == len(json.loads((out / "planes.json").read_text())["planes"])
    errors = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
    assert errors == []


def test_slider_scrubber_and_keys_change_what_is_shown(browser, two_depths):
    _, _, page = two_depths
    browser.get(page.resolve().as_uri())
    pos0 = browser.execute_script("return document.getElementById('view').style.backgroundPosition")
    browser.execute_script("const s = document.getElementById('focus'); s.value = 0;"
                           "s.dispatchEvent(new Event('input'))")
    assert browser.execute_script("return window.lfview.plane") == 0
    assert browser.execute_script("return document.getElementById('view').style.backgroundPosition") != pos0
    browser.execute_script("const s = document.getElementById('frame'); s.value = 2;"
                           "s.dispatchEvent(new Event('input'))")
    assert browser.execute_script("return window.lfview.frame") == 2
    assert "frame_000002.jpg" in browser.execute_script("return document.getElementById('view').style.backgroundImage")
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    browser.find_element(By.TAG_NAME, "body").send_keys(Keys.ARROW_UP)
    assert browser.execute_script("return window.lfview.plane") == 1
    browser.find_element(By.TAG_NAME, "body").send_keys(Keys.ARROW_LEFT)
    assert browser.execute_script("return window.lfview.frame") == 1


def test_click_focuses_the_plane_at_the_clicked_depth(browser, two_depths):
    clip, out, page = two_depths
    gt = clip.disparity[0, 2, 2]
    planes = json.loads((out / "planes.json").read_text())["planes"]
    slopes = np.array([p["slope"] for p in planes])
    depths = np.unique(np.round(gt, 3))
    assert len(depths) == 2  # background and shape
    browser.get(page.resolve().as_uri())
    import cv2

    for d in depths:
        # the pixel of this depth farthest from any other depth (and from the image border)
        mask = np.pad((np.abs(gt - d) < 1e-3).astype(np.uint8), 1)
        dist = cv2.distanceTransform(mask, cv2.DIST_L2, 5)[1:-1, 1:-1]
        y, x = (int(i) for i in np.unravel_index(np.argmax(dist), dist.shape))
        assert dist[y, x] >= 6, "the region is too small to click safely"
        _click_at(browser, x, y)
        assert _wait(browser, "return window.lfview.lastClick && window.lfview.plane === window.lfview.lastClick.target")
        chosen = browser.execute_script("return window.lfview.plane")
        expected = int(np.argmin(np.abs(slopes - d)))
        # the plane of that depth: the one nearest it, whose depth of field covers it
        assert chosen == expected, (d, chosen, expected, browser.execute_script("return window.lfview.lastClick"))
        assert abs(slopes[chosen] - d) <= plane_spacing((5, 5))
    shot = os.environ.get("LFSTREAM_SCREENSHOT")
    if shot:  # the guide's picture: LFSTREAM_SCREENSHOT=docs/figures/viewer.png pytest tests/test_viewer.py
        browser.save_screenshot(shot)
