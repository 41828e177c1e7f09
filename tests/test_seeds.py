"""Results over seeds (issue 14, "say for each of the paper's claims whether it holds in
every seed"): the claims checked seed by seed, and the mean ± std table, on synthetic
intra results whose numbers we choose."""

import json

from primspace.results.claims import check_claims


def _run(init, seed, fit, start, end, q=10):
    return {
        "init": init,
        "latent_dim": q,
        "seed": seed,
        "fit": [{"epoch": 0, "loss": 1.0}, {"epoch": 1, "loss": fit}],
        "infer": [{"epoch": 0, "loss": start}, {"epoch": 1, "loss": end}],
    }


def _write(tmp_path, runs):
    (tmp_path / "results").mkdir(parents=True)
    (tmp_path / "results" / "intra.json").write_text(json.dumps({"runs": runs}))
    return {r["key"]: r for r in check_claims(tmp_path)}


def test_a_claim_holding_in_one_seed_of_two_says_which(tmp_path):
    # "did not converge at all" (rule v2): random's own eval loss falls < 2x (holds); it falls but
    # ends >= 10x projection's (partly); else does not hold. Seed 0: 30x drop, 100x projection's
    # (partly); seed 1: 1.5x drop (holds literally).
    runs = [
        _run("projection", 0, 1e-4, 1e-2, 1e-4),
        _run("random", 0, 1e-3, 0.3, 1e-2),
        _run("projection", 1, 1e-4, 1e-2, 1e-4),
        _run("random", 1, 1e-3, 0.3, 0.2),
    ]
    rows = _write(tmp_path, runs)
    assert rows["infer_random"]["verdict"] == "holds in 1 of 2 seeds, partly in 1 (seed 0)"
    assert rows["infer_random"]["per_seed"] == {"0": "partly", "1": "holds"}
    assert rows["infer_random"]["ours"].startswith("seed 0: random's own eval loss falls q = 10: 30x; it ends at 100x")
    assert rows["infer_random"]["version"] == 2
    # the version-1 rule (random >= 10x projection at the end) stays readable beside it
    assert rows["infer_random"]["previous"] == [
        {
            "version": 1,
            "test": "final eval loss (θ frozen) of random at least 10x projection's at every q",
            "verdict": "holds in every seed (2 of 2)",
        }
    ]
    assert rows["fit_random"]["verdict"] == "holds in every seed (2 of 2)"  # 10x in both
    assert rows["fit_random"]["previous"] == []  # an unchanged rule has no earlier version
    assert rows["fit_zero"]["verdict"] == "cannot be checked"  # no zero runs


def test_a_seed_where_a_claim_fails_is_named(tmp_path):
    runs = [
        _run("projection", 0, 1e-4, 1e-2, 1e-4),
        _run("random", 0, 1e-3, 0.3, 1e-2),
        _run("projection", 1, 1e-4, 1e-2, 1e-4),
        _run("random", 1, 1e-3, 0.3, 5e-4),
    ]
    rows = _write(tmp_path, runs)  # seed 1: random falls 600x to 5x projection's: does not hold
    assert rows["infer_random"]["verdict"] == "partly in 1 of 2 seeds (seed 0), not in seed 1"
    runs[1] = _run("random", 0, 1e-3, 0.3, 0.25)
    assert _write(tmp_path / "b", runs)["infer_random"]["verdict"] == "holds in 1 of 2 seeds (not in seed 1)"


def test_one_seed_reads_as_before(tmp_path):
    rows = _write(tmp_path, [_run("projection", 0, 1e-4, 1e-2, 1e-4), _run("random", 0, 1e-3, 0.3, 1e-2)])
    assert rows["infer_random"]["verdict"] == "partly"
    assert rows["infer_random"]["previous"][0]["verdict"] == "holds"


def test_random_fit_claim_needs_a_low_dimensional_latent_size(tmp_path):
    # "performs very badly for low-dimensional latent space": a q = 40-only grid cannot say
    rows = _write(tmp_path, [_run("projection", 0, 1e-4, 1e-2, 1e-4, q=40), _run("random", 0, 1e-3, 0.3, 1e-2, q=40)])
    assert rows["fit_random"]["verdict"] == "cannot be checked"
    assert rows["fit_random"]["ours"].startswith("needs runs at a low-dimensional latent size (q <= 20)")


