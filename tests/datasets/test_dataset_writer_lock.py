"""One writer per dataset: an OS lock that names its holder, dies with it, and keeps resumed data correct.

Whatever order two processes take, the committed version's content hash equals that of the same command run
alone, or the second process has refused in one line that names the first.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading

import pytest

from nsl.datasets import api, versions
from nsl.errors import LockedError
from nsl.locks import dataset_lock, holder, holder_file, lock_file, writer_lock
from tests.conftest import run_cli
from tests.datasets.conftest import SYNTH_SPEC
from tests.lock_helpers import nsl_argv, popen, read_line_containing, start_held, wait_for

NAME = "race"
COLLECT = (
    "collect",
    "--shift",
    "base",
    "--episodes",
    "8",
    "--policy",
    "oracle:0.5",
    "--data",
    NAME,
    "--workers",
    "1",
    "--episodes-per-file",
    "2",
)
REFUSED = re.compile(
    r"nsl: error: dataset 'race' is being written by process (\d+) \(nsl collect --shift base .*\) "
    r"since \d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ; wait for it to finish, or pass --wait"
)


@pytest.fixture(scope="module")
def alone(tmp_path_factory) -> str:
    """The version hash of the command run alone, in a workspace of its own."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("NSL_HOME", str(tmp_path_factory.mktemp("alone")))
        assert run_cli(*COLLECT) == 0
        return api.open_version(NAME).hash


