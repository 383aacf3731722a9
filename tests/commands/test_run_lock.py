"""One writer per run: a second ``nsl train --name X`` refuses in one line naming the first, or waits for it."""

from __future__ import annotations

import os
import re
import signal

import pytest

from nsl import workspace
from nsl.locks import holder
from tests.conftest import run_cli
from tests.lock_helpers import nsl_argv, popen, read_line_containing, start_held

TRAIN = (
    "train",
    "--data",
    "lock-data",
    "--steps",
    "2",
    "--checkpoint-every",
    "2",
    "--batch-size",
    "8",
    "--name",
    "locked-run",
)
CHECKPOINT = re.compile(r"^checkpoint ckpt:locked-run@2 \([0-9a-f]{12}\) -> .+$", re.M)


@pytest.fixture
def held_run(tmp_path):
    """A dataset, and a first ``nsl train --name locked-run`` that holds the run's lock, stopped before its
    first gradient step until the test touches the go file."""
    collect = ("collect", "--shift", "base", "--episodes", "6", "--policy", "oracle:0.5", "--data", "lock-data")
    assert run_cli(*collect, "--workers", "1") == 0
    first, _, go = start_held(tmp_path, "nsl.learners", "train", *TRAIN)
    try:
        yield first, go
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGKILL)
            first.wait()


def test_a_second_train_of_one_run_refuses_in_one_line_naming_the_first(held_run, capsys):
    first, _ = held_run
    assert holder(workspace.runs_dir() / "locked-run")["pid"] == first.pid
    capsys.readouterr()
    assert run_cli(*TRAIN) == 2  # a second process (this one)
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and re.fullmatch(
        rf"nsl: error: run 'locked-run' is being written by process {first.pid} \(nsl train --data lock-data "
        r".*--name locked-run\) since \S+Z; wait for it to finish, or pass --wait",
        err,
    ), err
    assert not (workspace.runs_dir() / "locked-run" / "checkpoints").exists()  # nothing written by either yet


@pytest.mark.slow  # two more training processes (~15 s on a busy 2-core machine)
def test_with_wait_a_second_train_finishes_after_the_first_and_reports_the_same_checkpoint(held_run):
    first, go = held_run
    second = popen(nsl_argv(*TRAIN, "--wait"))
    try:
        line = read_line_containing(second, "waiting for it")
        assert f"run 'locked-run' is being written by process {first.pid} (nsl train " in line
        go.touch()
        out1, err1 = first.communicate(timeout=300)
        out2, err2 = second.communicate(timeout=300)
    finally:
        if second.poll() is None:
            os.killpg(second.pid, signal.SIGKILL)
    assert first.returncode == 0 and second.returncode == 0, (err1[-2000:], err2[-2000:])
    reported = [CHECKPOINT.search(out) for out in (out1, out2)]
    assert all(reported), (out1, out2)
    assert reported[0][0] == reported[1][0]  # it found the run finished: the same checkpoint, the same id
    assert holder(workspace.runs_dir() / "locked-run") is None
