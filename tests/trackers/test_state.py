"""Saving and restoring the pipeline's state: an exact round trip on the reference scenario,
re-moding under other motion models, peers' sections, and refusal of bad or foreign files."""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from clients.scenarios.multitarget import reference_scenario, simulate
from trackers.config import TrackerConfig
from trackers.peers import PeerProposal, PersistentTracker, PointTrackView
from trackers.pipeline import TrackingPipeline
from trackers.state import (
    FORMAT,
    PipelineState,
    StateError,
    StateSection,
    decode_state,
    encode_state,
    pack_strings,
    unpack_strings,
)
from trackers.types import Scan, ScanRejected, TrackSnapshot


@pytest.fixture(scope="module")
def scans() -> list[Scan]:
    return [s.to_scan() for s in simulate(reference_scenario(0))]


def tracks_of(p: TrackingPipeline) -> list[tuple[Any, ...]]:
    """Everything a track shows, tentative ones too, exactly."""
    return [
        (
            t.id,
            t.status,
            t.time,
            t.position,
            t.velocity,
            t.covariance.tolist(),
            t.score,
            t.hits,
            t.created,
            t.updated,
            t.model_probabilities,
            t.detection_ids,
        )
        for t in p.snapshot()
    ]


def candidates_of(p: TrackingPipeline) -> list[Any]:
    c = p.point.candidates  # type: ignore[attr-defined]
    grouped = np.isfinite(c.group_velocity)
    arrays = (c.z, c.R, c.time, c.score, c.origin, c.detection_ids, grouped)
    return [a.tolist() for a in arrays] + [c.group_velocity[grouped].tolist()]


def restarted(p: TrackingPipeline, config: TrackerConfig | None = None) -> TrackingPipeline:
    """A new pipeline going on from ``p``'s state, through the bytes of a file."""
    state, meta = decode_state(encode_state(p.export_state(), {"note": "x"}))
    assert meta == {"note": "x"}
    q = TrackingPipeline(config)
    q.import_state(state)
    return q


def _without(state: PipelineState, *names: str) -> PipelineState:
    """``state`` as a file written before the point section had the arrays ``names``."""
    arrays = {k: v for k, v in state.point.arrays.items() if k not in names}
    section = StateSection(state.point.values, arrays)
    return PipelineState(state.last_time, state.point_kind, section, state.peers)


def test_candidates_keep_their_group_velocities_and_older_files_have_none() -> None:
    p = TrackingPipeline(TrackerConfig())
    v = np.array([-200.0, 300.0])
    for k in range(9):
        z = [[5000.0, 800.0] + v * k] + ([[5400.0, 800.0] + v * k] if k == 8 else [])
        R = np.tile(400.0 * np.eye(2), (len(z), 1, 1))
        p.process(Scan(sensor_id="s", time=float(k), z=np.array(z), R=R))
    c = p.point.candidates  # type: ignore[attr-defined]
    assert np.isfinite(c.group_velocity).all(axis=1).sum() == 1  # the detection beside it
    assert candidates_of(restarted(p)) == candidates_of(p)
    older = _without(p.export_state(), "candidates.grouped", "candidates.group_velocity")
    q = TrackingPipeline(TrackerConfig())
    q.import_state(older)
    assert np.isnan(q.point.candidates.group_velocity).all()  # type: ignore[attr-defined]


