"""``nsl render`` and CLI error handling through the real entry point."""

from __future__ import annotations

import subprocess
import sys

from PIL import Image

from tests.conftest import run_cli


def test_render_all_writes_one_row_per_shift(tmp_path):
    out = tmp_path / "gallery.png"
    assert run_cli("render", "--shift", "all", "--episodes", "2", "--scale", "2", "--out", str(out)) == 0
    img = Image.open(out)
    assert img.height == 6 * 64 * 2 and img.width > 2 * 64 * 2


def test_bad_input_is_one_line_and_nonzero(tmp_path):
    for args, needle in [
        (["render", "--shift", "harsh", "--out", str(tmp_path / "x.png")], "unknown shift 'harsh'"),
        (["render", "--image-size", "0", "--out", str(tmp_path / "x.png")], "image_size 0"),
        (["eval", "--policy", "orcale", "--episodes", "1"], "unknown policy 'orcale'"),
    ]:
        r = subprocess.run([sys.executable, "-m", "nsl", *args], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2, r.stderr
        lines = [ln for ln in r.stderr.splitlines() if ln.startswith("nsl: error:")]
        assert len(lines) == 1 and needle in lines[0], r.stderr
        assert "Traceback" not in r.stderr
