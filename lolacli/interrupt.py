"""Stopping on Ctrl-C (SIGINT) and SIGTERM, in one place.

:func:`stop_signals` installs handlers for both signals for the time of a ``with`` block
and puts the previous ones back when it ends, however it ends; nothing else in lolacli
calls :func:`signal.signal`, so importing or calling the library never leaves a handler
behind. The CLI wraps every command in it.

A signal raises :class:`Interrupted` (a :class:`KeyboardInterrupt`, so code that lets
Ctrl-C through lets both through) at once, except inside :meth:`Stop.polled`: there the
first signal only sets :attr:`Stop.signum` and the code polls the :class:`Stop` (it is a
``should_stop`` callable) at points where its state is whole (between cycles, between
frames), so that what it made so far can still be reported. A second signal raises
anyway. The exit code of a stop is 128 + the signal: 130 for SIGINT, 143 for SIGTERM.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """Stopped by ``signum``; :attr:`exit_code` is 128 + ``signum``."""

    def __init__(self, signum: int = signal.SIGINT) -> None:
        self.signum = signum
        self.exit_code = 128 + signum
        super().__init__(f"stopped by {signal.Signals(signum).name}")


def exit_code(exc: BaseException) -> int:
    """The exit code for a stop: 143 after SIGTERM, else 130."""
    return getattr(exc, "exit_code", 128 + signal.SIGINT)


class Stop:
    """What :func:`stop_signals` yields: whether a stop was asked for, and by which
    signal; call it (``should_stop``) to poll."""

    def __init__(self) -> None:
        self.signum: int | None = None
        self._polling = 0

    def __call__(self) -> bool:
        return self.signum is not None

    @property
    def exit_code(self) -> int:
        return 128 + (self.signum or signal.SIGINT)

    @contextmanager
    def polled(self) -> Iterator[Stop]:
        """Inside: the first signal sets :attr:`signum` and does not raise; the code polls
        the Stop. Already stopped when entered: raises at once."""
        if self.signum is not None:
            raise Interrupted(self.signum)
        self._polling += 1
        try:
            yield self
        finally:
            self._polling -= 1

    def handle(self, signum: int, _frame: FrameType | None) -> None:
        first = self.signum is None
        if first:
            self.signum = signum
        if not (first and self._polling):
            raise Interrupted(signum)

    def raise_if_stopped(self) -> None:
        if self.signum is not None:
            raise Interrupted(self.signum)


@contextmanager
def stop_signals() -> Iterator[Stop]:
    """SIGINT and SIGTERM handled by a :class:`Stop` inside the block, the previous
    handlers back after it. Outside the main thread (where Python delivers no signals)
    the Stop is never set and nothing is installed."""
    stop = Stop()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    previous = {s: signal.getsignal(s) for s in SIGNALS}
    try:
        for s in SIGNALS:
            signal.signal(s, stop.handle)
        yield stop
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)


def never() -> bool:
    """A ``should_stop`` that never asks to stop."""
    return False


__all__ = ["SIGNALS", "Interrupted", "Stop", "exit_code", "never", "stop_signals"]