def test_tracks_of_an_older_file_count_an_instant_a_detection_and_have_no_siblings(
    scans: list[Scan],
) -> None:
    """A file written before tracks counted their instants and siblings: each detection was
    an instant (one sensor's scans, as before), and no track took a detection of the last
    batch with another."""
    p = TrackingPipeline(TrackerConfig())
    for scan in scans[:12]:
        p.process(scan)
    state = p.export_state()
    values = {k: v for k, v in state.point.values.items() if k != "next_serial"}
    state = PipelineState(
        state.last_time, state.point_kind, StateSection(values, state.point.arrays), state.peers
    )
    older = _without(state, "tracks.instants", "tracks.took", "tracks.first", "candidates.serial")
    q = TrackingPipeline(TrackerConfig())
    q.import_state(older)
    tracks = q.point.tracks  # type: ignore[attr-defined]
    assert len(tracks) and (tracks.instants == tracks.hits).all()
    assert (tracks.took == -1).all() and (tracks.first == -1).all()
    assert (q.point.candidates.serial == -1).all()  # type: ignore[attr-defined]
    assert tracks_of(q) == tracks_of(p)
    # a file of the first version with instants: its took were rows of the last batch, and
    # it had no serial counter; they are not read as serials
    first = _without(p.export_state())
    values = {k: v for k, v in first.point.values.items() if k != "next_serial"}
    first = PipelineState(
        first.last_time, first.point_kind, StateSection(values, first.point.arrays), first.peers
    )
    r = TrackingPipeline(TrackerConfig())
    r.import_state(first)
    assert (r.point.tracks.took == -1).all()  # type: ignore[attr-defined]


@pytest.mark.parametrize("at", [0, 1, 2, 40])
def test_a_restored_pipeline_goes_on_exactly_as_an_uninterrupted_one(
    scans: list[Scan], at: int
) -> None:
    """Saved after ``at`` scans (none; only candidates; the first tracks; mid-run), restored
    and fed the rest of the reference scenario: the same tracks, ids, numbers and deletions
    at every scan as the tracker that ran through."""
    a = TrackingPipeline()
    for s in scans[:at]:
        a.process(s)
    b = restarted(a)
    assert b.last_time == a.last_time
    assert tracks_of(b) == tracks_of(a)
    assert candidates_of(b) == candidates_of(a)
    seen_before = {t.id for t in a.snapshot()}
    new_ids: set[str] = set()
    for s in scans[at:]:
        ra, rb = a.process(s), b.process(s)
        assert rb.deleted == ra.deleted
        assert tracks_of(b) == tracks_of(a)
        new_ids |= {t.id for t in rb.tracks} - seen_before
    assert candidates_of(b) == candidates_of(a)
    assert len(b.snapshot()) >= 40 and len(new_ids) > 0
    if seen_before:  # the id counter went on: no id of before the save is given again
        top = max(int(i[1:]) for i in seen_before)
        assert min(int(i[1:]) for i in new_ids) > top


@pytest.mark.parametrize("at", [5, 13, 31])
def test_a_restored_pipeline_of_radars_reporting_together_goes_on_exactly(at: int) -> None:
    """Paper 003's three radars reporting together, with clutter: saved between two radars'
    batches of one instant (after 5, 13 and 31 batches), a restored tracker counts the instants
    of its tracks and knows their siblings as the uninterrupted one does."""
    from clients.scenarios.formation import environment_2, simulate_formations

    sims = simulate_formations(environment_2(3, 6, seed=1, scans=20, synchronized=True))
    scans = [s.to_scan() for s in sims]
    assert scans[at].time == scans[at - 1].time
    a = TrackingPipeline()
    for s in scans[:at]:
        a.process(s)
    b = restarted(a)
    tracks = a.point.tracks  # type: ignore[attr-defined]
    assert (tracks.instants < tracks.hits).any() and (tracks.took >= 0).any()
    np.testing.assert_array_equal(b.point.tracks.first, tracks.first)  # type: ignore[attr-defined]
    assert (tracks.first >= 0).any()
    for s in scans[at:]:
        ra, rb = a.process(s), b.process(s)
        assert rb.deleted == ra.deleted
        assert tracks_of(b) == tracks_of(a)


