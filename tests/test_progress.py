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


def test_a_bar_whose_postfix_changes_every_step_still_writes_a_few_lines_in_a_log():
    """Evaluation and collection bars set a postfix (the running success rate) after every episode; tqdm redraws on
    each such call by default, which in a log was a line per episode."""
    log = io.StringIO()
    with progress_bar(total=300, desc="eval base", unit="ep", file=log) as bar:
        for k in range(300):
            bar.update(1)
            bar.set_postfix(success=f"{k / 300:.2f}")
            bar.set_postfix_str(f"running {k}")
            bar.set_description(f"eval base {k}")
    lines = log.getvalue().splitlines()
    assert 1 <= len(lines) <= 3, lines[:5]
    assert "300/300" in lines[-1] and "running 299" in lines[-1]


def test_collect_train_and_eval_write_a_few_progress_lines_each_to_a_log(capsys):
    """The commands' own bars, with stderr captured (not a terminal), as in `make demo > demo.log 2>&1`."""
    from tests.conftest import run_cli

    steps = [
        "collect --shift base --episodes 24 --policy oracle:0.5 --data p --num-envs 4".split(),
        "train --data p --steps 40 --name p --checkpoint-every 20".split(),
        "eval --policy oracle:0.5 --shift base --episodes 30 --workers 1".split(),
    ]
    for argv in steps:
        assert run_cli(*argv) == 0, argv
        err = capsys.readouterr().err
        bars = [line for line in err.splitlines() if "%|" in line]
        assert 1 <= len(bars) <= 4, (argv[0], len(bars), bars[:6])
        assert "\r" not in err
