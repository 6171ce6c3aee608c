"""Builds the app and runs it: :func:`create_app` (FastAPI, with a lifespan that starts the
engine and opens Zenoh, and closes both) and :func:`main`, the ``tracker-service`` entry.

SIGINT and SIGTERM stop the service cleanly: uvicorn stops serving, the lifespan closes the
Zenoh session and stops the engine, and the process exits with status 0.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import re
import secrets
import signal
import subprocess
import sys
import threading
import time
from collections.abc import AsyncIterator, Sequence
from pathlib import Path
from typing import Any

import uvicorn
import zenoh
from fastapi import FastAPI
from fastapi.openapi.docs import (
    get_redoc_html,
    get_swagger_ui_html,
    get_swagger_ui_oauth2_redirect_html,
)
from fastapi.openapi.utils import get_openapi
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

from service import __version__
from service.api import api_router
from service.api.methods import AllowedMethods
from service.api.view import VIEW_DIR
from service.api.view import router as view_router
from service.config_store import config_changes, load_config_file
from service.config_tree import ConfigDocument, ConfigError, ConfigPatch, config_document
from service.engine import Engine
from service.files import remove_stale_temporaries
from service.id_reserve import IdReservation, id_file
from service.keys import Keys, local_endpoints
from service.scale_out import ScaleOut, Sector
from service.schemas import DetectionBatchIn, IngestConfig
from service.settings import Settings, SettingsLoadError, api_token_source, load_settings
from service.state_store import StateStore
from service.stats import Stats
from service.zenoh_io import ZenohIO
from trackers.config import TrackerConfig
from trackers.pipeline import TrackingPipeline

__all__ = ["create_app", "main"]

log = logging.getLogger("service")

#: Seconds between the interpreter's thread switches: short, so REST answers promptly while
#: the tracker's worker thread is busy (the default is 5 ms).
SWITCH_INTERVAL = 0.001

#: A client that finds no Zenoh router tries again after this many seconds, doubling up to
#: ``CONNECT_RETRY_MAX``, and logs a warning at most every ``CONNECT_LOG_INTERVAL`` seconds.
CONNECT_RETRY_MIN = 0.5
CONNECT_RETRY_MAX = 5.0
CONNECT_LOG_INTERVAL = 30.0
#: Seconds between two looks at whether a session that must reach others still does.
WATCH_INTERVAL = 2.0


def _resolve_token(settings: Settings, source: str | None = None) -> str:
    """The bearer token for writes; says on stderr where it came from (a set one is not
    shown; a generated one is, once)."""
    if settings.api_token is not None:
        print(
            f"tracker-service: the token for writes comes from {source or 'the settings'} "
            "(not shown)",
            file=sys.stderr,
            flush=True,
        )
        return settings.api_token.get_secret_value()
    token = secrets.token_urlsafe(24)
    print(
        "tracker-service: no TRACKER_API_TOKEN, TRACKER_API_TOKEN_FILE or --api-token set: "
        "generated for this run "
        f"(export TRACKER_API_TOKEN=... before starting to choose your own); "
        f"the API token for writes is: {token}",
        file=sys.stderr,
        flush=True,
    )
    return token


def _reason(exc: zenoh.ZError) -> str:
    """Zenoh's message without the Rust source location it ends with."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?\s*$", "", str(exc)).strip()


class ZenohStartError(RuntimeError):
    """The Zenoh session could not be opened (the message says why)."""


def demo_command(settings: Settings) -> list[str] | None:
    """The command line of the demo client (``python -m clients.demo``) for this service:
    connected to its listen endpoints (its connect endpoints in client mode, or when it
    listens on none). ``None`` when it has no Zenoh endpoint to reach."""
    s = settings
    listen = s.zenoh_listen if s.zenoh_mode != "client" else []
    endpoints = local_endpoints(listen or s.zenoh_connect)
    if not endpoints:
        return None
    command = [sys.executable, "-m", "clients.demo", "--exit-with-parent"]
    for endpoint in endpoints:
        command += ["--connect", endpoint]
    command += [
        "--prefix",
        s.key_prefix,
        "--summary-interval",
        repr(s.demo_summary_interval),
        "--log-level",
        s.log_level,
    ]
    if s.demo_scenario != "continuous":
        command += ["--scenario", s.demo_scenario]
    if s.demo_speed != 1.0:
        command += ["--speed", repr(s.demo_speed)]
    return command


