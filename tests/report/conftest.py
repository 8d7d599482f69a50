"""The report tests' shared fixture: one headless Chromium per test process."""

from __future__ import annotations

import pytest

from tests.report.chromium import Browser


@pytest.fixture(scope="session")
def browser():
    b = Browser()
    yield b
    b.close()