def test_no_seed_holding_is_said(tmp_path):
    runs = [_run("projection", s, 1e-4, 1e-2, 1e-4) for s in (0, 1)] + [
        _run("random", s, 2e-4, 0.3, 2e-4) for s in (0, 1)
    ]
    assert _write(tmp_path, runs)["infer_random"]["verdict"] == "does not hold in any seed (0 of 2)"


def test_spread_table_is_mean_and_std_over_seeds():
    import numpy as np

    from primspace.results.tables import spread_table

    runs = [
        _run("projection", s, fit, 1e-2, end) for s, fit, end in ((0, 1e-4, 2e-4), (1, 3e-4, 4e-4), (2, 2e-4, 9e-4))
    ]
    probe = {
        "runs": [
            {"init": "projection", "latent_dim": 10, "seed": s, "inferred": {"mean_r2": v}}
            for s, v in ((0, 0.9), (1, 0.8), (2, None))
        ]
    }
    columns, rows = spread_table({"runs": runs}, probe)
    assert columns[-1] == "probe R² (inferred codes)"
    fit, end = np.array([1e-4, 3e-4, 2e-4]), np.array([2e-4, 4e-4, 9e-4])
    # the sample std (ddof 1): fit sqrt((1e-8 + 1e-8 + 0) / 2) = 1e-4, end 3.6e-4; the probe's
    # two values 0.9, 0.8 (the third is missing): sqrt(2 * 0.05^2 / 1) = 0.0707
    assert rows == [
        [
            "projection",
            10,
            3,
            f"{fit.mean():.3g} ± {fit.std(ddof=1):.2g}",
            "0.01 ± 0",
            f"{end.mean():.3g} ± {end.std(ddof=1):.2g}",
            "0.85 ± 0.071",
        ]
    ]
    assert rows[0][3] == "0.0002 ± 0.0001" and rows[0][5] == "0.0005 ± 0.00036"
    assert spread_table({"runs": runs[:1]}) is None  # one seed: no spread


def _rates(zero, projection, n=100, by_tolerance=None):
    """Success results of zero and projection: {primitive: rate} each, ``n`` judged per primitive."""

    def one(rates, sweep):
        res = {
            "rates": rates,
            "counts": {p: n for p in rates},
            "successes": {p: round(r * n) for p, r in rates.items()},
        }
        if sweep is not None:
            res["by_tolerance"] = {
                t: {"rates": r, "successes": {p: round(v * n) for p, v in r.items()}} for t, r in sweep.items()
            }
        return res

    by_tolerance = by_tolerance or {}
    return {"zero": one(zero, by_tolerance.get("zero")), "projection": one(projection, by_tolerance.get("projection"))}


def _sensitive(pull, push, grasp):
    return {"pull": pull, "push": push, "grasp": grasp}


def test_success_and_clustering_claims_are_checked_in_every_seed(tmp_path):
    def latent(zero, projection):
        return [
            {"init": "zero", "codes": "learned", "accuracy": zero},
            {"init": "projection", "codes": "learned", "accuracy": projection},
        ]

    higher = _rates(_sensitive(0.5, 0.5, 0.2), _sensitive(0.95, 0.95, 0.9))  # every gap beyond the intervals
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "success.json").write_text(
        json.dumps(
            {
                "seed": 0,
                "generated": higher,
                "by_seed": {
                    "1": _rates(_sensitive(1, 1, 0.95), _sensitive(1, 1, 0.9)),  # ties and a small loss
                    "2": _rates(_sensitive(1, 1, 0.3), _sensitive(1, 1, 1.0)),
                },
            }
        )
    )  # ties, grasp higher
    trajectory = {"data": {"k": 7}}  # chance 1/7; "organised" from 0.57
    (tmp_path / "results" / "clustering.json").write_text(
        json.dumps(
            {
                "seed": 0,
                "latent_dim": 40,
                "trajectory": trajectory,
                "latent": latent(0.5, 0.9),
                "by_seed": {"1": latent(0.8, 0.85), "2": latent(0.3, 0.35)},
            }
        )
    )
    rows = {r["key"]: r for r in check_claims(tmp_path)}
    assert rows["success"]["verdict"] == "holds in 1 of 3 seeds, partly in 1 (seed 2), not in seed 1"
    assert (
        "seed 1: zero / projection success: pull 1.00 / 1.00, push 1.00 / 1.00, grasp 0.95 / 0.90"
        in rows["success"]["ours"]
    )
    assert "seed 0: zero / projection success: pull 0.50 / 0.95 (higher)" in rows["success"]["ours"]
    # version 1 counted ties as holding: seed 1's equal pull and push, but its grasp fell
    assert rows["success"]["previous"][0]["verdict"] == "holds in 2 of 3 seeds (not in seed 1)"
    # clustering: seed 0 not similar, seed 1 similar and organised, seed 2 similar near chance
    assert rows["clustering"]["verdict"] == "holds in 1 of 3 seeds, partly in 1 (seed 2), not in seed 0"
    assert rows["clustering"]["previous"][0]["verdict"] == "holds in 2 of 3 seeds (not in seed 0)"


