"""Keep a benchmark's stdout for its JSON document while native code prints banners."""

from __future__ import annotations

import ctypes
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def c_stdout_to_stderr() -> Iterator[None]:
    """Send what C code writes to file descriptor 1 (pybullet's banners) to stderr meanwhile."""
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        yield
    finally:
        ctypes.CDLL(None).fflush(None)  # C stdio buffers the banner until exit otherwise
        os.dup2(saved, 1)
        os.close(saved)