def _stop_process(proc: subprocess.Popen[bytes], timeout: float = 2.0) -> None:
    """SIGTERM, then SIGKILL after ``timeout`` seconds."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            log.warning("the demo client did not stop within %.1f s; killing it", timeout)
            proc.kill()
            proc.wait(5)


class ServiceRuntime:
    """What runs besides the web server: the engine's worker, the Zenoh session and the demo
    client. :meth:`start` and :meth:`stop` are idempotent, so the entry point can start
    it before uvicorn (to fail early and cleanly) and the lifespan still stops it."""

    def __init__(self, settings: Settings, engine: Engine, token: str = "") -> None:
        self.settings = settings
        self.engine = engine
        self.zenoh: ZenohIO | None = None
        #: scale-out (setting scale_out): federated queries, hand-over, shared configuration
        self.scale_out: ScaleOut | None = None
        if settings.scale_out:
            self.scale_out = ScaleOut(
                engine=engine,
                keys=Keys(settings.key_prefix),
                instance_id=settings.instance_id,
                token=token,
                sector=Sector(*settings.sector) if settings.sector else None,
                sector_margin=settings.sector_margin,
                federate_timeout=settings.federate_timeout,
            )
            if settings.sector:
                engine.on_report = self.scale_out.after_report
        self.demo: subprocess.Popen[bytes] | None = None
        #: while a client waits for its router: the last attempt and why it failed
        self.connecting: str | None = None
        self._lock = threading.Lock()
        self._started = False
        self._stopping = threading.Event()
        self._connector: threading.Thread | None = None
        self._watcher: threading.Thread | None = None

    def start(self) -> None:
        """Start the worker and open Zenoh. A listen endpoint that cannot be opened raises
        :class:`ZenohStartError`; a client that finds no router keeps trying in the
        background (``/ready`` says so) and goes on when one answers."""
        with self._lock:
            if self._started:
                return
            s = self.settings
            sys.setswitchinterval(SWITCH_INTERVAL)
            zio = ZenohIO(
                mode=s.zenoh_mode,
                listen=s.zenoh_listen,
                connect=s.zenoh_connect,
                key_prefix=s.key_prefix,
                instance_id=s.instance_id,
                submit=self.engine.submit,
                report_bytes=self.engine.latest_report_bytes,
                filtered=self.engine.tracks,
                congestion_control=s.tracks_congestion_control,
                config_file=s.zenoh_config_file,
                shared_memory=s.zenoh_shared_memory,
                refuse=self.engine.refuse_unread,
                max_payload_bytes=s.max_batch_bytes,
                max_message_bytes=s.zenoh_max_message_bytes,
                detection_keys=s.detection_keys or None,
                scale_out=self.scale_out,
            )
            where = (
                f"mode {s.zenoh_mode}, listen {','.join(s.zenoh_listen) or 'none'}, connect "
                f"{','.join(s.zenoh_connect) or 'none'}"
            )
            try:
                zio.build_config()
            except zenoh.ZError as exc:  # a bad configuration: waiting would not mend it
                raise ZenohStartError(
                    f"cannot configure the Zenoh session ({where}): {exc}"
                ) from None
            self._stopping.clear()
            self.connecting = None
            self.engine.start()
            try:
                zio.open()
            except zenoh.ZError as exc:
                if s.zenoh_mode != "client":
                    self.engine.stop()
                    raise ZenohStartError(
                        f"cannot open the Zenoh session ({where}): {exc}"
                    ) from None
                self._started = True
                self.connecting = f"attempt 1: {_reason(exc)}"
                log.warning(
                    "no Zenoh router answers at %s (%s); trying again every %.0f s at most "
                    "until one does (GET /ready says not ready meanwhile)",
                    ",".join(s.zenoh_connect) or "none",
                    _reason(exc),
                    CONNECT_RETRY_MAX,
                )
                self._connector = threading.Thread(
                    target=self._keep_connecting, args=(zio,), name="zenoh-connect", daemon=True
                )
                self._connector.start()
                return
            self._started = True
            self._connected(zio)

    def _keep_connecting(self, zio: ZenohIO) -> None:
        """Open ``zio`` until it opens (a client waiting for its router), backing off from
        :data:`CONNECT_RETRY_MIN` to :data:`CONNECT_RETRY_MAX` seconds; a warning every
        :data:`CONNECT_LOG_INTERVAL` seconds while it fails. Ends when the runtime stops."""
        delay, attempt = CONNECT_RETRY_MIN, 1
        logged = time.monotonic()
        while not self._stopping.wait(delay):
            attempt += 1
            try:
                zio.open()
            except zenoh.ZError as exc:
                self.connecting = f"attempt {attempt}: {_reason(exc)}"
                if time.monotonic() - logged >= CONNECT_LOG_INTERVAL:
                    logged = time.monotonic()
                    log.warning("still no Zenoh router (%s)", self.connecting)
                delay = min(2.0 * delay, CONNECT_RETRY_MAX)
                continue
            with self._lock:
                if self._stopping.is_set():
                    zio.close()
                    return
                log.info("connected to the Zenoh router after %d attempts", attempt)
                self._connected(zio)
            return

    def _connected(self, zio: ZenohIO) -> None:
        """The session is open: reports go out on it, the demo starts (caller holds the lock)."""
        s = self.settings
        self.connecting = None
        self.engine.sink = zio
        self.zenoh = zio
        if s.scale_out and s.zenoh_mode == "peer" and not s.zenoh_listen:
            log.warning(
                "scale-out as a Zenoh peer that listens nowhere: the other instances "
                "cannot reach this one (federated queries, hand-overs). Connect to the "
                "router as a client (zenoh_mode client) or listen on an address they reach"
            )
        if s.demo:
            self._start_demo()
        if s.zenoh_connect or s.zenoh_mode == "client":
            self._watcher = threading.Thread(
                target=self._watch, args=(zio,), name="zenoh-watch", daemon=True
            )
            self._watcher.start()
        log.info(
            "tracker-service %s ready: instance %s, key prefix %r",
            __version__,
            s.instance_id,
            s.key_prefix,
        )

    def _watch(self, zio: ZenohIO) -> None:
        """Log when the session stops reaching any router or peer, and when it reaches one
        again (Zenoh reconnects by itself; ``/ready`` says so meanwhile)."""
        reached = True
        where = ",".join(self.settings.zenoh_connect) or "none"
        while not self._stopping.wait(WATCH_INTERVAL):
            reach = zio.reach()
            if reach is None:
                return
            n = sum(reach)
            if reached and n == 0:
                log.warning(
                    "the Zenoh session reaches no router or peer any more (connect %s): no "
                    "batch comes in and no report goes out until one answers",
                    where,
                )
            elif not reached and n > 0:
                log.info("the Zenoh session reaches %d router(s) or peer(s) again", n)
            reached = n > 0

    def stop(self) -> None:
        self._stopping.set()
        for thread in (self._connector, self._watcher):
            if thread is not None and thread is not threading.current_thread():
                thread.join(CONNECT_RETRY_MAX + 5.0)
        with self._lock:
            self._watcher = None
            self._connector = None
            self.connecting = None
            if not self._started:
                return
            self._started = False
            if self.demo is not None:
                _stop_process(self.demo)
                self.demo = None
            # no new batches; the queued ones are tracked and their reports still go out
            if self.zenoh is not None:
                self.zenoh.stop_intake()
            self.engine.view.close()  # end the live view's streams
            self.engine.stop()
            if self.zenoh is not None:
                self.zenoh.close()
                self.zenoh = None
            log.info("tracker-service stopped")

    def readiness(self) -> dict[str, Any]:
        """Whether the service can take detections now (``GET /ready``): the Zenoh session
        open and, when it is to reach others (connect endpoints, or a client), connected to
        at least one router or peer; the tracker's worker running. ``detail`` names what is
        not ready."""
        s = self.settings
        zio = self.zenoh  # read once: stop() may clear it meanwhile
        reach = zio.reach() if zio is not None else None
        routers, peers = reach or (0, 0)
        must_connect = bool(s.zenoh_connect) or s.zenoh_mode == "client"
        connected = reach is not None and (not must_connect or routers + peers > 0)
        running = self.engine.running
        problems = []
        if reach is None and self.connecting is not None:
            problems.append(
                "waiting for a Zenoh router (connect "
                f"{','.join(s.zenoh_connect) or 'none'}; {self.connecting})"
            )
        elif reach is None:
            problems.append("the Zenoh session is not open")
        elif not connected:
            problems.append(
                "the Zenoh session reaches no router or peer (connect "
                f"{','.join(s.zenoh_connect) or 'none'})"
            )
        if not running:
            problems.append("the tracker worker is not running")
        out: dict[str, Any] = {
            "status": "ready" if not problems else "not_ready",
            "zenoh": {
                "open": reach is not None,
                "connected": connected,
                "mode": s.zenoh_mode,
                "routers": routers,
                "peers": peers,
            },
            "worker": {"running": running},
        }
        if problems:
            out["detail"] = "; ".join(problems)
        return out

    def _start_demo(self) -> None:
        command = demo_command(self.settings)
        if command is None:
            log.warning("demo: the service has no Zenoh endpoint to reach; no demo client")
            return
        self.demo = subprocess.Popen(command, stdin=subprocess.DEVNULL)
        log.info("demo: started the demo client (pid %d): %s", self.demo.pid, " ".join(command[1:]))


def _state_store(settings: Settings) -> StateStore | None:
    """The tracker state file (restored when the engine starts), if one is set."""
    if settings.state_file is None:
        return None
    return StateStore(
        settings.state_file,
        max_age=settings.state_max_age,
        save_interval=settings.state_save_interval,
    )


def create_app(settings: Settings | None = None, token_source: str | None = None) -> FastAPI:
    """The service as a FastAPI app. The engine is built here (loading ``config_file`` when it
    exists: a bad file raises :class:`~service.config_store.ConfigError`); the lifespan starts it
    (restoring ``state_file`` when there is a usable one), opens Zenoh (and starts the demo
    client), and closes everything on shutdown (saving ``state_file``). ``token_source`` names
    where a set ``api_token`` came from, for the start-up line."""
    settings = settings or Settings()
    ingest_defaults = IngestConfig(
        max_detections_per_batch=settings.max_detections_per_batch,
        reorder_window=settings.reorder_window,
        sensor_wait=settings.sensor_wait,
        max_time_jump=settings.max_time_jump,
    )
    loaded = None
    if settings.config_file is not None:
        remove_stale_temporaries(settings.config_file)  # what a crash during a save left
        loaded = load_config_file(settings.config_file, ingest_defaults)
    tracker_config, ingest = loaded if loaded else (TrackerConfig(), ingest_defaults)
    if loaded:
        changed = config_changes(
            config_document(TrackerConfig(), ingest_defaults), config_document(*loaded)
        )
        log.info(
            "tracker configuration loaded from %s: %s",
            settings.config_file,
            f"{len(changed)} setting(s) differ from the defaults ({'; '.join(changed)}); a "
            "fresh --state-dir starts from the defaults"
            if changed
            else "the defaults",
        )
    if settings.demo and settings.demo_scenario == "formation":
        tracker_config = tracker_config.merged({"formation": {"enabled": True}})
        log.info("demo formation: formation tracking switched on (formation.enabled)")
    log.info(
        "state folder %s; configuration file %s; tracks %s",
        settings.state_dir,
        "none (changes are not saved)"
        if settings.config_file is None
        else f"{settings.config_file} ({'loaded' if loaded else 'written at the first change'})",
        "not saved (a restart begins with none: --state-file keeps them)"
        if settings.state_file is None
        else f"saved to {settings.state_file}",
    )
    ids = IdReservation(
        id_file(settings.state_dir, settings.instance_id if settings.scale_out else None)
    )
    stats = Stats(settings.instance_id, settings.ingest_queue_size)
    engine = Engine(
        tracker_config,
        ingest,
        stats=stats,
        queue_size=settings.ingest_queue_size,
        put_timeout=settings.ingest_put_timeout,
        max_batch_bytes=settings.max_batch_bytes,
        queue_bytes=settings.ingest_queue_bytes,
        ingest_defaults=ingest_defaults,
        config_file=settings.config_file,
        state_store=_state_store(settings),
        id_reservation=ids,
        pipeline_factory=functools.partial(
            TrackingPipeline.all_kinds,
            id_prefix=f"{settings.instance_id}:" if settings.scale_out else "",
        ),
    )
    token = _resolve_token(settings, token_source)
    runtime = ServiceRuntime(settings, engine, token)

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        runtime.start()  # a no-op when main() started it already
        try:
            yield
        finally:
            runtime.stop()

    app = FastAPI(
        title="tracker-service",
        version=__version__,
        summary="Real-time multi-target tracking: detections in over Zenoh or REST, tracks out.",
        lifespan=lifespan,
        docs_url=None,  # served below from the package's files, not a CDN
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.engine = engine
    app.state.stats = stats
    app.state.api_token = token
    app.state.runtime = runtime
    app.include_router(api_router)
    app.include_router(view_router)
    app.mount("/view/assets", StaticFiles(directory=VIEW_DIR), name="view-assets")
    _offline_docs(app)
    app.add_middleware(AllowedMethods, openapi=lambda: app.openapi())
    _extend_openapi(app)
    return app


def _docs_assets() -> Path:
    """The folder of Swagger UI's and ReDoc's files (the ``fastapi-offline`` package's:
    Swagger UI 5, which reads the OpenAPI 3.1 documents FastAPI writes)."""
    import fastapi_offline

    return Path(fastapi_offline.__file__).resolve().parent / "static"


def _offline_docs(app: FastAPI) -> None:
    """``/docs`` (Swagger UI) and ``/redoc`` with their files served by the service itself,
    so the documentation works with no Internet access."""
    assets = "/docs/assets"
    app.mount(assets, StaticFiles(directory=_docs_assets()), name="docs-assets")
    openapi_url = app.openapi_url or "/openapi.json"
    oauth2_redirect = app.swagger_ui_oauth2_redirect_url or "/docs/oauth2-redirect"

    @app.get("/docs", include_in_schema=False)
    async def swagger_ui() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url=openapi_url,
            title=f"{app.title} - Swagger UI",
            oauth2_redirect_url=oauth2_redirect,
            swagger_js_url=f"{assets}/swagger-ui-bundle.js",
            swagger_css_url=f"{assets}/swagger-ui.css",
            swagger_favicon_url=f"{assets}/favicon.png",
            swagger_ui_parameters={"validatorUrl": None},  # no badge from validator.swagger.io
        )

    @app.get(oauth2_redirect, include_in_schema=False)
    async def swagger_ui_redirect() -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()

    @app.get("/redoc", include_in_schema=False)
    async def redoc() -> HTMLResponse:
        return get_redoc_html(
            openapi_url=openapi_url,
            title=f"{app.title} - ReDoc",
            redoc_js_url=f"{assets}/redoc.standalone.js",
            redoc_favicon_url=f"{assets}/favicon.png",
            with_google_fonts=False,
        )


def _extend_openapi(app: FastAPI) -> None:
    """Put the raw-body request schemas (Detection batch, configuration) in the components."""

    def openapi() -> dict[str, Any]:
        if app.openapi_schema:
            return app.openapi_schema
        schema = get_openapi(
            title=app.title,
            version=app.version,
            summary=app.summary,
            routes=app.routes,
        )
        components = schema.setdefault("components", {}).setdefault("schemas", {})
        template = "#/components/schemas/{model}"
        for model in (DetectionBatchIn, ConfigDocument, ConfigPatch, IngestConfig):
            js = model.model_json_schema(ref_template=template)
            for name, sub in js.pop("$defs", {}).items():
                components.setdefault(name, sub)
            components[model.__name__] = js
        app.openapi_schema = schema
        return schema

    app.openapi = openapi  # type: ignore[method-assign]


def view_url(host: str, port: int) -> str:
    """The live view's address on ``host`` (a wildcard address: on this machine)."""
    if host in ("", "0.0.0.0"):
        host = "127.0.0.1"
    elif host == "::":
        host = "::1"
    if ":" in host:
        host = f"[{host}]"
    return f"http://{host}:{port}/view"


