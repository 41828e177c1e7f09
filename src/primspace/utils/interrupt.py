"""Ctrl-C deferred to a safe point: :func:`deferred_interrupt` and :class:`Interrupted`.

A loop whose state is consistent only between its steps (a training epoch: the weights, the
optimiser and the random generators move together) asks for the first SIGINT to be noted
instead of raised; the loop checks the note after each step, saves what it must and raises
:class:`Interrupted`. A second Ctrl-C raises :class:`KeyboardInterrupt` at once, as usual.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator

__all__ = ["Interrupted", "StopRequest", "deferred_interrupt"]


class Interrupted(KeyboardInterrupt):
    """Ctrl-C, handled: the message says what was saved and how to continue (the command line
    prints it as its one line, exit 130)."""


class StopRequest:
    """Whether Ctrl-C was pressed inside :func:`deferred_interrupt` (:attr:`requested`)."""

    def __init__(self) -> None:
        self.requested = False


@contextlib.contextmanager
def deferred_interrupt(then: str, *, enabled: bool = True) -> Iterator[StopRequest]:
    """Note the first Ctrl-C (SIGINT) instead of raising it; yield the :class:`StopRequest`.

    On the first Ctrl-C one line goes to stderr (``then``: what happens next, e.g. "stopping
    after this epoch") and Python's own handler comes back, so a second Ctrl-C raises
    :class:`KeyboardInterrupt` where the code stands. The handler is installed only where
    Python's default one is in place and this is the main thread (elsewhere, and with
    ``enabled`` False, Ctrl-C raises as usual and :attr:`StopRequest.requested` stays False);
    the previous handler is restored on exit.
    """
    request = StopRequest()
    usable = (
        enabled
        and threading.current_thread() is threading.main_thread()
        and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    )
    if not usable:
        yield request
        return

    def note(signum, frame) -> None:
        request.requested = True
        signal.signal(signal.SIGINT, signal.default_int_handler)
        print(f"\nCtrl-C: {then} (Ctrl-C again to stop at once)", file=sys.stderr, flush=True)

    signal.signal(signal.SIGINT, note)
    try:
        yield request
    finally:
        if signal.getsignal(signal.SIGINT) is note:
            signal.signal(signal.SIGINT, signal.default_int_handler)
