"""The configuration tree: one typed, validated document for every tracker and the ingest.

The tracker's sections are written once, in ``trackers/config.py`` (frozen dataclasses with
defaults, descriptions and range checks, free of pydantic). This module derives their
pydantic models from those dataclasses, so that the REST document, its OpenAPI schema and the
configuration file all follow them: a section or field added there appears here with its
type, default and description, and nothing is written twice. ``ingest`` (how the service
takes batches in) is the service's own section (:class:`service.schemas.IngestConfig`).

Validation is in two steps, both at the edge: the document's shape and types (pydantic,
strict: a number is never a string or a boolean, unknown fields are refused), then the
dataclasses' own range and consistency checks. Either failure is a :class:`ConfigError`
naming the field, and nothing is built.
"""

from __future__ import annotations

import dataclasses
from functools import cache
from typing import Annotated, Any, Literal, get_args, get_origin, get_type_hints

from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, create_model

from service.schemas import IngestConfig, format_validation_error
from trackers.config import TrackerConfig

__all__ = [
    "ConfigDocument",
    "ConfigError",
    "ConfigPatch",
    "check_patch",
    "config_document",
    "section_model",
    "to_tracker_config",
    "validate_config_document",
]


class ConfigError(ValueError):
    """An invalid configuration document; the message starts with the field path."""


def _annotation(hint: Any, meta: Any) -> Any:
    """The strict pydantic type of a dataclass field's type hint, with the field's bounds or
    allowed values (its ``metadata``) on the number or on each item of a list."""
    bounds = {k: meta[k] for k in ("gt", "ge", "lt", "le") if k in meta}
    choices = meta.get("choices")
    if hint is bool:
        return Annotated[bool, Strict()]
    if hint is float:
        return Annotated[float, Strict(), Field(allow_inf_nan=False, **bounds)]
    if hint is int:
        return Annotated[int, Strict(), Field(**bounds)]
    if hint is str:
        return Literal[choices] if choices else Annotated[str, Strict()]  # type: ignore[valid-type]
    if get_origin(hint) is dict:  # name -> value (point_patterns.patterns)
        key = Annotated[str, Strict(), Field(min_length=1, max_length=meta.get("name_length", 64))]
        value = _annotation(get_args(hint)[1], meta)
        return Annotated[dict[key, value], Field(max_length=meta.get("max_items"))]  # type: ignore[valid-type]
    if get_origin(hint) is tuple and get_args(hint)[-1] is not Ellipsis:  # fixed: (x, y)
        args = get_args(hint)
        items = _annotation(args[0], {})
        return Annotated[
            list[items],  # type: ignore[valid-type]
            Field(min_length=len(args), max_length=len(args)),
        ]
    if get_origin(hint) is tuple:
        item = _annotation(get_args(hint)[0], meta)
        fewest, most = meta.get("length", (0, None))
        # A list of names names each once.
        extra = {"uniqueItems": True} if meta.get("choices") else None
        return Annotated[
            list[item],  # type: ignore[valid-type]
            Field(min_length=fewest, max_length=most, json_schema_extra=extra),
        ]
    if dataclasses.is_dataclass(hint):
        return section_model(hint)  # type: ignore[arg-type]
    raise TypeError(f"no wire type for configuration field type {hint!r}")


@cache
def section_model(cls: type) -> type[BaseModel]:
    """The pydantic model of a configuration dataclass: same fields, types, defaults and
    descriptions; unknown fields refused."""
    hints = get_type_hints(cls)
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        ann = _annotation(hints[f.name], f.metadata)
        desc = f.metadata.get("description")
        if dataclasses.is_dataclass(hints[f.name]):
            fields[f.name] = (ann, Field(default_factory=ann, description=desc))
        else:
            if f.default_factory is not dataclasses.MISSING:  # a mapping, empty by default
                fields[f.name] = (ann, Field(default=f.default_factory(), description=desc))
                continue
            default = f.default
            if isinstance(default, tuple):
                default = list(default)
            fields[f.name] = (ann, Field(default=default, description=desc))
    doc = (cls.__doc__ or "").strip() or None
    return create_model(  # type: ignore[call-overload,no-any-return]
        cls.__name__.removesuffix("Config") + "Section",
        __config__=ConfigDict(extra="forbid"),
        __doc__=doc,
        **fields,
    )


