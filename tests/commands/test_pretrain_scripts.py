"""The pre-training recipe behind the 80% result (docs/experiments/rounds.md) keeps to the project's data budget: it
collects at most 10,000 episodes in all, and its final training reads every collected episode and nothing else."""

from __future__ import annotations

import re
from pathlib import Path

from tests.conftest import recorded_calls

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


def test_rounds_recipe_keeps_to_50000_episodes_and_its_final_runs_read_every_round(tmp_path):
    """Run pretrain_base_rounds.sh with a recording stand-in for `nsl`: the commands it would run."""
    calls = recorded_calls(SCRIPTS / "experiments" / "pretrain_base_rounds.sh", tmp_path, SEEDS="0 1 2")

    def opt(call, flag):
        return [call[i + 1] for i, a in enumerate(call) if a == flag]

    collects = {opt(c, "--data")[0]: int(opt(c, "--episodes")[0]) for c in calls if c[0] == "collect"}
    assert sum(collects.values()) <= 50_000, collects
    rounds = sorted(n for n in collects if n.startswith("grasp-rounds-"))
    assert len(rounds) == 4
    trains = {opt(c, "--name")[0]: c for c in calls if c[0] == "train"}
    finals = [trains["rounds-r4"], trains["rounds-r4-s1"], trains["rounds-r4-s2"]]
    for call in finals:
        data = dict(d.split("=") for d in opt(call, "--data"))
        used = {ref.split(":")[0]: int(ref.split(":")[1]) if ":" in ref else collects[ref] for ref in data}
        assert used == collects  # every collected episode, each tier exactly its dataset's size
        assert abs(sum(float(w) for w in data.values()) - 1.0) < 1e-3
    assert [opt(c, "--seed") for c in finals] == [[], ["1"], ["2"]]
    # each round is collected by the policy of the round before it
    for i in range(1, 5):
        call = next(c for c in calls if c[0] == "collect" and opt(c, "--data") == [f"grasp-rounds-{i}"])
        assert opt(call, "--policy") == [f"ckpt:rounds-r{i - 1}@6000"]
    evals = [c for c in calls if c[0] == "eval"]
    assert opt(evals[0], "--checkpoint") == ["ckpt:rounds-r4@6000,ckpt:rounds-r4-s1@6000,ckpt:rounds-r4-s2@6000"]
