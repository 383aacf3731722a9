"""meta/stats.json carries LeRobot's quantiles, pooled per episode as LeRobot pools them, and a LeRobot
policy's QUANTILES normaliser builds from them through LeRobot's own code."""

from __future__ import annotations

import json

import numpy as np
import torch

from nsl import keys
from nsl.datasets import stats as statslib

QUANTILE_KEYS = ["q01", "q10", "q50", "q90", "q99"]  # LeRobot's, from DEFAULT_QUANTILES


def test_quantiles_per_episode_exact_and_pooled_as_lerobot_pools_them(make_synth):
    from lerobot.datasets.compute_stats import DEFAULT_QUANTILES, aggregate_stats

    assert statslib.QUANTILE_NAMES == tuple(QUANTILE_KEYS) and statslib.QUANTILES == tuple(DEFAULT_QUANTILES)
    make_synth("quant", [3, 4, 2], successes={0})
    v = make_synth("quant", [5, 2], start=3, successes={4})  # v2 pools v1's stored episode stats
    per_episode = v.episode_stats()
    assert len(per_episode) == 5
    # Each episode's quantiles are numpy's over its own frames (images per channel, in [0, 1]).
    ep = v.view().episode(3)
    pixels = ep[keys.OBS_IMAGE].reshape(-1, 3).astype(np.float64) / 255.0
    want = np.quantile(pixels, statslib.QUANTILES, axis=0)
    got = np.stack([np.ravel(per_episode[3][keys.OBS_IMAGE][q]) for q in QUANTILE_KEYS])
    np.testing.assert_allclose(got, want, atol=1e-12)
    np.testing.assert_allclose(
        np.stack([per_episode[3][keys.ACTION][q] for q in QUANTILE_KEYS]),
        np.quantile(ep[keys.ACTION].astype(np.float64), statslib.QUANTILES, axis=0),
    )
    # stats.json pools them exactly as LeRobot's aggregate_stats does.
    stats = json.loads((v.root / "meta/stats.json").read_text())
    lerobot_pooled = aggregate_stats(per_episode)
    for key in (keys.OBS_IMAGE, keys.OBS_STATE, keys.ACTION, keys.REWARD, keys.DONE):
        for q in QUANTILE_KEYS:
            np.testing.assert_allclose(stats[key][q], lerobot_pooled[key][q], rtol=1e-12, err_msg=f"{key} {q}")
    assert np.asarray(stats[keys.OBS_IMAGE]["q50"]).shape == (3, 1, 1)
    # Episodes stored without quantiles (written before they were recorded) leave them out, as in LeRobot.
    old = [{k: {s: a for s, a in st.items() if not s.startswith("q")} for k, st in p.items()} for p in per_episode[:2]]
    pooled = statslib.aggregate(old + per_episode[2:])
    assert "q50" not in pooled[keys.ACTION] and "mean" in pooled[keys.ACTION]
    assert "q50" not in statslib.to_json(pooled)[keys.ACTION]


def test_lerobot_quantiles_normaliser_from_an_nsl_dataset(make_synth, lerobot_offline):
    from lerobot.configs.types import FeatureType, NormalizationMode
    from lerobot.datasets.utils import dataset_to_policy_features
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.factory import make_pre_post_processors

    v = make_synth("normalised", [3, 4, 5], successes={1})
    ds = lerobot_offline("local/normalised", root=v.root)
    assert set(QUANTILE_KEYS) <= set(ds.meta.stats[keys.ACTION])

    features = dataset_to_policy_features(ds.meta.features)
    quantiles = {t: NormalizationMode.QUANTILES for t in ("VISUAL", "STATE", "ACTION")}
    cfg = ACTConfig(device="cpu", normalization_mapping=quantiles)
    cfg.input_features = {k: f for k, f in features.items() if f.type is not FeatureType.ACTION}
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    preprocess, postprocess = make_pre_post_processors(cfg, dataset_stats=ds.meta.stats)

    batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=4)))
    out = preprocess(dict(batch))
    s = {
        k: {q: torch.as_tensor(np.asarray(ds.meta.stats[k][q]), dtype=torch.float32) for q in ("q01", "q99")}
        for k in (keys.ACTION, keys.OBS_STATE, keys.OBS_IMAGE)
    }
    for k in (keys.ACTION, keys.OBS_STATE, keys.OBS_IMAGE):
        q01, q99 = s[k]["q01"], s[k]["q99"]
        denom = torch.where(q99 == q01, torch.tensor(1e-8), q99 - q01)
        want = 2 * (batch[k] - q01) / denom - 1
        torch.testing.assert_close(out[k].cpu(), want, msg=k)
    assert out[keys.OBS_IMAGE].shape == (4, 3, 16, 16) and out[keys.OBS_IMAGE].abs().max() < 1.5
    torch.testing.assert_close(postprocess(out[keys.ACTION]), batch[keys.ACTION], atol=1e-5, rtol=1e-5)
