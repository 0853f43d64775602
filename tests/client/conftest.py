"""The browser client's fixtures: the service's real server (``tests/service/conftest.py``). Every module here
drives a headless Chromium (``helpers/browser.py``) and marks itself ``pytestmark = needs_chromium``."""

from service.conftest import live_server  # noqa: F401 (a fixture)
