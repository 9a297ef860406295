"""The dashboard's browser tests: Debian's Chromium driven by Playwright, headless.

Needs /usr/bin/chromium (``make browser``, or ``apt-get install chromium``; another path in
``ECTSKIN_CHROMIUM``); Playwright is never asked to download a browser. Outside CI a machine
without them skips these tests; in CI (``CI`` set, as every CI service does) they FAIL instead: a
skip there would silently drop the only tests of the page.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

CHROMIUM = Path(os.environ.get("ECTSKIN_CHROMIUM", "/usr/bin/chromium"))
IN_CI = os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")
#: the flags the machine's notes ask for: no sandbox (a container), no GPU, no network chatter
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"]


def _unavailable(why: str) -> None:
    """Skip on a developer machine; fail in CI, where a skip would go unnoticed."""
    if IN_CI:
        pytest.fail(f"{why}: the dashboard's browser test must run in CI (CI is set)", pytrace=False)
    pytest.skip(why)


@pytest.fixture
def chromium():
    """A launched headless Chromium (Playwright's ``Browser``), closed afterwards."""
    if not CHROMIUM.exists():
        _unavailable(f"{CHROMIUM} is not installed (make browser)")
    try:
        from playwright import sync_api
    except ImportError:
        _unavailable("playwright is not installed (pip install -e '.[dev]')")
    try:
        import fastapi  # noqa: F401
    except ImportError:
        _unavailable("fastapi is not installed (pip install -e '.[live]')")
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            browser.close()