def test_a_restored_camera_goes_on_exactly_with_its_learned_rates() -> None:
    """A 20 Hz camera stating no P_D, saved while a walker is hidden: the restored tracker
    knows the P_D its tracks showed and the camera's interval between frames (since
    2026-11-28), so the walker's track coasts on and goes on exactly as without the restart.
    A file from before has none: they are learned afresh."""
    rng = np.random.default_rng(5)
    frames = []
    for k in range(240):
        t = k / 20.0
        hidden = 8.0 <= t < 9.0 or rng.random() < 0.08
        z = (
            np.zeros((0, 2))
            if hidden
            else np.array([[10.0 + 1.4 * t, 50.0]]) + rng.normal(0, 0.3, (1, 2))
        )
        R = np.tile(0.09 * np.eye(2), (len(z), 1, 1))
        frames.append(Scan("cam", t, z, R, clutter_density=1e-4))  # (the map is not saved)
    a = TrackingPipeline()
    for scan in frames[:170]:  # 8.5 s: hidden for 10 frames
        a.process(scan)
    b = restarted(a)
    assert b.point.detection_probability("cam") == a.point.detection_probability("cam")  # type: ignore[attr-defined]
    assert a.point.detection_probability("cam") != TrackerConfig().track_management.pd  # type: ignore[attr-defined]
    for scan in frames[170:]:
        ra, rb = a.process(scan), b.process(scan)
        assert rb.deleted == ra.deleted == ()
        assert tracks_of(b) == tracks_of(a)
    state = a.export_state()
    values = {k: v for k, v in state.point.values.items() if k != "n_rates"}
    older = _without(
        PipelineState(
            state.last_time, state.point_kind, StateSection(values, state.point.arrays), state.peers
        ),
        "rates.sensors.utf8",
        "rates.sensors.len",
        "rates.values",
    )
    q = TrackingPipeline()
    q.import_state(older)
    assert q.point.detection_probability("cam") == TrackerConfig().track_management.pd  # type: ignore[attr-defined]


def test_the_saved_time_keeps_older_scans_out_of_sequence(scans: list[Scan]) -> None:
    a = TrackingPipeline()
    for s in scans[:10]:
        a.process(s)
    b = restarted(a)
    before = tracks_of(b)
    with pytest.raises(ScanRejected) as err:
        b.process(scans[5])
    assert err.value.reason == "out_of_sequence"
    assert tracks_of(b) == before


def test_every_kind_of_string_survives() -> None:
    ids = ["T1", "", None, "dét-ü", "a\x00", "\x00", "x" * 300]
    utf8, lengths = pack_strings(ids)
    assert utf8.dtype == np.uint8 and lengths.tolist()[:3] == [2, 0, -1]
    assert unpack_strings(utf8, lengths, "w") == ids
    with pytest.raises(StateError, match="add up"):
        unpack_strings(utf8[:-1], lengths, "w")
    with pytest.raises(StateError, match="UTF-8"):
        unpack_strings(np.frombuffer(b"\xff\xfe", dtype=np.uint8), np.array([2]), "w")
    # detection ids of every kind ride along with tracks and candidates
    p = TrackingPipeline()
    det = ("dét-1", "a\x00")
    p.process(Scan("r", 0.0, np.array([[0, 0], [500, 0]]), np.tile(25 * np.eye(2), (2, 1, 1)), det))
    p.process(Scan("r", 1.0, np.array([[5, 0], [505, 0]]), np.tile(25 * np.eye(2), (2, 1, 1))))
    q = restarted(p)
    assert candidates_of(q) == candidates_of(p)
    assert tracks_of(q) == tracks_of(p)
    assert {t.detection_ids for t in q.snapshot()} == {()}
    assert sorted(x for x in q.point.candidates.detection_ids.tolist() if x) == sorted(det)  # type: ignore[attr-defined]


def test_tracks_saved_under_other_motion_models_restart_their_modes(scans: list[Scan]) -> None:
    a = TrackingPipeline()
    for s in scans[:30]:
        a.process(s)
    cv_only = TrackerConfig().merged(
        {"motion": {"models": ["cv"], "sojourn_times": [30.0], "initial_mode_probabilities": [1]}}
    )
    b = restarted(a, cv_only)
    assert [t.id for t in b.snapshot()] == [t.id for t in a.snapshot()]
    assert [t.position for t in b.snapshot()] == [t.position for t in a.snapshot()]
    assert {tuple(t.model_probabilities or {}) for t in b.snapshot()} == {("cv",)}
    assert b.point.tracks.x.shape[1] == 1  # type: ignore[attr-defined]
    for s in scans[30:60]:
        b.process(s)
    assert sum(t.confirmed for t in b.snapshot()) >= 40


# -- bad and foreign files ------------------------------------------------------------------


