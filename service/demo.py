"""``--demo``: an in-process scenario publisher, so a newcomer sees tracks at once.

A second Zenoh session connects to the service's own listen endpoint (or its connect
endpoints in client mode) and publishes the reference scenario's batches in real time, as a
sensor would, looping with shifted times so it never goes out of sequence. Every few seconds
a one-line summary of the confirmed tracks is logged.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from typing import Any

import orjson
import zenoh

from clients.scenarios.multitarget import reference_scenario, simulate
from clients.zenoh_session import BatchPublisher, client_endpoints, open_session
from service.engine import Engine
from service.settings import Settings

__all__ = ["DemoPublisher", "summary_line"]

log = logging.getLogger("service.demo")


def summary_line(report: dict[str, Any], limit: int = 5) -> str:
    """``seq 42 t=41.0 s: 48 confirmed tracks: T3 (120, -40) 5.1 m/s, ...``"""
    tracks = report.get("tracks", [])
    parts = []
    for t in tracks[:limit]:
        (x, y), (vx, vy) = t["position"], t["velocity"]
        parts.append(f"{t['id']} ({x:.0f}, {y:.0f}) {math.hypot(vx, vy):.1f} m/s")
    more = f", +{len(tracks) - limit} more" if len(tracks) > limit else ""
    when = "-" if report.get("time") is None else f"{report['time']:.1f}"
    return f"seq {report.get('seq', 0)} t={when} s: {len(tracks)} confirmed tracks" + (
        ": " + ", ".join(parts) + more if parts else ""
    )


class DemoPublisher:
    """Publishes the reference scenario in real time until :meth:`stop`."""

    def __init__(self, settings: Settings, engine: Engine, *, seed: int = 0) -> None:
        self.settings = settings
        self.engine = engine
        self.seed = seed
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="demo-publisher", daemon=True)
        self.published = 0

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        self._thread.join(timeout)

    def _endpoints(self) -> list[str]:
        s = self.settings
        return client_endpoints(s.zenoh_listen if s.zenoh_mode != "client" else s.zenoh_connect)

    def _run(self) -> None:
        endpoints = self._endpoints()
        session: zenoh.Session | None = None
        publisher: BatchPublisher | None = None
        try:
            if endpoints:
                session = open_session("peer", endpoints)
                publisher = BatchPublisher(session, self.settings.key_prefix, wait_matching=5.0)
                log.info("demo: publishing the reference scenario to %s", endpoints)
            else:
                log.info("demo: no Zenoh endpoint to reach; feeding the engine directly")
            self._loop(publisher)
        except Exception:
            log.exception("the demo publisher failed")
        finally:
            if publisher is not None:
                publisher.close()
            if session is not None:
                session.close()

    def _loop(self, publisher: BatchPublisher | None) -> None:
        scans = simulate(reference_scenario(self.seed))
        if not scans:
            return
        first = scans[0].time
        duration = scans[-1].time - first
        dt = scans[1].time - scans[0].time if len(scans) > 1 else 1.0
        interval = self.settings.demo_summary_interval
        next_summary = time.monotonic() + interval
        loop = 0
        while not self._stop.is_set():
            last = self.engine.stats.last_time
            offset = loop * (duration + dt)
            if last is not None and first + offset <= last:
                offset = last + dt - first
            start_wall = time.monotonic()
            for scan in scans:
                due = start_wall + (scan.time - first)
                while True:
                    now = time.monotonic()
                    if now >= next_summary:
                        log.info("demo: %s", summary_line(self.engine.latest_report()))
                        next_summary = now + interval
                    wait = min(due, next_summary) - now
                    if wait <= 0 or now >= due:
                        break
                    if self._stop.wait(wait):
                        return
                batch = scan.to_batch()
                batch["time"] = scan.time + offset
                if publisher is not None:
                    publisher.put(batch)
                else:
                    self.engine.submit(orjson.dumps(batch), batch["sensor_id"], "demo")
                self.published += 1
            loop += 1
