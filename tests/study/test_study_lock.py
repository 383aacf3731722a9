"""One process runs a study at a time: a second ``nsl study run`` on its folder refuses in one line naming the
first, and whether a study runs is the lock's answer, not a pid's (a pid can be reused)."""

from __future__ import annotations

import os
import re
import signal

from nsl import workspace
from nsl.locks import holder
from nsl.study import study_status
from nsl.study.scheduler import STATUS_FILE
from nsl.workspace import atomic_write_json
from tests.conftest import run_cli
from tests.lock_helpers import start_held, wait_for


def test_a_second_study_run_on_one_folder_refuses_and_a_killed_first_frees_it(micro_plan, tmp_path, capsys):
    folder = workspace.home() / "studies" / "micro"
    # the first driver holds the study's lock, its plan saved, and stops before its first unit
    first, _, _ = start_held(
        tmp_path, "nsl.study.driver", "run_graph", "study", "run", str(micro_plan), "--quiet", release=False
    )
    try:
        assert holder(folder)["pid"] == first.pid
        capsys.readouterr()
        assert run_cli("study", "run", str(micro_plan), "--quiet") == 2  # a second driver (this process)
        err = capsys.readouterr().err.strip()
        assert "\n" not in err and re.fullmatch(
            rf"nsl: error: study 'micro' is being written by process {first.pid} \(nsl study run \S+micro\.toml "
            r"--quiet\) since \S+Z; wait for it to finish, or pass --wait",
            err,
        ), err
        assert not (folder / STATUS_FILE).exists()  # it wrote nothing
        # a journal that names a live process which is not the driver (a reused pid) does not fool the status
        atomic_write_json(folder / STATUS_FILE, {"study": "micro", "pid": os.getpid(), "state": "running", "units": {}})
        assert study_status("micro")["state"] == "running"  # the first driver holds the lock
        os.killpg(first.pid, signal.SIGKILL)
        first.wait()
        wait_for(lambda: holder(folder) is None, "the OS to release the killed driver's lock", timeout=10)
        assert study_status("micro")["state"] == "interrupted"  # although the recorded pid (this one) lives
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGKILL)
            first.wait()