def saved(scans: list[Scan], n: int = 12) -> PipelineState:
    p = TrackingPipeline()
    for s in scans[:n]:
        p.process(s)
    return p.export_state()


def changed(state: PipelineState, **arrays: Any) -> PipelineState:
    """``state`` with some point arrays or values (``values={...}``) replaced or removed."""
    values = {**state.point.values, **arrays.pop("values", {})}
    new = {**state.point.arrays}
    for name, a in arrays.items():
        name = name.replace("__", ".")
        if a is None:
            new.pop(name)
        else:
            new[name] = a
    return PipelineState(state.last_time, state.point_kind, StateSection(values, new), state.peers)


def _npz(**members: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **members)  # type: ignore[arg-type]
    return buf.getvalue()


def _header(**changes: Any) -> np.ndarray:
    h: dict[str, Any] = {"format": FORMAT, "version": 1, "last_time": None}
    h.update(point={"kind": "individual", "values": {}}, peers={}, meta={})
    h.update(changes)
    return np.frombuffer(json.dumps(h).encode(), dtype=np.uint8)


def _compressed(data: bytes) -> bytes:
    src = zipfile.ZipFile(io.BytesIO(data))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            dst.writestr(info.filename, src.read(info))
    return buf.getvalue()


def _huge_member(data: bytes) -> bytes:
    """``data`` with the header of ``point/tracks.score`` claiming 10^12 numbers."""
    src = zipfile.ZipFile(io.BytesIO(data))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as dst:
        for info in src.infolist():
            raw = src.read(info)
            if info.filename == "point/tracks.score.npy":
                raw = raw.replace(b"'shape': (", b"'shape': (1000000000000, ", 1)
            dst.writestr(info.filename, raw)
    return buf.getvalue()


