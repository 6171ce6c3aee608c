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
MAX_CLUSTER_SCANS = 80  # scans of the extended test's cluster, at most


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


def _cluster_batches(n: int, seed: int = 4) -> list[dict[str, Any]]:
    """A convoy-like cluster: ten detections a scan spread over a 100 m x 20 m ellipse whose
    major axis is at 20° from +x (counter-clockwise), moving east-north-east at 8.5 m/s."""
    import numpy as np

    rng = np.random.default_rng(seed)
    angle = np.radians(20.0)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    batches = []
    for k in range(n):
        centre = np.array([1000.0 + 8.0 * k, 500.0 + 3.0 * k])
        pts = centre + (rng.uniform(-1.0, 1.0, (10, 2)) * [50.0, 10.0]) @ rot.T
        batches.append(
            {
                "sensor_id": "radar-1",
                "time": float(k),
                "detections": [
                    {"x": float(x), "y": float(y), "id": f"d{k}-{i}"}
                    for i, (x, y) in enumerate(pts)
                ],
                "cov": [[4.0, 0.0], [0.0, 4.0]],
                "pd": 0.9,
                "clutter_density": 1e-6,
            }
        )
    return batches


def test_the_view_draws_an_extended_track_and_its_details(service: RunningService) -> None:
    import math

    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    driver = _driver()
    try:
        driver.get(service.url + "/view")
        # scan by scan until the tracker confirms an extended track for the cluster
        served: list[dict[str, Any]] = []
        fed = 0
        with httpx.Client(base_url=service.url, timeout=10) as http:
            for batch in _cluster_batches(MAX_CLUSTER_SCANS):
                assert http.post("/api/v1/detections", json=batch).status_code == 202
                fed += 1
                wait_until(lambda n=fed: service.engine.seq == n, timeout=30, what="tracked")
                served = http.get("/api/v1/tracks", params={"kind": "extended"}).json()["tracks"]
                if served:
                    break
        assert served, f"no confirmed extended track after {fed} scans"
        track = served[0]
        assert track["kind"] == "extended" and track["status"] == "confirmed"

        def state() -> dict[str, Any]:
            return driver.execute_script("return window.viewState || {}") or {}

        wait_until(lambda: state().get("seq") == fed, timeout=30, what="the last frame")
        view = state()
        drawn = next(t for t in view["tracks"] if t["id"] == track["id"])
        assert drawn["kind"] == "extended" and drawn["rx"] > drawn["ry"] > 0
        # north up: the canvas turns the ellipse clockwise by the world's counter-clockwise angle
        assert math.isclose(drawn["rotation"], -track["extent"]["orientation"], abs_tol=1e-9)
        listed = driver.find_element(
            By.CSS_SELECTOR, f'#track-list li[data-track-id="{track["id"]}"]'
        )
        assert listed.get_attribute("data-kind") == "extended"

        # click inside the ellipse, along its major axis, away from any other track's dot:
        # computed in world coordinates, so a wrong rotation would miss the ellipse
        def to_screen(x: float, y: float) -> tuple[float, float]:
            return view["offsetX"] + x * view["scale"], view["offsetY"] - y * view["scale"]

        major, _ = track["extent"]["semi_axes"]
        angle = track["extent"]["orientation"]
        others = [t for t in view["tracks"] if t["id"] != track["id"]]
        spots = [
            to_screen(
                track["position"][0] + f * major * math.cos(angle),
                track["position"][1] + f * major * math.sin(angle),
            )
            for f in (0.6, -0.6, 0.45, -0.45, 0.75, -0.75, 0.3, -0.3)
        ]
        px, py = next(
            (
                (sx, sy)
                for sx, sy in spots
                if all(math.hypot(t["sx"] - sx, t["sy"] - sy) > 16 for t in others)
            ),
            (drawn["sx"], drawn["sy"]),
        )
        canvas = driver.find_element(By.ID, "plan")
        w, h = canvas.size["width"], canvas.size["height"]
        ActionChains(driver).move_to_element_with_offset(
            canvas, int(px - w / 2), int(py - h / 2)
        ).click().perform()
        details = driver.find_element(By.ID, "details")
        wait_until(lambda: details.is_displayed(), timeout=10, what="the details panel")
        assert details.get_attribute("data-track-id") == track["id"]
        fields = {
            dd.get_attribute("data-field"): dd.text
            for dd in details.find_elements(By.CSS_SELECTOR, "dd[data-field]")
        }
        latest = next(t for t in state_tracks(service) if t["id"] == track["id"])
        assert fields["kind"] == "extended" and fields["id"] == track["id"]
        assert fields["status"] == "confirmed"
        assert fields["position"] == "{:.1f}, {:.1f} m".format(*latest["position"])
        assert fields["semi-axes"] == "{:.1f}, {:.1f} m".format(*latest["extent"]["semi_axes"])
        assert fields["orientation"] == "{:.1f}°".format(
            math.degrees(latest["extent"]["orientation"])
        )
        assert fields["detections"] == str(len(latest["detection_ids"]))
        assert {"velocity", "score", "hits"} <= set(fields)
        ARTIFACTS.mkdir(exist_ok=True)
        assert driver.save_screenshot(str(ARTIFACTS / "view-extended.png"))
    finally:
        driver.quit()


