"""Fixtures of the service tests: simulated scans, a report sink that keeps what it gets, and a
running engine publishing to it."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from clients.scenarios.multitarget import reference_scenario, simulate
from service.engine import Engine

from .helpers import ListSink


@pytest.fixture(scope="module")
def scans() -> list[Any]:
    return simulate(reference_scenario(3))


@pytest.fixture
def sink() -> ListSink:
    return ListSink()


@pytest.fixture
def engine(sink: ListSink) -> Iterator[Engine]:
    eng = Engine(sink=sink)
    eng.start()
    try:
        yield eng
    finally:
        eng.stop()