FILE_DEFECTS: list[tuple[str, Callable[[bytes], bytes], str]] = [
    ("random bytes", lambda d: b"\x00garbage" * 100, "not an .npz archive"),
    ("cut in half", lambda d: d[: len(d) // 2], "not an .npz archive"),
    ("empty", lambda d: b"", "not an .npz archive"),
    ("no header", lambda d: _npz(x=np.zeros(3)), "no header"),
    ("another format", lambda d: _npz(header=_header(format="other")), "another format"),
    ("a later version", lambda d: _npz(header=_header(version=2)), "version 2"),
    ("header not JSON", lambda d: _npz(header=np.frombuffer(b"{", np.uint8)), "header"),
    (
        "an object array",
        lambda d: _npz(header=_header(), **{"point/x": np.array([{}], dtype=object)}),
        "not a number type",
    ),
    (
        "a string array",
        lambda d: _npz(header=_header(), **{"point/x": np.array(["a"])}),
        "not a number type",
    ),
    ("a stray member", lambda d: _npz(header=_header(), other=np.zeros(1)), "member 'other.npy'"),
    ("compressed", _compressed, "compressed"),
    ("a shape larger than its member", _huge_member, "does not fit"),
    (
        "flipped bytes",
        lambda d: d[:200] + bytes(b ^ 0xFF for b in d[200:260]) + d[260:],
        "damaged",
    ),
]


@pytest.mark.parametrize(
    ("data_of", "text"), [d[1:] for d in FILE_DEFECTS], ids=[d[0] for d in FILE_DEFECTS]
)
def test_bad_or_foreign_files_are_refused(
    scans: list[Scan], data_of: Callable[[bytes], bytes], text: str
) -> None:
    data = encode_state(saved(scans), {})
    with pytest.raises(StateError, match=text):
        state, _ = decode_state(data_of(data))
        TrackingPipeline().import_state(state)  # what decodes must still pass the checks


SECTION_DEFECTS: list[tuple[str, dict[str, Any], str]] = [
    ("a NaN", {"tracks__x": "nan"}, "point.tracks.x: holds a number that is not finite"),
    ("an infinite score", {"tracks__score": "inf"}, "tracks.score"),
    ("a shape", {"tracks__P": "short"}, "point.tracks.P: shape"),
    ("a missing array", {"tracks__mu": None}, "point.tracks.mu: missing"),
    ("a type", {"tracks__hits": "float"}, "point.tracks.hits: wrong type"),
    ("an extra array", {"tracks__extra": np.zeros(3)}, "unexpected array"),
    ("a count", {"values": {"n_tracks": 3}}, "shape"),
    ("a counter behind the ids", {"values": {"next_id": 2}}, "would give again the id"),
    ("origins", {"values": {"next_origin": 0}}, "next_origin"),
    ("a time", {"values": {"time": "soon"}}, "point.time"),
    ("no models", {"values": {"models": []}}, "point.models"),
    ("mode probabilities", {"tracks__mu": "half"}, "mode probabilities"),
    ("duplicate ids", {"tracks__ids__len": "dup"}, "unique"),
    ("ids that do not add up", {"tracks__ids__utf8": "cut"}, "add up"),
    ("an asymmetric covariance", {"tracks__P_comb": "skew"}, "covariance"),
    ("a candidate covariance", {"candidates__R": "singular"}, "candidate covariance"),
    ("a track later than the time", {"tracks__updated": "late"}, "created <= updated"),
    ("instants beyond the hits", {"tracks__instants": "more"}, "instants must be from 1"),
    ("a detection not yet numbered", {"tracks__took": "late"}, "next_serial"),
    ("a serial counter past its bound", {"values": {"next_serial": 2**63}}, "next_serial"),
    ("more detections than looks", {"rates__values": "seen"}, "0 <= detected <= looks"),
    ("a sensor heard after the time", {"rates__values": "late"}, "a time after the state's"),
]


def _defect(state: PipelineState, how: dict[str, Any]) -> PipelineState:
    a = state.point.arrays
    out: dict[str, Any] = {}
    for key, spec in how.items():
        name = key.replace("__", ".")
        if not isinstance(spec, str):
            out[key] = spec
            continue
        v = np.array(a[name], copy=True)
        if spec == "nan":
            v.flat[7] = np.nan
        elif spec == "inf":
            v[0] = np.inf
        elif spec == "short":
            v = v[:, :, :4]
        elif spec == "float":
            v = v.astype(float)
        elif spec == "half":
            v[0] = v[0] / 2
        elif spec == "dup":
            ids = unpack_strings(a["tracks.ids.utf8"], a["tracks.ids.len"], "t")
            utf8, v = pack_strings([ids[0], *ids[:-1]])
            out["tracks__ids__utf8"] = utf8
        elif spec == "cut":
            v = v[:-1]
        elif spec == "skew":
            v[0, 0, 1] += 1.0
        elif spec == "singular":
            v[0] = [[1.0, 1.0], [1.0, 1.0]]
        elif spec == "late":
            v[0] = 1e9 if v.dtype.kind == "f" else 2**40
        elif spec == "more":
            v[0] = a["tracks.hits"][0] + 1
        elif spec == "seen":
            v[0, 2] = v[0, 1] + 1.0
        out[key] = v
    return changed(state, **out)


@pytest.mark.parametrize(
    ("how", "text"), [d[1:] for d in SECTION_DEFECTS], ids=[d[0] for d in SECTION_DEFECTS]
)
def test_a_bad_section_is_refused_and_changes_nothing(
    scans: list[Scan], how: dict[str, Any], text: str
) -> None:
    state = _defect(saved(scans), how)
    state, _ = decode_state(encode_state(state))  # through the bytes, as from a file
    p = TrackingPipeline()
    for s in scans[:3]:
        p.process(s)
    before, last = tracks_of(p), p.last_time
    with pytest.raises(StateError, match=text):
        p.import_state(state)
    assert tracks_of(p) == before and p.last_time == last
    p.process(scans[3])  # and it goes on


def test_another_point_tracker_or_an_unknown_peer_is_refused(scans: list[Scan]) -> None:
    state = saved(scans)
    other = PipelineState(state.last_time, "mht", state.point, {})
    with pytest.raises(StateError, match="'mht'"):
        TrackingPipeline().import_state(other)
    with_peer = PipelineState(state.last_time, "individual", state.point, {"extended": state.point})
    with pytest.raises(StateError, match="peer 'extended'"):
        TrackingPipeline().import_state(with_peer)
    early = PipelineState(1.0, "individual", state.point, {})
    with pytest.raises(StateError, match="is after"):
        TrackingPipeline().import_state(early)


# -- peers ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class _CounterCheckpoint:
    count: int
    history: np.ndarray

    def export(self) -> StateSection:
        return StateSection({"count": self.count}, {"history": self.history})


class CountingPeer:
    """A peer that claims nothing and keeps the times of the scans it committed."""

    kind = "counter"

    def __init__(self) -> None:
        self.history = np.zeros(0)

    def propose(self, scan: Scan, view: PointTrackView) -> PeerProposal:
        return PeerProposal(
            claimed=np.zeros(scan.size, dtype=bool), state=np.append(self.history, scan.time)
        )

    def commit(self, proposal: PeerProposal) -> None:
        self.history = proposal.state

    def snapshot(self) -> tuple[TrackSnapshot, ...]:
        return ()

    def reconfigure(self, config: TrackerConfig) -> None:
        pass

    def checkpoint(self) -> _CounterCheckpoint:
        return _CounterCheckpoint(len(self.history), self.history)

    def check_state(self, section: StateSection) -> np.ndarray:
        h = np.asarray(section.arrays.get("history"))
        if h.shape != (section.values.get("count"),):
            raise StateError("counter: history and count differ")
        return h

    def restore_state(self, checked: np.ndarray) -> None:
        self.history = checked


class PlainPeer(CountingPeer):
    """The same without the persistence methods."""

    kind = "plain"
    checkpoint = check_state = restore_state = None  # type: ignore[assignment]


def test_each_peer_kind_has_a_section_of_its_own(scans: list[Scan]) -> None:
    assert isinstance(CountingPeer(), PersistentTracker)
    assert not isinstance(PlainPeer(), PersistentTracker)
    p = TrackingPipeline(peers=[CountingPeer(), PlainPeer()])
    for s in scans[:5]:
        p.process(s)
    state, _ = decode_state(encode_state(p.export_state()))
    assert set(state.peers) == {"counter"}  # a peer that cannot be saved is left out
    assert state.peers["counter"].arrays["history"].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    q = TrackingPipeline(peers=[CountingPeer(), PlainPeer()])
    q.import_state(state)
    assert q.peers[0].history.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]  # type: ignore[attr-defined]
    assert tracks_of(q) == tracks_of(p)
    # a peer's bad section changes no tracker, the point tracker included
    bad = PipelineState(
        state.last_time,
        state.point_kind,
        state.point,
        {"counter": StateSection({"count": 9}, {"history": np.zeros(2)})},
    )
    r = TrackingPipeline(peers=[CountingPeer()])
    with pytest.raises(StateError, match="counter"):
        r.import_state(bad)
    assert r.snapshot() == () and r.last_time is None


def test_the_learned_coverage_is_saved_with_the_tracks() -> None:
    """Two radars, no coverage stated: the boxes learned of each are in the state, come
    back with it, and a file without them (written before they were saved) still loads."""
    from clients.scenarios.formation import environment_2, simulate_formations

    sims = simulate_formations(environment_2(1, 2, seed=0, scans=6))
    a = TrackingPipeline()
    for s in sims:
        a.process(s.to_scan())
    state = a.export_state()
    sensors = state.learned["coverage"].values["sensors"]
    assert sorted(s["id"] for s in sensors) == ["radar-1", "radar-2", "radar-3"]
    b = restarted(a)
    assert b.export_state().learned["coverage"].values == state.learned["coverage"].values
    old = PipelineState(state.last_time, state.point_kind, state.point, state.peers)
    c = TrackingPipeline()
    c.import_state(decode_state(encode_state(old))[0])
    assert c.export_state().learned["coverage"].values == {"sensors": []}
    bad = PipelineState(
        state.last_time,
        state.point_kind,
        state.point,
        state.peers,
        {"coverage": StateSection({"sensors": [{"id": 1}]}, {})},
    )
    with pytest.raises(StateError, match=r"coverage\.sensors\[0\]"):
        TrackingPipeline().import_state(bad)
