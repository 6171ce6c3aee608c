"""Scale-out over Zenoh: several service instances share the work, joined by nothing but
Zenoh routers.

Each instance takes the detection keys of its own sensors (setting ``detection_keys``),
qualifies its track ids with its ``instance_id`` and publishes on
``{prefix}/tracks/{instance_id}`` (:class:`service.zenoh_io.ZenohIO`). This module adds what
the instances do together:

- **Federated track queries** (:meth:`ScaleOut.federated_tracks`): every instance answers on
  ``{prefix}/state/tracks/{instance_id}``; one ``get`` on ``{prefix}/state/tracks/*``
  (consolidation off, a timeout) gathers them. Instances are known by their liveliness
  tokens ``{prefix}/alive/{instance_id}``; the answer says which answered and which did not,
  and returns after the timeout at the latest, so a hung instance cannot hold it.
- **Sector hand-over** (:meth:`ScaleOut.after_report`): a confirmed individual track more
  than ``sector_margin`` beyond the instance's ``sector`` is offered, state and id, on
  ``{prefix}/handover/*``; an instance whose sector holds it takes it
  (:meth:`Engine.hand_in`: predicted to its next batch and updated there, or merged into its
  own track of the same target, which takes the id) and says so; the offering instance then
  drops it (:meth:`Engine.hand_over`). Until an instance takes it, the track stays where it is
  and is offered again every ``OFFER_RETRY_S``.
- **Shared configuration** (:meth:`ScaleOut.share_config`): a change accepted over REST is
  put on ``{prefix}/config/{instance_id}``; every other instance applies the whole document
  (validated and saved as a PUT would be), the latest change winning.

Hand-over offers, their answers and configuration changes are sealed with an HMAC-SHA256
keyed by the API token: only instances that share the token (the deployment's secret) act on
them, so a sender on the Zenoh network without it can neither move tracks nor change the
configuration.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import math
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import orjson
import zenoh

from service.config_tree import ConfigError
from service.engine import Engine
from service.keys import Keys
from service.reports import ReportState
from trackers.peers import PointTrackState

__all__ = ["OFFER_RETRY_S", "ScaleOut", "SealError", "Sector", "merge_answers", "seal", "unseal"]

log = logging.getLogger("service.scale_out")

_JSON = zenoh.Encoding.APPLICATION_JSON

#: Seconds before a track no instance took is offered again.
OFFER_RETRY_S = 5.0
#: Seconds an instance whose liveliness token went away is still named as missing.
DEPARTED_KEEP_S = 600.0


class SealError(ValueError):
    """A sealed message that is not one, or not sealed with this deployment's key."""


def seal(obj: Any, key: bytes) -> bytes:
    """``obj`` as JSON with an HMAC-SHA256 over it: ``{"body": <json text>, "mac": <hex>}``."""
    body = orjson.dumps(obj, option=orjson.OPT_SERIALIZE_NUMPY)
    mac = hmac.new(key, body, hashlib.sha256).hexdigest()
    return orjson.dumps({"body": body.decode(), "mac": mac})


def unseal(data: bytes, key: bytes) -> Any:
    """The object :func:`seal` sealed with ``key``; :class:`SealError` otherwise."""
    try:
        outer = orjson.loads(data)
        body = outer["body"].encode()
        mac = outer["mac"]
    except (orjson.JSONDecodeError, KeyError, TypeError, AttributeError):
        raise SealError("not a sealed message") from None
    expected = hmac.new(key, body, hashlib.sha256).hexdigest()
    if not isinstance(mac, str) or not hmac.compare_digest(mac, expected):
        raise SealError("the seal does not match this deployment's key (another api_token?)")
    try:
        return orjson.loads(body)
    except orjson.JSONDecodeError:
        raise SealError("the sealed body is not JSON") from None


@dataclass(frozen=True)
class Sector:
    """An instance's area: ``xmin <= x < xmax``, ``ymin <= y < ymax`` (metres), so that
    sectors that share an edge never both hold a point."""

    xmin: float
    ymin: float
    xmax: float
    ymax: float

    def contains(self, x: float, y: float) -> bool:
        return self.xmin <= x < self.xmax and self.ymin <= y < self.ymax

    def beyond(self, x: float, y: float, margin: float) -> bool:
        """Whether ``(x, y)`` lies more than ``margin`` outside the sector (on either axis)."""
        return (
            x < self.xmin - margin
            or x >= self.xmax + margin
            or y < self.ymin - margin
            or y >= self.ymax + margin
        )


