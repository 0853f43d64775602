"""The one way the service says no: :class:`Refusal`, a message in one line, the HTTP status it answers with, and
when it is worth asking again. Every door raises it; one exception handler (``app.py``) answers it over REST,
and the walk-through sends it as its one error line."""

from __future__ import annotations


class Refusal(Exception):
    """A request the server does not take as asked, in one line.

    status : the HTTP status (404 an unknown name, 422 a request the painting cannot take, 503 no room for now,
    507 no disk); retry_after : seconds until asking again may succeed, None when it would not (as asked)."""

    def __init__(self, message: str, status: int = 422, retry_after: int | None = None):
        super().__init__(message)
        self.message = message
        self.status = status
        self.retry_after = retry_after

    def headers(self) -> dict[str, str] | None:
        """The answer's headers: ``Retry-After`` when there is a time to try again."""
        return None if self.retry_after is None else {"Retry-After": str(self.retry_after)}
