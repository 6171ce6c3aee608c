"""The selector filters of the state queryable (the session itself is exercised by the
integration tests)."""

from __future__ import annotations

import pytest

from service.zenoh_io import parse_selector_filters


@pytest.mark.parametrize(
    ("parameters", "expected"),
    [
        ("", ("confirmed", None)),
        ("status=all", ("all", None)),
        ("status=tentative;kind=individual,extended", ("tentative", {"individual", "extended"})),
        ("kind=formation&status=confirmed", ("confirmed", {"formation"})),
        ("other=1", ("confirmed", None)),
    ],
)
def test_selector_filters(parameters: str, expected: tuple[str, set[str] | None]) -> None:
    assert parse_selector_filters(parameters) == expected


def test_selector_filters_refuse_an_unknown_status() -> None:
    with pytest.raises(ValueError, match="status: one of confirmed, tentative, all, got 'bogus'"):
        parse_selector_filters("status=bogus")


@pytest.mark.parametrize("kind", ["bogus", "Extended", "individual,points"])
def test_selector_filters_refuse_an_unknown_kind(kind: str) -> None:
    """An unknown kind matched no track, silently (a newcomer's ``kind=Extended``)."""
    with pytest.raises(ValueError, match="kind: each one of individual, extended, formation"):
        parse_selector_filters(f"kind={kind}")