def _state_dict(st: PointTrackState) -> dict[str, Any]:
    return {
        "id": st.id,
        "time": st.time,
        "x": st.x.tolist(),
        "P": st.P.tolist(),
        "score": st.score,
        "hits": st.hits,
        "confirmed": st.confirmed,
        "created": st.created,
        "updated": st.updated,
        "instants": st.instants,
    }


def _state_of(d: Any) -> PointTrackState:
    """A hand-over record from its JSON form; ``ValueError`` when it is not a usable one."""
    if not isinstance(d, dict):
        raise ValueError("a track must be an object")
    try:
        x = np.asarray(d["x"], dtype=float)
        P = np.asarray(d["P"], dtype=float)
        numbers = [float(d[k]) for k in ("time", "score", "created", "updated")]
        tid, hits, confirmed = d["id"], int(d["hits"]), bool(d["confirmed"])
        instants = d.get("instants")  # (an instance of before instants: none)
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"a track field is missing or not a number: {exc}") from None
    if instants is not None and (
        isinstance(instants, bool) or not isinstance(instants, int) or instants < 0
    ):
        raise ValueError(f"instants: an integer >= 0 or null, got {instants!r}")
    if not isinstance(tid, str) or not 0 < len(tid) <= 200:
        raise ValueError("id: a string of 1 to 200 characters")
    if x.shape != (5,) or P.shape != (5, 5):
        raise ValueError(f"track {tid}: x must have 5 entries and P 5x5")
    if not (np.isfinite(x).all() and np.isfinite(P).all() and all(map(math.isfinite, numbers))):
        raise ValueError(f"track {tid}: numbers must be finite")
    if not np.allclose(P, P.T, rtol=1e-6, atol=1e-9) or (np.linalg.eigvalsh(P) <= 0).any():
        raise ValueError(f"track {tid}: P must be symmetric positive definite")
    t, score, created, updated = numbers
    return PointTrackState(
        id=tid,
        time=t,
        x=x,
        P=P,
        score=score,
        hits=max(0, hits),
        confirmed=confirmed,
        created=created,
        updated=updated,
        instants=instants,
    )


