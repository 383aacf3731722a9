"""Progress bars that redraw on a terminal and print a line every so often anywhere else.

On a terminal a tqdm bar redraws in place.  In a log file or CI (stderr is not
a terminal) a redrawn bar would write thousands of ``\\r`` updates; there,
:func:`progress_bar` prints a plain line at most every :data:`LOG_INTERVAL`
seconds, and one at the end, as pip and huggingface_hub do.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

LOG_INTERVAL = 30.0  # seconds between lines when stderr is not a terminal


class _Lines:
    """A stream for tqdm that turns each redraw into one line and drops the clearing writes."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream

    def write(self, text: str) -> int:
        line = text.replace("\r", "").replace("\x1b[A", "").strip()
        if line:
            self.stream.write(line + "\n")
        return len(text)

    def flush(self) -> None:
        self.stream.flush()


def is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def progress_bar(*args: Any, file: TextIO | None = None, **kwargs: Any):
    """A ``tqdm`` bar on a terminal; elsewhere the same bar printing a line every :data:`LOG_INTERVAL` seconds."""
    from tqdm import tqdm

    stream = file if file is not None else sys.stderr
    if is_terminal(stream):
        return tqdm(*args, file=stream, **kwargs)
    kwargs.pop("dynamic_ncols", None)
    kwargs.update(mininterval=LOG_INTERVAL, maxinterval=LOG_INTERVAL, ncols=100, ascii=True)
    return tqdm(*args, file=_Lines(stream), **kwargs)
