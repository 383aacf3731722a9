"""Progress bars redraw only on a terminal; in a log they print a line every so often."""

from __future__ import annotations

import io

from nsl.progress import LOG_INTERVAL, progress_bar


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_log_gets_a_few_plain_lines_not_thousands_of_redraws():
    log = io.StringIO()
    with progress_bar(total=5000, desc="eval base", unit="ep", file=log) as bar:
        for _ in range(5000):
            bar.update(1)
    text = log.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert 1 <= len(lines) <= 3 and LOG_INTERVAL >= 10  # the first line and the last, well under a line a second
    assert lines[-1].startswith("eval base") and "5000/5000" in lines[-1]


def test_a_terminal_gets_a_redrawing_bar():
    term = _Terminal()
    with progress_bar(total=50, desc="train", file=term, mininterval=0) as bar:
        for _ in range(50):
            bar.update(1)
    assert term.getvalue().count("\r") >= 10


def test_a_disabled_bar_writes_nothing():
    log = io.StringIO()
    for _ in progress_bar(range(10), file=log, disable=True):
        pass
    assert log.getvalue() == ""
