"""The live view in a real headless Chromium (Debian's ``chromium`` and ``chromium-driver``,
which ``.ci/run`` installs): it draws the service's confirmed tracks, the same ids as
``GET /api/v1/tracks``, and a click on a track shows its details. Saves a screenshot to
``test-artifacts/view.png``."""

from __future__ import annotations

import itertools
import shutil
from pathlib import Path
from typing import Any

import httpx
import orjson
import pytest

from clients.scenarios.continuous import ContinuousScenario
from tests.conftest import RunningService, open_peer

from .helpers import declare_publisher, wait_until

pytestmark = pytest.mark.timeout(180)

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "test-artifacts"
SCANS = 25
MIN_TRACKS = 20


def _driver() -> Any:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    chromedriver = shutil.which("chromedriver")
    if chromium is None or chromedriver is None:
        pytest.skip(
            "no headless Chromium here: .ci/run installs Debian's chromium and "
            "chromium-driver with apt-get when it runs as root"
        )
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium (the test extra)")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1280,900"):
        options.add_argument(arg)
    options.add_argument("--disable-dev-shm-usage")
    return webdriver.Chrome(service=Service(chromedriver), options=options)


def test_the_view_draws_the_services_tracks_and_details(service: RunningService) -> None:
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    driver = _driver()
    session = open_peer(service.endpoint)
    try:
        driver.get(service.url + "/view")
        pub = declare_publisher(session, "tracking/detections/radar-1")
        for scan in itertools.islice(ContinuousScenario(seed=2).scans(), SCANS):
            pub.put(orjson.dumps(scan.to_batch()))
        wait_until(lambda: service.engine.seq == SCANS, timeout=30, what="every scan tracked")

        def state() -> dict[str, Any]:
            return driver.execute_script("return window.viewState || {}") or {}

        wait_until(lambda: state().get("seq") == SCANS, timeout=30, what="the view's last frame")
        confirmed = [t for t in state()["tracks"] if t["status"] == "confirmed"]
        assert len(confirmed) >= MIN_TRACKS, confirmed
        served = httpx.get(service.url + "/api/v1/tracks").json()["tracks"]
        assert sorted(t["id"] for t in confirmed) == sorted(t["id"] for t in served)
        listed = driver.find_elements(By.CSS_SELECTOR, "#track-list li[data-status=confirmed]")
        assert sorted(li.get_attribute("data-track-id") for li in listed) == sorted(
            t["id"] for t in served
        )

        # click the confirmed track nearest the canvas's middle; its details appear
        canvas = driver.find_element(By.ID, "plan")
        w, h = canvas.size["width"], canvas.size["height"]
        target = min(confirmed, key=lambda t: (t["sx"] - w / 2) ** 2 + (t["sy"] - h / 2) ** 2)
        ActionChains(driver).move_to_element_with_offset(
            canvas, int(target["sx"] - w / 2), int(target["sy"] - h / 2)
        ).click().perform()
        details = driver.find_element(By.ID, "details")
        wait_until(lambda: details.is_displayed(), timeout=10, what="the details panel")
        shown = details.get_attribute("data-track-id")
        track = next((t for t in served if t["id"] == shown), None)
        assert track is not None, (shown, target)
        fields = {
            dd.get_attribute("data-field"): dd.text
            for dd in details.find_elements(By.CSS_SELECTOR, "dd[data-field]")
        }
        assert fields["status"] == "confirmed"
        assert fields["position"] == "{:.1f}, {:.1f} m".format(*track["position"])
        ARTIFACTS.mkdir(exist_ok=True)
        assert driver.save_screenshot(str(ARTIFACTS / "view.png"))
    finally:
        driver.quit()
        session.close()
