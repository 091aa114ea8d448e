"""Ctrl-C and SIGTERM: one line, exit 130 or 143, nothing written, from a command's first instruction.

The handler exits the process rather than raise KeyboardInterrupt: an
exception raised while a C extension initialises (cadquery's, trimesh's
import) is swallowed, or comes out as an ImportError with a traceback.
Files and folders being written (:func:`removing`) are removed first.
"""

import os
import shutil
import signal
from contextlib import contextmanager
from pathlib import Path

MESSAGE = b"fixturecad: interrupted; nothing was written\n"
_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_PENDING = []  # temporary files and folders an interrupt removes
_HOLDING = []  # open :func:`held` blocks: an interrupt in one waits for the last to end
_WAITING = []  # the signal that waited


def install() -> dict:
    """Handle Ctrl-C and SIGTERM from now on; the previous handlers ({} off the main thread: left alone)."""
    try:
        return {signum: signal.signal(signum, _stop) for signum in _SIGNALS}
    except ValueError:
        return {}


@contextmanager
def removing(path: Path):
    """In the block, an interrupt removes ``path`` (a temporary file or folder) before it exits."""
    previous = install()  # a library call (build(), not the CLI) is covered too
    _PENDING.append(Path(path))
    try:
        yield
    finally:
        _PENDING.remove(Path(path))
        for signum, handler in previous.items():
            signal.signal(signum, handler)


@contextmanager
def held():
    """In the block, an interrupt waits until the block ends: a temporary path made and given to :func:`removing`
    in one such block is never left behind (an interrupt between the two would leave it)."""
    _HOLDING.append(None)
    try:
        yield
    finally:
        _HOLDING.pop()
        if _WAITING and not _HOLDING:
            _stop(_WAITING[0], None)


def _stop(signum, frame):
    if _HOLDING:
        _WAITING.append(signum)
        return
    for path in _PENDING:
        shutil.rmtree(path, ignore_errors=True) if path.is_dir() else path.unlink(missing_ok=True)
    os.write(2, MESSAGE)
    os._exit(128 + signum)