def test_a_tie_never_counts_and_a_small_gap_is_within_the_spread(tmp_path):
    from primspace.results.claims import CLAIMS

    check = next(c for c in CLAIMS if c.key == "success").check
    tie = _rates(_sensitive(1.0, 1.0, 0.0), _sensitive(1.0, 1.0, 0.0))
    assert check({"generated": tie}).ok is False  # demo: grasp 0 / 0, pull, push 1 / 1
    small = _rates(_sensitive(0.86, 0.90, 0.80), _sensitive(0.92, 0.94, 1.0), n=50)
    assert check({"generated": small}).ok == "partly"  # only the grasp gap clears the intervals at n = 50
    assert check({"generated": _rates(_sensitive(0.86, 0.90, 0.80), _sensitive(0.92, 0.94, 1.0), n=1000)}).ok is True
    lower = _rates(_sensitive(0.5, 0.9, 0.2), _sensitive(0.9, 0.5, 0.9))
    assert check({"generated": lower}).ok is False  # push lower beyond the spread


def test_the_success_verdict_is_given_at_every_judge_tolerance(tmp_path):
    sweep = {
        "zero": {"0.004": _sensitive(0.86, 0.95, 0.25), "0.01": _sensitive(1.0, 1.0, 0.25)},
        "projection": {"0.004": _sensitive(0.82, 0.85, 0.99), "0.01": _sensitive(1.0, 1.0, 0.99)},
    }
    gen = _rates(_sensitive(1.0, 1.0, 0.25), _sensitive(1.0, 1.0, 0.99), n=196, by_tolerance=sweep)
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "success.json").write_text(json.dumps({"seed": 0, "generated": gen}))
    row = next(r for r in check_claims(tmp_path) if r["key"] == "success")
    assert row["verdict"] == "partly"  # grasp higher, pull and push tied at 10 mm
    assert row["sweep"] == {"0.004": "does not hold", "0.01": "partly"}  # push lower at 4 mm
    assert row["robust"] is False
    from primspace.results.claims import claims_table

    _, table = claims_table(tmp_path)
    text = next(r for r in table if "gripper fingers" in r[0])[2]
    assert "4 mm does not hold, 10 mm partly (NOT robust to the tolerance)" in text


def test_inter_claim_measures_speed_final_and_robustness_paired_by_fold(tmp_path):
    from primspace.results.claims import CLAIMS

    check = next(c for c in CLAIMS if c.key == "inter").check

    def fold(init, f, early, last):
        curve = [{"epoch": e, "loss": v} for e, v in enumerate([1.0] + [early] * 8 + [last])]
        return {"init": init, "fold": f, "seed": 0, "phase2": curve}

    zero = [fold("zero", f, 0.1, 1e-3 * (1 + f)) for f in range(7)]
    better = [fold("projection", f, 0.05, 0.5e-3 * (1 + f)) for f in range(7)]
    assert check({"runs": zero + better}).ok is True
    mixed = [fold("projection", f, 0.05 if f < 4 else 0.2, 0.5e-3 * (1 + f)) for f in range(7)]
    outcome = check({"runs": zero + mixed})
    assert outcome.ok == "partly" and "projection lower in 4 of 7 folds" in outcome.numbers
    assert check({"runs": zero + [fold("projection", f, 0.1, 1e-3 * (1 + f)) for f in range(7)]}).ok is False  # a tie
