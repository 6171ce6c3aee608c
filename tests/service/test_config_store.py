"""The configuration document: validation as a whole, JSON merge patch, the store's accept and
hand-over to the worker, and atomic saving."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import orjson
import pytest

from service.config_store import (
    ConfigStore,
    config_changes,
    load_config_file,
    merge_patch,
    save_config_file,
)
from service.config_tree import ConfigError, config_document, validate_config_document
from service.schemas import IngestConfig
from trackers.config import TrackerConfig


def test_validate_takes_defaults_and_names_the_field() -> None:
    defaults = IngestConfig(reorder_window=2.0)
    tracker, ingest = validate_config_document({}, defaults)
    assert tracker == TrackerConfig() and ingest == defaults
    _, ingest = validate_config_document({"ingest": {"max_time_jump": 5.0}}, defaults)
    assert (ingest.max_time_jump, ingest.reorder_window) == (5.0, 2.0)
    with pytest.raises(ConfigError, match=r"^config: expected a JSON object"):
        validate_config_document([], defaults)
    with pytest.raises(ConfigError, match=r"^ingest: not an object"):
        validate_config_document({"ingest": 3}, defaults)
    with pytest.raises(ConfigError, match=r"^ingest\.max_detections_per_batch"):
        validate_config_document({"ingest": {"max_detections_per_batch": 0}}, defaults)
    with pytest.raises(ConfigError, match=r"track_management\.pd"):
        validate_config_document({"track_management": {"pd": 2}}, defaults)


def test_store_accepts_saves_and_hands_over_once(tmp_path: Path) -> None:
    path = tmp_path / "sub" / "tracker.json"
    store = ConfigStore(TrackerConfig(), IngestConfig(), ingest_defaults=IngestConfig(), path=path)
    assert store.take_pending() is None
    assert store.document() == config_document(TrackerConfig(), IngestConfig())
    doc = store.patch({"gating": {"gate_probability": 0.999}})
    assert store.document() == doc == orjson.loads(path.read_bytes())
    assert store.tracker.gating.gate_probability == 0.999
    doc = store.patch({"ingest": {"reorder_window": 1.0}})
    pending = store.take_pending()  # the latest accepted, once
    assert pending == (store.tracker, store.ingest) and pending[1].reorder_window == 1.0
    assert store.take_pending() is None
    saved = path.read_bytes()
    with pytest.raises(ConfigError, match="config patch: expected a JSON object"):
        store.patch([1])
    with pytest.raises(ConfigError, match=r"ingest\.reorder_window"):
        store.replace({"ingest": {"reorder_window": -1}})
    assert path.read_bytes() == saved and store.document() == doc
    assert store.take_pending() is None


def test_a_store_that_cannot_save_changes_nothing(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    store = ConfigStore(
        TrackerConfig(), IngestConfig(), ingest_defaults=IngestConfig(), path=blocker / "x.json"
    )
    with pytest.raises(OSError, match="could not save"):
        store.patch({"gating": {"gate_probability": 0.999}})
    assert store.document() == config_document(TrackerConfig(), IngestConfig())
    assert store.take_pending() is None


def test_save_is_atomic_and_leaves_no_temporary_file(tmp_path: Path) -> None:
    path = tmp_path / "tracker.json"
    save_config_file(path, {"a": 1})
    save_config_file(path, {"a": 2})
    assert orjson.loads(path.read_bytes()) == {"a": 2}
    assert os.listdir(tmp_path) == ["tracker.json"]
    with pytest.raises(TypeError):  # not serialisable: the old file stays, no temporary file
        save_config_file(path, {"a": object()})
    assert orjson.loads(path.read_bytes()) == {"a": 2}
    assert os.listdir(tmp_path) == ["tracker.json"]


def test_load_config_file(tmp_path: Path) -> None:
    path = tmp_path / "tracker.json"
    assert load_config_file(path, IngestConfig()) is None
    path.write_text("{nope")
    with pytest.raises(ConfigError, match=r"config file .*tracker\.json: not JSON"):
        load_config_file(path, IngestConfig())
    path.write_text('{"track_management": {"pd": 7}}')
    with pytest.raises(ConfigError, match=r"config file .*tracker\.json: .*track_management\.pd"):
        load_config_file(path, IngestConfig())
    save_config_file(path, {"measurement": {"position_std": 3.0}})
    loaded = load_config_file(path, IngestConfig())
    assert loaded is not None and loaded[0].measurement.position_std == 3.0


def test_merge_patch() -> None:
    assert merge_patch({"a": {"b": 1, "c": 2}}, {"a": {"b": None, "d": 3}}) == {
        "a": {"c": 2, "d": 3}
    }
    assert merge_patch({"a": 1}, {"a": [1, 2]}) == {"a": [1, 2]}


def test_config_changes_name_each_changed_field() -> None:
    old = {"motion": {"q_cv": 0.5, "models": ["cv", "ct"]}, "gating": {"gate_probability": 0.9}}
    new = {"motion": {"q_cv": 1.0, "models": ["cv"]}, "gating": {"gate_probability": 0.9}}
    assert config_changes(old, new) == [
        "motion.q_cv 0.5 -> 1.0",
        'motion.models ["cv","ct"] -> ["cv"]',
    ]
    assert config_changes(old, old) == []
    assert config_changes({"a": {"b": 1}}, {"a": {}, "c": "x"}) == [
        "a (none) -> {}",
        "c (none) -> x",
        "a.b 1 -> (none)",
    ]


def test_apply_says_what_changed_and_where_it_was_saved(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "config.json"
    store = ConfigStore(TrackerConfig(), IngestConfig(), ingest_defaults=IngestConfig(), path=path)
    with caplog.at_level(logging.INFO, logger="service.config"):
        applied = store.apply({"motion": {"q_cv": 1.0}}, merge=True)
    assert applied.changes == ("motion.q_cv 0.5 -> 1.0",) and applied.saved_to == path
    assert applied.document == store.document() == orjson.loads(path.read_bytes())
    assert f"configuration applied: motion.q_cv 0.5 -> 1.0; saved to {path}" in caplog.text
    # PUT of the defaults puts it back; the same again changes nothing
    applied = store.apply(config_document(TrackerConfig(), IngestConfig()))
    assert applied.changes == ("motion.q_cv 1.0 -> 0.5",)
    assert store.apply({}, merge=True).summary() == f"nothing changed; saved to {path}"
    unsaved = ConfigStore(TrackerConfig(), IngestConfig(), ingest_defaults=IngestConfig())
    applied = unsaved.apply({"gating": {"gate_probability": 0.99}}, merge=True)
    assert applied.summary() == "gating.gate_probability 0.9999 -> 0.99; not saved"