def _document_model() -> type[BaseModel]:
    tracker = section_model(TrackerConfig)
    fields: dict[str, Any] = {}
    for name, info in tracker.model_fields.items():
        model = info.annotation
        fields[name] = (model, Field(default_factory=model, description=info.description))
    fields["ingest"] = (
        IngestConfig,
        Field(default_factory=IngestConfig, description=IngestConfig.__doc__),
    )
    return create_model(  # type: ignore[call-overload,no-any-return]
        "ConfigDocument",
        __config__=ConfigDict(extra="forbid"),
        __doc__=(
            "The configuration document: the trackers' sections and `ingest`. PUT replaces "
            "it (missing fields take their defaults), PATCH merges into it (JSON merge "
            "patch: `null` resets a field)."
        ),
        **fields,
    )


#: The whole configuration document (REST body, OpenAPI schema, configuration file).
ConfigDocument = _document_model()


def _patch_model(model: type[BaseModel], name: str) -> type[BaseModel]:
    """The JSON merge patch of ``model``: every field optional and nullable (``null`` resets
    it to its default), sections patched field by field."""
    fields: dict[str, Any] = {}
    for fname, info in model.model_fields.items():
        ann = info.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            ann = _patch_model(ann, ann.__name__ + "Patch")
            typ: Any = ann | None
        elif get_origin(ann) is dict:  # a mapping merges by name; a name's null removes it
            key, value = get_args(ann)
            typ = Annotated[dict[key, value | None] | None, *info.metadata]  # type: ignore[valid-type]
        else:
            typ = Annotated[ann | None, *info.metadata] if info.metadata else ann | None
        fields[fname] = (typ, Field(default=None, description=info.description))
    return create_model(  # type: ignore[call-overload,no-any-return]
        name,
        __config__=ConfigDict(extra="forbid"),
        __doc__=(model.__doc__ or "") + "\n\nA JSON merge patch: `null` resets a field.",
        **fields,
    )


#: The body of ``PATCH /api/v1/config``: any part of the document; ``null`` resets a field.
ConfigPatch = _patch_model(ConfigDocument, "ConfigPatch")


def to_tracker_config(doc: BaseModel) -> TrackerConfig:
    """The tracker's configuration from a validated document; its range checks raise
    :class:`ConfigError` naming the field."""
    try:
        return TrackerConfig.from_dict(doc.model_dump(exclude={"ingest"}))
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def validate_config_document(
    doc: Any, ingest_defaults: IngestConfig | None = None
) -> tuple[TrackerConfig, IngestConfig]:
    """Check a whole document; missing fields take their defaults (those of ``ingest`` from
    ``ingest_defaults``, the service's settings). Raises :class:`ConfigError`."""
    if not isinstance(doc, dict):
        raise ConfigError("config: expected a JSON object")
    if ingest_defaults is not None:
        ingest = doc.get("ingest", {})
        if isinstance(ingest, dict):  # anything else: refused below, naming the field
            doc = {**doc, "ingest": {**ingest_defaults.model_dump(), **ingest}}
    try:
        model = ConfigDocument.model_validate(doc)
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc)) from None
    return to_tracker_config(model), model.ingest  # type: ignore[attr-defined]


def check_patch(patch: Any) -> None:
    """Raise :class:`ConfigError` unless ``patch`` fits :data:`ConfigPatch`: known fields only
    (``null`` included), each of its type and within its bounds. The merged document is then
    validated as a whole."""
    if not isinstance(patch, dict):
        raise ConfigError("config patch: expected a JSON object")
    try:
        ConfigPatch.model_validate(patch)
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc)) from None


def config_document(tracker: TrackerConfig, ingest: IngestConfig) -> dict[str, Any]:
    """The document of a configuration: the tracker's sections plus ``ingest``."""
    doc = tracker.to_dict()
    doc["ingest"] = ingest.model_dump()
    return doc
