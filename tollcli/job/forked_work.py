"""Work run in a forked child process beside this one, its result read back through a pipe.

The child does the work, writes the pickled result (or the exception it raised) to the pipe and ends with
``os._exit``: no executor, no manager thread, no multiprocessing bootstrap, no atexit hooks or stream flushes in the
child. A ``ProcessPoolExecutor`` started with ``fork`` did all of those; once in CI a command using it never ended.

If this process stops without reading the result, the pipe's read end closes with it and the child's write fails:
the child ends too, holding nothing of the caller's (its standard streams among them) any longer than its work.
"""

from __future__ import annotations

import os
import pickle
import signal
from collections.abc import Callable


class ForkedWork:
    """``work()`` running in a forked child; :meth:`result` waits for it and returns what it returned, or raises what
    it raised. Call only where ``os.fork`` exists."""

    def __init__(self, work: Callable[[], object]):
        read_fd, write_fd = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: never returns
            os.close(read_fd)
            _child(work, write_fd)
        os.close(write_fd)
        self._pid, self._read_fd = pid, read_fd
        self._done = False
        self._value: object = None
        self._error: BaseException | None = None

    def result(self):
        """What the work returned (waits for the child); raises what it raised."""
        if not self._done:
            self._collect()
        if self._error is not None:
            raise self._error
        return self._value

    def _collect(self) -> None:
        parts = []
        with os.fdopen(self._read_fd, "rb") as pipe:
            while chunk := pipe.read(1 << 20):
                parts.append(chunk)
        _, status = os.waitpid(self._pid, 0)
        self._done = True
        payload = b"".join(parts)
        if not payload:
            code = os.waitstatus_to_exitcode(status)
            ended = f"signal {-code}" if code < 0 else f"exit status {code}"
            self._error = RuntimeError(f"the process working beside this one ended without a result ({ended})")
            return
        ok, value = pickle.loads(payload)
        if ok:
            self._value = value
        else:
            self._error = value


def _child(work: Callable[[], object], write_fd: int) -> None:
    """Run ``work`` and write ``(True, result)`` or ``(False, exception)``; end the process whatever happens."""
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # an interrupt is the parent's to handle; it ends this with it
        try:
            payload = pickle.dumps((True, work()), protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException as exc:  # noqa: BLE001 - handed to the parent, which raises it
            payload = _pickled_error(exc)
        with os.fdopen(write_fd, "wb") as pipe:
            pipe.write(payload)
    except BaseException:  # noqa: BLE001 - the parent stopped reading (a broken pipe): nothing is left to tell
        code = 1
    finally:
        os._exit(code)


def _pickled_error(exc: BaseException) -> bytes:
    """``(False, exc)`` pickled; an exception that does not survive pickling goes as a RuntimeError naming it."""
    try:
        payload = pickle.dumps((False, exc), protocol=pickle.HIGHEST_PROTOCOL)
        pickle.loads(payload)
        return payload
    except Exception:  # noqa: BLE001
        return pickle.dumps((False, RuntimeError(f"{type(exc).__name__}: {exc}")))
