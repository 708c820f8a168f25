"""Only the latest request is answered: while a slow answer is being computed, newer requests
replace the one waiting, so dragging never builds a queue.
"""

from __future__ import annotations

import threading
import traceback
from typing import Any, Callable


class Latest:
    """A one-slot mailbox and the thread that empties it. :meth:`put` leaves a request and
    returns at once; the thread takes the newest one waiting, answers it with ``answer`` and
    hands ``(request, result)`` to ``done`` (an exception raised by ``answer`` is handed over as
    the result). ``dropped`` counts the requests replaced before their turn.
    """

    def __init__(self, answer: Callable[[Any], Any], done: Callable[[Any, Any], None]):
        self._answer, self._done = answer, done
        self._wake = threading.Condition()
        self._waiting: Any = None
        self._has, self._closed, self._busy = False, False, False
        self.answered = self.dropped = 0
        self._thread = threading.Thread(target=self._run, name="stmpl-answers", daemon=True)
        self._thread.start()

    def put(self, request: Any) -> None:
        """Leave ``request``, replacing any request still waiting."""
        with self._wake:
            if self._closed:
                raise RuntimeError("the mailbox is closed")
            self.dropped += int(self._has)
            self._waiting, self._has = request, True
            self._wake.notify()

    def idle(self, timeout: float | None = None) -> bool:
        """Wait until nothing is waiting or being answered; ``False`` on timeout."""
        with self._wake:
            return self._wake.wait_for(lambda: not self._has and not self._busy, timeout)

    def close(self) -> None:
        """Answer nothing more; the request being answered finishes."""
        with self._wake:
            self._closed = True
            self._wake.notify_all()
        self._thread.join(timeout=5)

    def _run(self) -> None:
        while True:
            with self._wake:
                self._wake.wait_for(lambda: self._has or self._closed)
                if self._closed:
                    return
                request, self._waiting, self._has, self._busy = self._waiting, None, False, True
            try:
                result = self._answer(request)
            except Exception as e:  # handed to done: the page says what went wrong
                e.trace = traceback.format_exc()
                result = e
            try:
                self._done(request, result)
            finally:
                with self._wake:
                    self._busy = False
                    self.answered += 1
                    self._wake.notify_all()
