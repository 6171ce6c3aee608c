"""The configuration tree: the document's models derived from the tracker's dataclasses, strict
validation naming the field, and the round trip through the document, the file and the
settings."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, get_type_hints

import pytest

from service.config_store import ConfigStore, load_config_file
from service.config_tree import (
    ConfigDocument,
    ConfigError,
    config_document,
    validate_config_document,
)
from service.schemas import IngestConfig
from service.settings import load_settings
from trackers.config import TrackerConfig


def _leaves(cls: type, prefix: str = "") -> list[tuple[str, dataclasses.Field[Any]]]:
    hints = get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        if dataclasses.is_dataclass(hints[f.name]):
            out.extend(_leaves(hints[f.name], f"{prefix}{f.name}."))  # type: ignore[arg-type]
        else:
            out.append((prefix + f.name, f))
    return out


def _schema_of(schema: dict[str, Any], path: str) -> dict[str, Any]:
    defs = schema["$defs"]
    node = schema
    for part in path.split("."):
        node = node["properties"][part]
        if "$ref" in node:
            node = defs[node["$ref"].rsplit("/", 1)[1]]
    return node


JSON_BOUNDS = {"gt": "exclusiveMinimum", "ge": "minimum", "lt": "exclusiveMaximum", "le": "maximum"}


def test_every_tracker_field_is_in_the_document_schema_with_its_default_and_description():
    """...and its bounds: every number has them, so that a configuration that validates is one
    the tracker can run."""
    schema = ConfigDocument.model_json_schema()
    leaves = _leaves(TrackerConfig)
    assert len(leaves) > 20
    for path, f in leaves:
        node = _schema_of(schema, path)
        default = list(f.default) if isinstance(f.default, tuple) else f.default
        if f.default_factory is not dataclasses.MISSING:  # a mapping
            default = f.default_factory()
        assert node["default"] == default, path
        assert node["description"] == f.metadata["description"], path
        number = node.get("items", node)
        for key, js in JSON_BOUNDS.items():
            if key in f.metadata:
                assert number[js] == f.metadata[key], (path, key)
        if node.get("type") in ("number", "integer") or "items" in node:
            assert any(k in f.metadata for k in JSON_BOUNDS) or "choices" in f.metadata, path
    assert _schema_of(schema, "initiation.method")["enum"] == ["two_point", "single_point"]
    assert _schema_of(schema, "ingest.reorder_window")["default"] == 0.0


def test_the_empty_document_is_the_default_configuration():
    tracker, ingest = validate_config_document({})
    assert tracker == TrackerConfig() and ingest == IngestConfig()
    assert validate_config_document(config_document(tracker, ingest)) == (tracker, ingest)


@pytest.mark.parametrize(
    ("doc", "field", "text"),
    [
        ({"motion": {"q_cv": "1.0"}}, "motion.q_cv", "number"),
        ({"motion": {"q_cv": True}}, "motion.q_cv", "number"),
        ({"motion": {"q_cv": -1}}, "motion.q_cv", "> 0"),
        ({"motion": {"q_cv": float("inf")}}, "motion.q_cv", "finite"),
        ({"motion": {"sojourn_times": 30.0}}, "motion.sojourn_times", ""),
        ({"motion": {"models": ["cv"]}}, "motion.sojourn_times", "one per model"),
        ({"initiation": {"method": "three_point"}}, "initiation.method", "two_point"),
        (
            {"initiation": {"max_pairs_per_candidate": 2.5}},
            "initiation.max_pairs_per_candidate",
            "",
        ),
        ({"initiation": {"max_pairs_per_candidate": 0}}, "initiation.max_pairs_per_candidate", ""),
        ({"association": {"method": "jpda"}}, "association.method", "gnn"),
        ({"gating": {"gate_probability": 1.0}}, "gating.gate_probability", "<= 0.999999999999"),
        ({"measurement": {"position_std": 1e200}}, "measurement.position_std", "<= 100000"),
        ({"motion": {"q_cv": 1e300}}, "motion.q_cv", "<= 10000"),
        ({"gating": {"unknown": 1.0}}, "gating.unknown", "unknown"),
        ({"tracks": {}}, "tracks", "unknown"),
        ({"ingest": {"reorder_window": -1}}, "ingest.reorder_window", ""),
        ({"ingest": []}, "ingest", ""),
        ([], "config", "object"),
    ],
)
def test_bad_documents_are_refused_naming_the_field(doc, field, text):
    with pytest.raises(ConfigError) as err:
        validate_config_document(doc, IngestConfig())
    assert str(err.value).startswith(field), str(err.value)
    assert text in str(err.value)


def test_integers_are_numbers_and_lists_are_tuples():
    tracker, _ = validate_config_document(
        {"motion": {"q_cv": 1, "sojourn_times": [20, 5]}, "initiation": {"max_speed": 300}}
    )
    assert tracker.motion.q_cv == 1.0 and isinstance(tracker.motion.q_cv, float)
    assert tracker.motion.sojourn_times == (20.0, 5.0)
    assert tracker == TrackerConfig().merged(
        {"motion": {"q_cv": 1.0, "sojourn_times": [20.0, 5.0]}, "initiation": {"max_speed": 300}}
    )


def test_round_trip_through_the_store_and_its_file(tmp_path: Path):
    path = tmp_path / "config.json"
    store = ConfigStore(TrackerConfig(), IngestConfig(), ingest_defaults=IngestConfig(), path=path)
    doc = store.patch({"motion": {"q_ct": 3}, "ingest": {"reorder_window": 1.5}})
    assert doc["motion"]["q_ct"] == 3.0 and doc["ingest"]["reorder_window"] == 1.5
    loaded = load_config_file(path, IngestConfig())
    assert loaded == (store.tracker, store.ingest)
    assert config_document(*loaded) == doc
    with pytest.raises(ConfigError):
        store.patch({"motion": {"q_ct": "3"}})
    with pytest.raises(ConfigError, match="nonsense"):  # null removes a field, but a known one
        store.patch({"nonsense": None})
    assert load_config_file(path, IngestConfig()) == loaded  # the file did not change


def test_a_bad_file_is_refused_naming_the_file_and_the_field(tmp_path: Path):
    path = tmp_path / "config.json"
    path.write_text('{"initiation": {"max_speed": "fast"}}')
    with pytest.raises(ConfigError, match=r"config\.json: initiation\.max_speed"):
        load_config_file(path, IngestConfig())


def test_the_settings_defaults_of_the_ingest_section_are_the_documents():
    settings = load_settings([])
    for name, info in IngestConfig.model_fields.items():
        assert getattr(settings, name) == info.default, name
    # A setting changes the default of the document's field; the document still wins.
    ingest_defaults = IngestConfig(
        reorder_window=load_settings(["--reorder-window", "2"]).reorder_window
    )
    assert validate_config_document({}, ingest_defaults)[1].reorder_window == 2.0
    doc = {"ingest": {"reorder_window": 0.5}}
    assert validate_config_document(doc, ingest_defaults)[1].reorder_window == 0.5
