"""The pre-training recipe behind the 80% result (docs/experiments.md) keeps to the project's data budget: it
collects at most 10,000 episodes in all, and its final training reads every collected episode and nothing else."""

from __future__ import annotations

import re
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


def _joined(path: Path) -> str:
    return path.read_text().replace("\\\n", " ")


def collected(text: str) -> dict[str, int]:
    """Dataset name -> episodes, from the `nsl collect` lines of a script."""
    out = {}
    for line in text.splitlines():
        if " collect " in line and not line.lstrip().startswith("#"):
            episodes = int(re.search(r"--episodes (\d+)", line).group(1))
            out[re.search(r"--data (\S+)", line).group(1)] = episodes
    return out


def test_iterated_recipe_collects_at_most_10000_episodes_and_trains_on_all_of_them():
    text = _joined(SCRIPTS / "experiments" / "pretrain_base_iterated.sh")
    assert "scripts/collect_base_data.sh" in text
    budget = {**collected(_joined(SCRIPTS / "collect_base_data.sh")), **collected(text)}
    assert sum(budget.values()) == 10_000, budget
    final = [line for line in text.splitlines() if "--name c1-final" in line]
    assert len(final) == 1
    scripted = re.search(r'SCRIPTED="([^"]+)"', text).group(1)
    refs = re.findall(r"--data (\S+?)(?::(\d+))?=[\d.]+", scripted + " " + final[0])
    used = {name: int(tier) if tier else budget[name] for name, tier in refs}
    assert used == budget  # every collected episode, each tier exactly its dataset's size
    weights = [float(w) for w in re.findall(r"--data \S+=([\d.]+)", scripted + " " + final[0])]
    assert abs(sum(weights) - 1.0) < 1e-9
