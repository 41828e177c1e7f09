"""The linear probe (issue 14, "structure as a number"): it recovers a planted linear
factor, gives nothing for noise even with nearly as many code dimensions as samples (no
leakage from the held-out folds), probes within each group, refuses bad input in one
line; and the intra experiment writes its table into the results and the report."""

import numpy as np
import pytest

from primspace.probe import linear_probe
from primspace.utils.errors import UserError


def _planted(n=120, q=10, seed=0, noise=0.01):
    rng = np.random.default_rng(seed)
    Z = rng.normal(size=(n, q))
    w = rng.normal(size=q)
    linear = Z @ w + noise * rng.normal(size=n)
    unrelated = rng.normal(size=n)
    return Z, np.stack([linear, unrelated], axis=1)


def test_a_planted_linear_factor_is_recovered_and_noise_is_not():
    Z, F = _planted()
    result = linear_probe(Z, F, factor_names=["linear", "noise"])
    assert result.r2["linear"] > 0.99
    assert result.r2["noise"] < 0.1
    assert result.mean_r2 == pytest.approx((result.r2["linear"] + result.r2["noise"]) / 2)
    assert result.n_samples == 120 and result.skipped_groups == []


def test_no_leakage_with_nearly_as_many_dimensions_as_samples():
    """In-sample least squares would give R² near 1 here; held-out folds give none."""
    rng = np.random.default_rng(3)
    Z, y = rng.normal(size=(40, 35)), rng.normal(size=40)
    assert linear_probe(Z, y).r2["factor_0"] < 0.1


def test_probe_is_within_each_group():
    """A factor linear in the codes with a different map per group: per-group probes
    recover it; one probe across the groups cannot."""
    rng = np.random.default_rng(1)
    Z = rng.normal(size=(200, 4))
    groups = np.repeat([0, 1], 100)
    y = np.where(groups == 0, Z[:, 0], -Z[:, 0])
    within = linear_probe(Z, y, groups)
    assert set(within.per_group) == {"0", "1"}
    assert all(v["factor_0"] > 0.99 for v in within.per_group.values())
    assert within.r2["factor_0"] > 0.99
    assert linear_probe(Z, y).r2["factor_0"] < 0.1


def test_constant_factors_and_tiny_groups():
    rng = np.random.default_rng(2)
    Z = rng.normal(size=(23, 3))
    F = np.stack([Z[:, 1], np.full(23, 0.05)], axis=1)
    groups = np.r_[np.zeros(20, int), np.ones(3, int)]
    result = linear_probe(Z, F, groups, factor_names=["x", "size"])
    assert result.r2["size"] is None and result.per_group["0"]["size"] is None
    assert result.skipped_groups == ["1"] and result.n_samples == 20
    assert result.mean_r2 == pytest.approx(result.r2["x"])


def test_same_seed_same_numbers_and_the_seed_matters():
    rng = np.random.default_rng(4)
    Z, y = rng.normal(size=(30, 5)), rng.normal(size=30) + rng.normal(size=(30, 5))[:, 0]
    a, b = linear_probe(Z, y, random_state=0), linear_probe(Z, y, random_state=0)
    assert a.to_dict() == b.to_dict()
    assert linear_probe(Z, y, random_state=1).r2 != a.r2


@pytest.mark.parametrize(
    "args, message",
    [
        ((np.zeros((5, 2)), np.zeros((4, 1))), "5 codes but 4 rows"),
        ((np.zeros(5), np.zeros((5, 1))), "codes must be (n, q)"),
        ((np.r_[np.zeros((3, 2)), [[np.nan, 0]]], np.zeros((4, 1))), "codes of sample 3 are not finite"),
        ((np.zeros((4, 2)), np.zeros((4, 1)), np.zeros(3)), "groups must have one entry per code"),
    ],
)
def test_bad_input_is_one_line(args, message):
    with pytest.raises(UserError) as info:
        linear_probe(*args)
    assert message in str(info.value) and "\n" not in str(info.value)


@pytest.mark.slow
def test_the_intra_experiment_probes_every_run_and_reports_it(tmp_path):
    from primspace.experiments.intra import run_intra
    from primspace.experiments.runs import initial_codes
    from primspace.experiments.workspace import ExperimentDir
    from primspace.report import build_report
    from primspace.results.readers import read_results
    from primspace.results.tables import probe_table
    from primspace.sim.generate import GenerationConfig, generate_dataset
    from test_experiments import TINY

    config = GenerationConfig(
        block_x=(0.45, 0.5, 0.55), block_y=(-0.05, 0.05), block_size=(0.05,), length=31, images=False
    )
    data_path = tmp_path / "data.h5"
    generate_dataset(config, seed=0, out=data_path, progress=False)
    exp = ExperimentDir(tmp_path / "exp", TINY, data=data_path, workers=1, progress=False)
    run_intra(exp)
    results = read_results(exp.path, "probe")
    assert results["factor_names"] == ["block_x", "block_y", "block_size"]
    assert {(r["init"], r["latent_dim"]) for r in results["runs"]} == {("zero", 4), ("projection", 4)}
    data = exp.dataset()
    for r in results["runs"]:
        for codes in ("fitted", "inferred", "initial"):
            assert r[codes]["r2"]["block_size"] is None  # one block size: nothing to probe
        # the untrained codes, recomputed: P m of a motion that follows the block reads the block
        expected = linear_probe(
            initial_codes(exp, r["init"], 4, 0), data.params, data.labels, factor_names=list(data.param_names)
        )
        assert r["initial"]["r2"] == pytest.approx(expected.r2)
    by_init = {r["init"]: r for r in results["runs"]}
    assert by_init["projection"]["initial"]["r2"]["block_x"] > 0.5
    assert by_init["zero"]["initial"]["r2"]["block_x"] <= 0.0  # all-zero codes carry nothing
    columns, rows = probe_table(results)
    assert columns[-1] == "mean R²" and len(rows) == 6
    assert "Linear probe of the codes." in build_report(exp.path).read_text()