def state_tracks(service: RunningService) -> list[dict[str, Any]]:
    """The service's latest confirmed tracks."""
    return httpx.get(service.url + "/api/v1/tracks").json()["tracks"]


def test_the_view_draws_a_formation_with_its_members(service: RunningService) -> None:
    """Paper 003's environment 1 with formations on: the view draws each formation track
    (kind ``formation``) joined to the members it names, which are drawn as individual
    tracks, and a click on the formation's centre shows its members."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    from clients.scenarios.formation import environment_1, simulate_formations

    from .helpers import batch_payload, run_batches

    sims = simulate_formations(environment_1(seed=0, scans=25))
    driver = _driver()
    try:
        with httpx.Client(base_url=service.url, timeout=10) as http:
            r = http.patch(
                "/api/v1/config", json={"formation": {"enabled": True}}, headers=service.auth
            )
            assert r.status_code == 200, r.text
            driver.get(service.url + "/view")
            results = run_batches(service.engine, [batch_payload(s) for s in sims], key=None)
            assert all(r.accepted for r in results)
            served = http.get("/api/v1/tracks", params={"kind": "formation"}).json()["tracks"]
        assert served, "no formation track after environment 1's first 25 s"

        def state() -> dict[str, Any]:
            return driver.execute_script("return window.viewState || {}") or {}

        wait_until(lambda: state().get("seq") == len(sims), timeout=30, what="the last frame")
        view = state()
        drawn = {t["id"]: t for t in view["tracks"]}
        for f in served:
            assert drawn[f["id"]]["kind"] == "formation"
            assert drawn[f["id"]]["members"] == len(f["members"]) >= 3
            assert all(drawn[m]["kind"] == "individual" for m in f["members"])
        legend = driver.find_element(By.CSS_SELECTOR, '#legend .key[data-kind="formation"]')
        assert legend.text == "formation"

        f = served[0]
        canvas = driver.find_element(By.ID, "plan")
        w, h = canvas.size["width"], canvas.size["height"]
        sx, sy = drawn[f["id"]]["sx"], drawn[f["id"]]["sy"]
        ActionChains(driver).move_to_element_with_offset(
            canvas, int(sx - w / 2), int(sy - h / 2)
        ).click().perform()
        details = driver.find_element(By.ID, "details")
        wait_until(lambda: details.is_displayed(), timeout=10, what="the details panel")
        fields = {
            dd.get_attribute("data-field"): dd.text
            for dd in details.find_elements(By.CSS_SELECTOR, "dd[data-field]")
        }
        if details.get_attribute("data-track-id") == f["id"]:
            assert fields["kind"] == "formation"
            assert fields["members"] == ", ".join(f["members"])
        else:  # the click fell on a member's dot, nearer than the centre: it names its formation
            assert fields["formation"] == f["id"]
        ARTIFACTS.mkdir(exist_ok=True)
        assert driver.save_screenshot(str(ARTIFACTS / "view-formation.png"))
    finally:
        driver.quit()
