"""Ctrl-C in the ``softplan`` command: one line, exit code 130, no partial files
(:func:`interrupt_guard`, :func:`atomic_output`; why the process ends without unwinding: the
documentation's "The softplan command", "Ctrl-C")."""

from __future__ import annotations

import contextlib
import os
import signal
import tempfile
import threading

from ..base._files import publish

__all__ = ["EXIT_INTERRUPTED", "interrupt_guard", "atomic_output", "exit_interrupted", "interrupted_say",
           "interrupted_next_step"]

EXIT_INTERRUPTED = 130  # 128 + SIGINT, the shell's convention

_PARTIAL: set[str] = set()  # temporary files being written
_LOCK = threading.Lock()
_MESSAGE = b"softplan: interrupted\n"
_NEXT_STEP = [b""]  # a line after the message: what to do next (interrupted_say)


def interrupted_say(text: str) -> None:
    """If Ctrl-C ends this command, write ``softplan: <text>`` after ``softplan: interrupted``
    (e.g. that the same command resumes); "" says nothing more."""
    _NEXT_STEP[0] = f"softplan: {' '.join(text.split())}\n".encode() if text.strip() else b""


def interrupted_next_step() -> str:
    """The line :func:`interrupted_say` set ("" when none)."""
    return _NEXT_STEP[0].decode()


def exit_interrupted() -> None:
    """Remove the partial outputs, write one line on stderr, end the process with code 130."""
    if not _LOCK.acquire(blocking=False):
        return  # the other path (handler or watcher) is already ending the process
    for path in list(_PARTIAL):
        try:
            os.unlink(path)
        except OSError:
            pass
    try:
        os.write(2, _MESSAGE + _NEXT_STEP[0])  # not sys.stderr: its lock may be held by the interrupted thread
    except OSError:
        pass
    os._exit(EXIT_INTERRUPTED)


def _handler(signum, frame):
    exit_interrupted()


def _watch(fd: int) -> None:
    while True:
        try:
            data = os.read(fd, 64)
        except OSError:
            return
        if not data:  # the write end was closed: the guard is over
            return
        if signal.SIGINT in data:
            exit_interrupted()


@contextlib.contextmanager
def interrupt_guard(restore: bool = True):
    """While active, SIGINT ends the process with :func:`exit_interrupted`. A no-op outside
    the main thread (signal handlers can only be set there). On exit the previous wakeup fd
    is restored, and the previous SIGINT handler too, unless ``restore`` is False: then
    SIGINT is ignored from there on (the process is about to exit, and finalization would reset
    the handler to one that kills the process or raises into jax's exit handlers).
    The handler is swapped in one call, so no SIGINT falls between the two."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    r, w = os.pipe()
    os.set_blocking(w, False)
    try:
        old_fd = signal.set_wakeup_fd(w)
    except ValueError:  # not the main thread of the main interpreter
        os.close(r)
        os.close(w)
        yield
        return
    old_handler = signal.signal(signal.SIGINT, _handler)
    watcher = threading.Thread(target=_watch, args=(r,), name="softplan-interrupt", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old_handler if restore else signal.SIG_IGN)
        signal.set_wakeup_fd(old_fd)
        os.close(w)  # the watcher reads end-of-file and returns
        watcher.join(timeout=1.0)
        os.close(r)


@contextlib.contextmanager
def atomic_output(path: str):
    """Write an output file whole or not at all: yields a temporary path in the same folder
    (same extension, so that writers that choose a format by it still do); on success it is
    renamed to ``path``, on an error removed, and on Ctrl-C :func:`exit_interrupted` removes it."""
    folder = os.path.dirname(os.path.abspath(path))
    ext = os.path.splitext(path)[1]
    fd, tmp = tempfile.mkstemp(prefix=".softplan-", suffix=ext, dir=folder)
    os.close(fd)
    _PARTIAL.add(tmp)
    try:
        yield tmp
        publish(tmp, path)
    finally:
        _PARTIAL.discard(tmp)
        if os.path.exists(tmp):
            try:
                os.unlink(tmp)
            except OSError:
                pass

