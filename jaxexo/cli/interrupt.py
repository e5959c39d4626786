"""Ctrl-C for ``jaxexo train``: honoured from the moment the command starts, wherever the process is
(importing JAX, compiling, a chunk running in XLA), never in the middle of a file write.

Python's own handling raises KeyboardInterrupt in whichever Python code runs next. JAX runs Python in
a garbage-collector callback (its XLA collector), where an exception is printed as "Exception
ignored" and dropped: a Ctrl-C in the first second was lost there and the run trained on to exit 0.
During a compile or a chunk no Python runs at all until it ends. Here the signal instead wakes a
thread (``signal.set_wakeup_fd``) that prints the command's message and ends the process at once,
unless the main thread is writing a file (jaxexo.storage.atomic, or JAX's compilation cache): then as
soon as that write is done. Stdlib only: it is set up before JAX is imported."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time

# 128 + SIGINT: what a shell reports for a command ended by Ctrl-C.
EXIT_CODE = 128 + signal.SIGINT
# The files whose code writes what a later run reads (every jaxexo file write goes through
# atomic.py; JAX writes its cache entries in place): the process never ends inside one of them.
_WRITERS = (
    os.path.join("jaxexo", "storage", "atomic.py"),
    os.path.join("jax", "_src", "lru_cache.py"),
)


def writing(frame) -> bool:
    """Whether the stack ending at ``frame`` (None: a finished thread) is inside a file write."""
    while frame is not None:
        if frame.f_code.co_filename.endswith(_WRITERS):
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def honoured(message):
    """Within the block, SIGINT ends the process with ``message()`` (one line) on standard error and
    exit status 130, once no file is being written. Nothing changes where SIGINT is ignored (a
    background job of a shell script) or off the main thread; the previous handling is restored."""
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    ):
        yield
        return
    r, w = os.pipe()
    os.set_blocking(w, False)

    def forward(signum, frame):
        # A simulated signal (_thread.interrupt_main) reaches only this handler; a real one has
        # already woken the watcher through the wakeup descriptor.
        with contextlib.suppress(OSError):
            os.write(w, bytes([signum]))

    main = threading.main_thread().ident
    watcher = threading.Thread(
        target=_watch, args=(r, message, main), name="jaxexo-interrupt", daemon=True
    )
    watcher.start()
    previous = signal.signal(signal.SIGINT, forward)
    previous_fd = signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    try:
        yield
    finally:
        signal.set_wakeup_fd(previous_fd)
        signal.signal(signal.SIGINT, previous)
        os.close(w)  # the watcher reads the end of the pipe and returns
        watcher.join()
        os.close(r)


def _watch(fd: int, message, main: int) -> None:
    while data := os.read(fd, 512):
        if signal.SIGINT in data:
            _stop(message, main)


def _stop(message, main: int) -> None:
    """Say ``message()``, wait for the main thread to finish a write it is in, end the process."""
    # This thread keeps the interpreter from the last look at the main thread to the exit (the main
    # thread could otherwise be switched in between and start a write).
    sys.setswitchinterval(1.0)
    try:
        text = message()
    except Exception:  # a message that cannot be made never keeps the process running
        text = "jaxexo: interrupted"
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    with contextlib.suppress(OSError):
        # On a terminal the "^C" echo ends no line: the message starts on its own.
        os.write(2, (("\n" if os.isatty(2) else "") + text + "\n").encode(errors="replace"))
    while writing(sys._current_frames().get(main)):
        time.sleep(0.002)
    # os._exit: an interpreter shutdown with XLA's threads mid-computation can crash (seen: SIGSEGV),
    # and every file is already whole.
    os._exit(EXIT_CODE)