def _configure_logging(level: str) -> None:
    logging.basicConfig(
        level=level.upper(),
        format="%(asctime)s %(levelname)-7s %(name)s: %(message)s",
        stream=sys.stderr,
        force=True,
    )


class _Server(uvicorn.Server):
    """Uvicorn that starts stopping the runtime as soon as it is asked to exit, so requests
    waiting on the engine (a REST batch held by the reorder window) get their answers while
    uvicorn drains its connections, instead of being cancelled."""

    def __init__(self, config: uvicorn.Config, runtime: ServiceRuntime) -> None:
        super().__init__(config)
        self._runtime = runtime

    def handle_exit(self, sig: int, frame: Any) -> None:
        if not self.should_exit:
            threading.Thread(target=self._runtime.stop, name="runtime-stop", daemon=True).start()
        super().handle_exit(sig, frame)


def main(argv: Sequence[str] | None = None) -> int:
    """``tracker-service``: run the service until SIGINT or SIGTERM."""
    try:
        settings = load_settings(argv)
    except SettingsLoadError as exc:
        print(f"tracker-service: {exc}", file=sys.stderr)
        return 2
    _configure_logging(settings.log_level)
    if settings.api_token_file is not None:
        source = f"the file {settings.api_token_file} (api_token_file)"
    else:
        source = api_token_source(argv)
    try:
        app = create_app(settings, source)
    except ConfigError as exc:
        print(f"tracker-service: {exc}", file=sys.stderr)
        return 2
    config = uvicorn.Config(
        app,
        host=settings.http_host,
        port=settings.http_port,
        log_config=None,
        log_level=settings.log_level,
        access_log=settings.log_level == "debug",
        timeout_graceful_shutdown=1,
        lifespan="on",
    )
    runtime: ServiceRuntime = app.state.runtime
    server = _Server(config, runtime)
    try:
        runtime.start()
    except ZenohStartError as exc:
        print(f"tracker-service: {exc}", file=sys.stderr)
        return 1
    log.info("live view: %s", view_url(settings.http_host, settings.http_port))

    # uvicorn re-raises the signal it stopped on once it is done; with these handlers in
    # place that re-raise is harmless and the process exits with status 0.
    def _stopped(signum: int, frame: Any) -> None:
        log.debug("signal %d after shutdown ignored", signum)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _stopped)
    try:
        server.run()
    except SystemExit as exc:  # uvicorn exits this way when start-up fails
        code = exc.code if isinstance(exc.code, int) else 1
        print("tracker-service: start-up failed (see the log above)", file=sys.stderr)
        return code or 1
    finally:
        runtime.stop()
    if not server.started:
        print("tracker-service: start-up failed (see the log above)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
