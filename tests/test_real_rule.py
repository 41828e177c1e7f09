"""The verdict rule of the intra protocol on real recordings, and the measures that explain it."""

import numpy as np
import pytest

from primspace.results.claim_rules_real import diagnostics, eval_losses, projection_below_zero


def intra(zero, projection, q=8):
    """An intra result with these final eval losses per seed (the curve's first point is larger)."""
    runs = []
    for init, losses in (("zero", zero), ("projection", projection)):
        for seed, loss in enumerate(losses):
            infer = [{"epoch": 0, "loss": 1.0}, {"epoch": 250, "loss": loss}]
            runs.append({"init": init, "latent_dim": q, "seed": seed, "infer": infer})
    return {"runs": runs}


@pytest.mark.parametrize(
    ("zero", "projection", "verdict", "detail"),
    [
        ([0.010, 0.011, 0.012], [0.002, 0.003, 0.004], "holds", "projection lower"),
        ([0.010, 0.011, 0.012], [0.0095, 0.0105, 0.0115], "does not hold", "tie"),  # 0.5e-3 apart, spread 1e-3
        ([0.0019, 0.0018, 0.0020], [0.0079, 0.0080, 0.0078], "does not hold", "reversed"),
        ([0.010], [0.002], "cannot be checked", "one seed"),
    ],
)
def test_projection_below_zero_by_more_than_the_spread(zero, projection, verdict, detail):
    out = projection_below_zero(intra(zero, projection))
    assert out["verdict"] == verdict
    assert detail in out["by_q"][8]["detail"]
    assert out["by_q"][8]["zero"] == pytest.approx(np.mean(zero))
    lower = sum(p < z for z, p in zip(zero, projection))
    assert out["by_q"][8]["lower_in"] == [lower, len(zero)]
    assert f"projection lower in {lower} of {len(zero)} seeds" in out["text"]


def test_eval_losses_are_the_last_inference_loss_per_seed():
    assert eval_losses(intra([0.5, 0.25], [0.1, 0.2])) == {
        8: {"zero": {0: 0.5, 1: 0.25}, "projection": {0: 0.1, 1: 0.2}}
    }


def test_a_difference_equal_to_the_spread_is_a_tie():
    # zero 0.01 ± 0.001, projection 0.009 ± 0.001: a difference of exactly the spread does not count
    out = projection_below_zero(intra([0.009, 0.010, 0.011], [0.008, 0.009, 0.010]))
    assert out["verdict"] == "does not hold"


def test_diagnostics_scale_drift_and_conditioning():
    rng = np.random.default_rng(0)
    pm = np.diag([10.0, 1.0]) @ rng.standard_normal((2, 40))  # anisotropic: most variance on the first axis
    pm = pm.T
    runs = {
        "intra/projection-q2-s0": {
            "fit/latents_init": pm[:10],
            "fit/latents": pm[:10] * 1.1,  # drift 0.1
            "infer/latents_init": pm[10:],
            "infer/latents": pm[10:],
        },
        "intra/zero-q2-s0": {
            "fit/latents_init": np.zeros((10, 2)),
            "fit/latents": np.full((10, 2), 0.1),
            "infer/latents_init": np.zeros((30, 2)),
            "infer/latents": np.zeros((30, 2)),
        },
    }
    out = diagnostics({"runs": runs}, {"length": 50, "n_joints": 3}, 2)
    assert out["values"] == 150
    assert out["drift"] == pytest.approx(0.1)
    assert out["zero_norm"] == pytest.approx(0.1 * np.sqrt(2))
    assert out["scale_ratio"] == pytest.approx(np.linalg.norm(pm, axis=1).mean() / (0.1 * np.sqrt(2)))
    s = np.linalg.svd(pm - pm.mean(0), compute_uv=False)
    assert out["condition"] == pytest.approx(s[0] / s[1])
    assert out["condition"] > 5
    assert 0.9 < out["top_share"] < 1


def test_the_real_preset_is_the_protocol():
    from primspace.experiments.presets import PRESETS, REAL_PRESET
    from primspace.report.real_tables import REAL

    assert REAL == REAL_PRESET  # the preset whose summaries docs/real.md shows
    p = PRESETS[REAL_PRESET]
    assert (p.train_fraction, p.latent_dims, p.seeds, p.fit_epochs, p.infer_epochs) == (0.2, (8,), (0, 1, 2), 400, 250)
    assert {"zero", "random", "projection", "calibrated", "pca"} == set(p.inits)
    assert not p.images
