"""A stop request that a signal handler may set: no lock, woken at the C level.

The pattern ``stop = threading.Event(); signal.signal(SIGTERM, lambda *_: stop.set());
while not stop.wait(dt): ...`` deadlocks: the handler runs in the main thread between two
bytecodes, and when the signal lands while ``wait`` holds the Event's condition lock
(entering or leaving the wait) ``set`` blocks on that same non-reentrant lock forever
(measured in isolation: 110 of 200 processes, issue 21). :class:`SignalStop` is the
signal-safe form: the handler only sets a flag and writes one byte to a pipe (also written
by ``signal.set_wakeup_fd`` in C, before any Python code runs); ``wait`` is a ``select``
on that pipe.
"""

from __future__ import annotations

import os
import select
import signal

__all__ = ["SignalStop"]


class SignalStop:
    """A stop request set from a signal handler, waited on without a lock.

    ``threading.Event.set()`` from a handler deadlocks when the signal lands while the
    main thread holds the Event's own lock inside ``wait()`` (the handler runs in that
    thread; the lock is not reentrant). Here the handler only sets a flag, and the wait is
    a ``select`` on a pipe that ``signal.set_wakeup_fd`` writes to at the C level, so a
    signal wakes the wait at once and nothing is ever locked.
    """

    def __init__(self):
        self._flag = False
        self._read, self._write = os.pipe()
        os.set_blocking(self._read, False)
        os.set_blocking(self._write, False)
        self._previous = signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)

    def set(self, *_):
        self._flag = True
        try:
            os.write(self._write, b"\0")
        except OSError:          # the pipe is full: a wake-up is already pending
            pass

    def is_set(self) -> bool:
        return self._flag

    def wait(self, timeout: float) -> bool:
        if not self._flag:
            select.select([self._read], [], [], max(timeout, 0.0))
            try:
                while os.read(self._read, 512):
                    pass
            except OSError:      # drained (EAGAIN)
                pass
        return self._flag

    def close(self):
        signal.set_wakeup_fd(self._previous)
        os.close(self._read)
        os.close(self._write)
