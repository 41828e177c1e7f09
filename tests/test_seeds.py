"""Results over seeds (issue 14, "say for each of the paper's claims whether it holds in
every seed"): the claims checked seed by seed, and the mean ± std table, on synthetic
intra results whose numbers we choose."""

import json

from primspace.experiments.claims import check_claims


def _run(init, seed, fit, start, end, q=10):
    return {"init": init, "latent_dim": q, "seed": seed,
            "fit": [{"epoch": 0, "loss": 1.0}, {"epoch": 1, "loss": fit}],
            "infer": [{"epoch": 0, "loss": start}, {"epoch": 1, "loss": end}]}


def _write(tmp_path, runs):
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "intra.json").write_text(json.dumps({"runs": runs}))
    return {r["key"]: r for r in check_claims(tmp_path)}


def test_a_claim_holding_in_one_seed_of_two_says_which(tmp_path):
    # "did not converge at all": random's final eval loss >= 10x projection's; seed 1 breaks it
    runs = [_run("projection", 0, 1e-4, 1e-2, 1e-4), _run("random", 0, 1e-3, 0.3, 1e-2),
            _run("projection", 1, 1e-4, 1e-2, 1e-4), _run("random", 1, 1e-3, 0.3, 5e-4)]
    rows = _write(tmp_path, runs)
    assert rows["infer_random"]["verdict"] == "holds in 1 of 2 seeds (not in seed 1)"
    assert rows["infer_random"]["ours"].startswith("seed 0: random / projection final eval loss: q = 10: 100x")
    assert "; seed 1: random / projection final eval loss: q = 10: 5x" in rows["infer_random"]["ours"]
    assert rows["fit_random"]["verdict"] == "holds in every seed (2 of 2)"  # 10x in both
    assert rows["fit_zero"]["verdict"] == "cannot be checked"  # no zero runs


def test_one_seed_reads_as_before(tmp_path):
    rows = _write(tmp_path, [_run("projection", 0, 1e-4, 1e-2, 1e-4), _run("random", 0, 1e-3, 0.3, 1e-2)])
    assert rows["infer_random"]["verdict"] == "holds"
    assert rows["infer_random"]["ours"].startswith("random / projection final eval loss: q = 10: 100x")


def test_random_fit_claim_needs_a_low_dimensional_latent_size(tmp_path):
    # "performs very badly for low-dimensional latent space": a q = 40-only grid cannot say
    rows = _write(tmp_path, [_run("projection", 0, 1e-4, 1e-2, 1e-4, q=40), _run("random", 0, 1e-3, 0.3, 1e-2, q=40)])
    assert rows["fit_random"]["verdict"] == "cannot be checked"
    assert rows["fit_random"]["ours"].startswith("needs runs at a low-dimensional latent size (q <= 20)")


def test_no_seed_holding_is_said(tmp_path):
    runs = [_run("projection", s, 1e-4, 1e-2, 1e-4) for s in (0, 1)] + [_run("random", s, 2e-4, 0.3, 2e-4) for s in (0, 1)]
    assert _write(tmp_path, runs)["infer_random"]["verdict"] == "does not hold in any seed (0 of 2)"


def test_spread_table_is_mean_and_std_over_seeds():
    import numpy as np

    from primspace.experiments.results import spread_table

    runs = [_run("projection", s, fit, 1e-2, end) for s, fit, end in ((0, 1e-4, 2e-4), (1, 3e-4, 4e-4), (2, 2e-4, 9e-4))]
    probe = {"runs": [{"init": "projection", "latent_dim": 10, "seed": s, "inferred": {"mean_r2": v}}
                      for s, v in ((0, 0.9), (1, 0.8), (2, None))]}
    columns, rows = spread_table({"runs": runs}, probe)
    assert columns[-1] == "probe R² (inferred codes)"
    fit, end = np.array([1e-4, 3e-4, 2e-4]), np.array([2e-4, 4e-4, 9e-4])
    assert rows == [["projection", 10, 3, f"{fit.mean():.3g} ± {fit.std():.2g}", "0.01 ± 0",
                     f"{end.mean():.3g} ± {end.std():.2g}", "0.85 ± 0.05"]]
    assert spread_table({"runs": runs[:1]}) is None  # one seed: no spread


def test_clustering_and_success_over_seeds(tmp_path):
    """Two seeds: the first seed's results are those of a one-seed experiment, bit for
    bit; the second's are under ``by_seed``; the outcome table averages both."""
    from dataclasses import replace

    import numpy as np
    from test_experiments import TINY

    from primspace.experiments.clustering import run_clustering
    from primspace.experiments.results import outcome_spread_table
    from primspace.experiments.success import run_success
    from primspace.experiments.workspace import ExperimentDir
    from primspace.sim.generate import GenerationConfig, generate_dataset

    config = GenerationConfig(block_x=(0.45, 0.55), block_y=(0.0,), block_size=(0.05,), length=31, images=False)
    data = tmp_path / "tiny.h5"
    generate_dataset(config, seed=0, out=data, progress=False)
    one = ExperimentDir(tmp_path / "one", TINY, data=data, workers=1, progress=False)
    two = ExperimentDir(tmp_path / "two", replace(TINY, seeds=(0, 1)), data=data, workers=1, progress=False)
    (c1, s1), (c2, s2) = [(run_clustering(e), run_success(e)) for e in (one, two)]
    assert c2["latent"] == c1["latent"] and s2["generated"] == s1["generated"]
    assert c1["by_seed"] == {} and s1["by_seed"] == {}
    assert {r["init"] for r in c2["by_seed"]["1"]} == {"zero", "projection"} and len(c2["by_seed"]["1"]) == 3
    assert set(s2["by_seed"]["1"]) == {"zero", "projection"}
    assert outcome_spread_table(c1, s1) is None
    columns, rows = outcome_spread_table(c2, s2)
    row = next(r for r in rows if r[0] == "projection")
    rates = [s2["generated"]["projection"]["overall"], s2["by_seed"]["1"]["projection"]["overall"]]
    assert row[1] == 2 and row[2] == f"{np.mean(rates):.3g} ± {np.std(rates):.2g}"
    assert any(r[0] == "untrained P m" for r in rows)


def test_success_and_clustering_claims_are_checked_in_every_seed(tmp_path):
    def rates(zero_grasp, projection_grasp):
        return {"zero": {"rates": {"pull": 1.0, "push": 1.0, "grasp": zero_grasp}},
                "projection": {"rates": {"pull": 1.0, "push": 1.0, "grasp": projection_grasp}}}

    def latent(zero, projection):
        return [{"init": "zero", "codes": "learned", "accuracy": zero}, {"init": "projection", "codes": "learned", "accuracy": projection}]

    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "success.json").write_text(json.dumps(
        {"seed": 0, "generated": rates(0.2, 0.9), "by_seed": {"1": rates(0.95, 0.9), "2": rates(0.3, 1.0)}}))
    (tmp_path / "results" / "clustering.json").write_text(json.dumps(
        {"seed": 0, "latent_dim": 40, "latent": latent(0.5, 0.9), "by_seed": {"1": latent(0.8, 0.85)}}))
    rows = {r["key"]: r for r in check_claims(tmp_path)}
    assert rows["success"]["verdict"] == "holds in 2 of 3 seeds (not in seed 1)"
    assert "seed 1: zero / projection success: pull 1.00 / 1.00, push 1.00 / 1.00, grasp 0.95 / 0.90" in rows["success"]["ours"]
    assert rows["clustering"]["verdict"] == "holds in 1 of 2 seeds (not in seed 0)"