def merge_answers(answers: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Every instance's tracks, each with its ``instance``; a track two instances hold
    (during a hand-over) once, as the one updated last."""
    merged: dict[str, dict[str, Any]] = {}
    for instance, report in answers.items():
        for track in report.get("tracks") or ():
            if not isinstance(track, dict) or "id" not in track:
                continue
            out = {**track, "instance": instance}
            old = merged.get(out["id"])
            if old is None or (out.get("updated") or -math.inf) > (old.get("updated") or -math.inf):
                merged[out["id"]] = out
    return list(merged.values())


class ScaleOut:
    """One instance's part of a scaled-out deployment (see the module docstring): declared
    on the service's Zenoh session by :meth:`declare`, undeclared by :meth:`undeclare`."""

    def __init__(
        self,
        *,
        engine: Engine,
        keys: Keys,
        instance_id: str,
        token: str,
        sector: Sector | None = None,
        sector_margin: float = 500.0,
        federate_timeout: float = 1.0,
    ) -> None:
        self.engine = engine
        self.keys = keys
        self.instance_id = instance_id
        self._key = token.encode()
        self.sector = sector
        self.sector_margin = sector_margin
        self.federate_timeout = federate_timeout
        self.session: zenoh.Session | None = None
        self._entities: list[Any] = []
        self._lock = threading.Lock()
        self._offered: dict[str, float] = {}  # track id -> monotonic time of the last offer
        self._alive: set[str] = set()
        self._departed: dict[str, float] = {}  # instance -> monotonic time its token went
        self._config_stamp: tuple[int, str] = (0, "")
        #: hand-over counts, for the stats and the tests
        self.handed_over = 0
        self.handed_in = 0

    # -- lifecycle --------------------------------------------------------------------------

    def declare(self, session: zenoh.Session) -> None:
        self.session = session
        self._entities.append(
            session.liveliness().declare_subscriber(
                self.keys.alive("*"), self._on_alive, history=True
            )
        )
        self._entities.append(session.declare_subscriber(self.keys.config("*"), self._on_config))
        if self.sector is not None:
            self._entities.append(
                session.declare_queryable(self.keys.handover(self.instance_id), self._on_offer)
            )

    def undeclare(self) -> None:
        entities, self._entities = self._entities, []
        for entity in entities:
            try:
                entity.undeclare()
            except Exception:
                log.debug("undeclare failed", exc_info=True)
        self.session = None

    # -- who is there -----------------------------------------------------------------------

    def _on_alive(self, sample: zenoh.Sample) -> None:
        instance = str(sample.key_expr).rsplit("/", 1)[-1]
        with self._lock:
            if sample.kind == zenoh.SampleKind.PUT:
                self._alive.add(instance)
                self._departed.pop(instance, None)
            else:
                self._alive.discard(instance)
                self._departed[instance] = time.monotonic()

    def instances(self) -> tuple[set[str], set[str]]:
        """The instances alive now (this one included) and those whose token went away in
        the last ``DEPARTED_KEEP_S`` seconds."""
        now = time.monotonic()
        with self._lock:
            for gone in [i for i, t in self._departed.items() if now - t > DEPARTED_KEEP_S]:
                del self._departed[gone]
            return self._alive | {self.instance_id}, set(self._departed)

    # -- federated queries (REST threads) ---------------------------------------------------

    def _gather(self, status: str, kinds: set[str] | None) -> dict[str, dict[str, Any]]:
        """Every instance's answer that came within the timeout, this one's included."""
        answers: dict[str, dict[str, Any]] = {self.instance_id: self.engine.tracks(status, kinds)}
        session = self.session
        if session is None:
            return answers
        params = f"status={status}"
        if kinds:
            params += ";kind=" + ",".join(sorted(kinds))
        try:
            replies = session.get(
                f"{self.keys.instance_state('*')}?{params}",
                target=zenoh.QueryTarget.ALL,
                consolidation=zenoh.ConsolidationMode.NONE,
                timeout=self.federate_timeout,
            )
            for reply in replies:
                ok = reply.ok
                if ok is None:
                    continue
                instance = str(ok.key_expr).rsplit("/", 1)[-1]
                if instance == self.instance_id:
                    continue
                try:
                    report = orjson.loads(ok.payload.to_bytes())
                except orjson.JSONDecodeError:
                    log.warning("instance %s answered with something that is not JSON", instance)
                    continue
                if isinstance(report, dict):
                    answers[instance] = report
        except zenoh.ZError as exc:
            log.warning("a federated track query failed: %s", exc)
        return answers

    def federated_tracks(self, status: str = "confirmed", kinds: set[str] | None = None) -> dict:
        """The latest Track report of every instance, merged (:func:`merge_answers`): this
        instance's ``seq``, ``sensor_id``, ``processing_ms`` and ``deleted``, the latest
        ``time`` of all, and ``instances``: ``answered`` and ``missing`` (alive and silent
        within ``federate_timeout``, or gone lately)."""
        answers = self._gather(status, kinds)
        alive, departed = self.instances()
        local = answers[self.instance_id]
        times = [r["time"] for r in answers.values() if isinstance(r.get("time"), int | float)]
        answered = sorted(answers)
        return {
            **local,
            "time": max(times) if times else None,
            "tracks": merge_answers(answers),
            "instances": {
                "answered": answered,
                "missing": sorted((alive | departed) - set(answered)),
                "timeout_s": self.federate_timeout,
            },
        }

    def federated_track(self, track_id: str) -> dict[str, Any] | None:
        """One live track (tentative too) of any instance, with its ``instance``."""
        local = self.engine.track(track_id)
        if local is not None:
            return {**local, "instance": self.instance_id}
        for track in merge_answers(self._gather("all", None)):
            if track.get("id") == track_id:
                return track
        return None

    # -- hand-over --------------------------------------------------------------------------

    def after_report(self, state: ReportState) -> None:
        """On the worker after each batch: offer the confirmed individual tracks (not in a
        formation) that went ``sector_margin`` beyond the sector to the other instances."""
        sector, session = self.sector, self.session
        if sector is None or session is None:
            return
        margin = self.sector_margin
        now = time.monotonic()
        # an offer older than the retry interval no longer holds a track back
        self._offered = {k: v for k, v in self._offered.items() if now - v < OFFER_RETRY_S}
        leaving = []
        for track in state.report.get("tracks") or ():
            if track.get("kind") != "individual" or track.get("formation_id"):
                continue
            x, y = track["position"]
            if not sector.beyond(x, y, margin):
                continue
            if track["id"] not in self._offered:
                leaving.append(track["id"])
        if not leaving:
            return
        states = self.engine.point_states(leaving)
        if not states:
            return
        for st in states:
            self._offered[st.id] = now
        offer = {"from": self.instance_id, "tracks": [_state_dict(st) for st in states]}
        try:
            session.get(
                self.keys.handover("*"),
                self._on_answer,
                payload=seal(offer, self._key),
                encoding=_JSON,
                target=zenoh.QueryTarget.ALL,
                consolidation=zenoh.ConsolidationMode.NONE,
                timeout=max(1.0, self.federate_timeout),
            )
        except zenoh.ZError as exc:
            log.warning("could not offer %d tracks for hand-over: %s", len(states), exc)

    def _on_offer(self, query: zenoh.Query) -> None:
        """Another instance offers tracks: take those inside this sector."""
        try:
            payload = query.payload
            if payload is None:
                return
            try:
                offer = unseal(payload.to_bytes(), self._key)
                source = offer["from"]
                states = [_state_of(d) for d in offer["tracks"]]
            except (SealError, KeyError, TypeError, ValueError) as exc:
                log.warning("a hand-over offer was refused: %s", exc)
                query.reply_err(str(exc).encode(), encoding=zenoh.Encoding.TEXT_PLAIN)
                return
            if source == self.instance_id:
                return
            sector = self.sector
            taken = [st for st in states if sector is not None and sector.contains(*st.x[:2])]
            if taken:
                self.engine.hand_in(taken)
                self.handed_in += len(taken)
                log.info("took over %s from instance %s", ", ".join(st.id for st in taken), source)
            answer = {"instance": self.instance_id, "taken": [st.id for st in taken]}
            query.reply(
                self.keys.handover(self.instance_id), seal(answer, self._key), encoding=_JSON
            )
        except Exception:
            log.exception("could not answer a hand-over offer")
        finally:
            query.drop()

    def _on_answer(self, reply: zenoh.Reply) -> None:
        """An instance answered an offer: drop the tracks it took."""
        try:
            ok = reply.ok
            if ok is None:
                return
            try:
                answer = unseal(ok.payload.to_bytes(), self._key)
                instance, taken = answer["instance"], answer["taken"]
            except (SealError, KeyError, TypeError) as exc:
                log.warning("a hand-over answer was ignored: %s", exc)
                return
            ids = [str(t) for t in taken if isinstance(t, str)]
            if not ids or instance == self.instance_id:
                return
            self.engine.hand_over(ids)
            self.handed_over += len(ids)
            log.info("handed over %s to instance %s", ", ".join(ids), instance)
        except Exception:
            log.exception("could not take a hand-over answer")

    # -- shared configuration ---------------------------------------------------------------

    def share_config(self, document: dict[str, Any]) -> None:
        """Put a configuration change accepted here for every other instance."""
        session = self.session
        if session is None:
            return
        stamp = (time.time_ns(), self.instance_id)
        with self._lock:
            self._config_stamp = max(self._config_stamp, stamp)
        message = {"origin": self.instance_id, "stamp": stamp[0], "document": document}
        try:
            session.put(
                self.keys.config(self.instance_id), seal(message, self._key), encoding=_JSON
            )
        except zenoh.ZError as exc:
            log.warning("could not share the configuration change: %s", exc)

    def _on_config(self, sample: zenoh.Sample) -> None:
        try:
            try:
                message = unseal(sample.payload.to_bytes(), self._key)
                origin, stamp = str(message["origin"]), int(message["stamp"])
                document = message["document"]
            except (SealError, KeyError, TypeError, ValueError) as exc:
                log.warning("a configuration change on %s was refused: %s", sample.key_expr, exc)
                return
            if origin == self.instance_id:
                return
            with self._lock:
                if (stamp, origin) <= self._config_stamp:
                    return  # an older change than one applied here
                self._config_stamp = (stamp, origin)
            try:
                applied = self.engine.apply_config(document, merge=False)
            except (ConfigError, OSError) as exc:
                log.warning("the configuration from instance %s was not applied: %s", origin, exc)
                return
            log.info(
                "configuration from instance %s applied: %s",
                origin,
                "; ".join(applied.changes) or "no change",
            )
        except Exception:
            log.exception("could not take a configuration change")
