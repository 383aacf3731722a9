"""Progress bars that redraw on a terminal and print a line every so often anywhere else.

On a terminal a tqdm bar redraws in place.  In a log file or CI (stderr is not
a terminal) a redrawn bar would write thousands of ``\\r`` updates; there,
:func:`progress_bar` prints a plain line at most every :data:`LOG_INTERVAL`
seconds, and one at the end, as pip and huggingface_hub do.  Changing a bar's
postfix or description redraws a tqdm bar at once by default; in a log that
would be a line per episode, so there it waits for the bar's next line.
"""

from __future__ import annotations

import functools
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


@functools.cache
def _log_bar_class():
    """A tqdm whose postfix and description changes never force a redraw (the next timed line shows them)."""
    from tqdm import tqdm

    class LogBar(tqdm):
        def set_postfix(self, ordered_dict=None, refresh=True, **kwargs):
            super().set_postfix(ordered_dict, refresh=False, **kwargs)

        def set_postfix_str(self, s="", refresh=True):
            super().set_postfix_str(s, refresh=False)

        def set_description(self, desc=None, refresh=True):
            super().set_description(desc, refresh=False)

        def set_description_str(self, desc=None, refresh=True):
            super().set_description_str(desc, refresh=False)

    return LogBar


def progress_bar(*args: Any, file: TextIO | None = None, **kwargs: Any):
    """A ``tqdm`` bar on a terminal; elsewhere the same bar printing a line every :data:`LOG_INTERVAL` seconds."""
    from tqdm import tqdm

    stream = file if file is not None else sys.stderr
    if is_terminal(stream):
        return tqdm(*args, file=stream, **kwargs)
    kwargs.pop("dynamic_ncols", None)
    kwargs["leave"] = True  # a log keeps the last line (the count and the rate), even of a bar a terminal clears
    kwargs.update(mininterval=LOG_INTERVAL, maxinterval=LOG_INTERVAL, ncols=100, ascii=True)
    return _log_bar_class()(*args, file=_Lines(stream), **kwargs)
