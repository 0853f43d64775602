"""The browser client's tests: the service's real server and one headless Chromium (tests/service/conftest.py)."""

from service.conftest import CHROMIUM, SOFTWARE_WEBGL, chromium, live_server  # noqa: F401 (live_server: a fixture)

__all__ = ["CHROMIUM", "SOFTWARE_WEBGL", "chromium"]