def _holding(folder, command: str = "nsl collect --data x") -> subprocess.Popen:
    """A process that holds ``folder``'s writer lock until it is killed."""
    code = (
        "import sys, time\nfrom nsl.locks import writer_lock\n"
        f"sys.argv = {command.split()!r}\n"
        f"with writer_lock({str(folder)!r}, 'dataset x'):\n"
        "    print('held', flush=True)\n    time.sleep(600)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
    return proc


def test_the_lock_names_its_holder_waits_for_it_and_dies_with_it(tmp_path, capsys):
    folder = tmp_path / "x"
    proc = _holding(folder)
    try:
        with pytest.raises(LockedError) as e:
            with writer_lock(folder, "dataset x"):
                pass
        message = str(e.value)
        assert "\n" not in message and re.fullmatch(
            rf"dataset x is being written by process {proc.pid} \(nsl collect --data x\) since "
            r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ; wait for it to finish, or pass --wait",
            message,
        ), message
        record = holder(folder)
        assert record is not None and record["pid"] == proc.pid and record["command"] == "nsl collect --data x"
        # --wait: one line on stderr, then the lock once the holder is gone (here: kill -9, which needs no clean-up)
        threading.Timer(1.0, os.kill, (proc.pid, signal.SIGKILL)).start()
        with writer_lock(folder, "dataset x", wait=True):
            assert holder(folder)["pid"] == os.getpid()
        assert capsys.readouterr().err.strip() == message.replace(
            "; wait for it to finish, or pass --wait", "; waiting for it"
        ).replace("dataset x", "nsl: dataset x", 1)
    finally:
        proc.kill()
        proc.wait()
    assert holder(folder) is None and not holder_file(folder).exists() and not folder.exists()  # made nothing there


def test_the_lock_is_reentrant_in_its_thread_and_refuses_other_threads(tmp_path):
    refused = []

    def other():
        try:
            with writer_lock(tmp_path, "run 'r'"):
                refused.append(False)
        except LockedError as e:
            refused.append(f"process {os.getpid()} (" in str(e))

    with writer_lock(tmp_path, "run 'r'"):
        with writer_lock(tmp_path, "run 'r'"):  # nested: a continual run's stage inside the run
            t = threading.Thread(target=other)
            t.start()
            t.join()
        assert holder(tmp_path)["pid"] == os.getpid()  # the inner exit keeps the outer hold
    assert refused == [True] and holder(tmp_path) is None


def test_lock_files_stay_out_of_versions_listings_and_hashes(make_synth, capsys):
    v = make_synth("locked", [3, 2, 4])
    with dataset_lock("locked"):
        root = api.dataset_root("locked")
        assert lock_file(root) == root.parent / ".locked.lock" and lock_file(root).exists()
        assert holder_file(root) == root.parent / ".locked.lock.json" and holder_file(root).exists()
        assert api.verify("locked")["hash"] == v.hash  # the version folder holds no lock file
        assert api.dataset_names() == ["locked"] and api.list_versions("locked") == [1]
        assert [r["ref"] for r in api.list_datasets()] == ["locked@v1"] and api.unfinished() == []
        assert ".lock" not in " ".join(versions.content_files(root))  # the dataset folder holds no lock file
        assert run_cli("dataset", "verify") == 0  # readers never wait for the lock
    assert "locked@v1 ok" in capsys.readouterr().out


def test_begin_refuses_while_another_process_writes_and_leaves_its_files_alone(tmp_path, make_synth):
    make_synth(NAME, [2, 3])
    root = api.dataset_root(NAME)
    theirs = root / ".tmp-v2-abc"  # as if the holder were publishing v2
    (theirs / "data").mkdir(parents=True)
    proc = _holding(root, "nsl collect --data race")
    try:
        with pytest.raises(LockedError, match=rf"dataset 'race' is being written by process {proc.pid} "):
            api.Collection.begin(NAME, 4, SYNTH_SPEC, 16)
        assert theirs.is_dir()  # begin cleans up only under the lock
    finally:
        proc.kill()
        proc.wait()
    with api.Collection.begin(NAME, 2, SYNTH_SPEC, 16, wait=True) as c:  # the holder is gone: a killed holder's
        assert not theirs.exists() and c.up_to_date  # leftovers are its own, cleared by the next holder
    assert holder(root) is None


def test_two_identical_collections_started_at_once(alone):
    procs = [popen(nsl_argv(*COLLECT)) for _ in range(2)]
    outs = [p.communicate(timeout=300) for p in procs]
    codes = [p.returncode for p in procs]
    assert sorted(codes) in ([0, 0], [0, 2]), outs
    for p, (_, err), code in zip(procs, outs, codes):
        if code == 2:  # refused at once, in one line naming the other process and its command
            other = next(q for q in procs if q is not p)
            m = REFUSED.fullmatch(err.strip())
            assert m and int(m[1]) == other.pid, err
    assert api.list_versions(NAME) == [1]
    assert api.open_version(NAME).hash == alone
    assert holder(api.dataset_root(NAME)) is None


def test_a_collection_started_while_another_commits(tmp_path, alone, capsys):
    # the first process stops inside finish(), with its .tmp-v1-* folder made and the lock held
    first, _, go = start_held(tmp_path, "nsl.datasets.versions", "build_manifest", *COLLECT)
    try:
        root = api.dataset_root(NAME)
        publishing = list(root.glob(".tmp-v1-*"))
        assert len(publishing) == 1
        capsys.readouterr()
        assert run_cli(*COLLECT) == 2  # a second process (this one)
        err = capsys.readouterr().err
        m = REFUSED.fullmatch(err.strip())
        assert m and int(m[1]) == first.pid, err
        assert publishing[0].is_dir()  # the second process touched nothing of the first's
        third = popen(nsl_argv(*COLLECT, "--wait"))
        line = read_line_containing(third, "waiting for it")
        assert line.startswith(f"nsl: dataset 'race' is being written by process {first.pid} (nsl collect ")
        go.touch()
        out1, err1 = first.communicate(timeout=300)
        assert first.returncode == 0, err1
        out3, err3 = third.communicate(timeout=300)
        assert third.returncode == 0, err3
    finally:
        for p in (first,):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
    assert "wrote race@v1: 8 episodes" in out1
    assert "race@v1 already holds 8 episodes" in out3  # it waited, then found the first's version
    assert api.list_versions(NAME) == [1] and api.open_version(NAME).hash == alone
    assert not list(root.glob(".tmp-v*")) and not (root / ".staging").exists()


def test_kill_9_of_the_holder_then_the_same_command_resumes_to_the_uninterrupted_hash(tmp_path, alone, capsys):
    # the holder stops before writing its third file (two staged), then is killed -9 with the lock held
    proc, _, _ = start_held(tmp_path, "nsl.datasets.writer", "write_file_pair", *COLLECT, after=2, release=False)
    root = api.dataset_root(NAME)
    assert holder(root)["pid"] == proc.pid
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    wait_for(lambda: holder(root) is None, "the OS to release a killed holder's lock", timeout=10)
    assert run_cli(*COLLECT) == 0  # no clean-up step: the same command takes the lock and resumes
    assert "resuming race: 4 of 8 episodes already staged" in capsys.readouterr().err
    assert api.open_version(NAME).hash == alone
    assert holder(root) is None and not holder_file(root).exists()
    assert sorted(p.name for p in root.iterdir()) == ["v1"]
