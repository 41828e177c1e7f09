"""Rules version 4 (issue 42, "the scoreboard"): every verdict has a direction, rules about
every latent size give their verdict at each, ``infer_projection`` reads its whole sentence
(the codes' drift from P m), inter compares the sample std over folds, and the Summary's
intra-and-inter sentence is checked. Small results dicts whose numbers we choose."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from primspace.results.claim_rules_v2 import clustering_similar, random_fit_bad, zero_within
from primspace.results.claim_rules_v4 import (
    CODE_DRIFT,
    LITTLE_CHANGE,
    code_drift,
    inter_improved,
    intra_and_inter_improved,
    projection_good_and_still,
)
from primspace.results.claim_verdicts import AGAINST, AS_SAID, IN_FAVOUR, PARTLY, UNCHECKABLE, Outcome, rule_verdict
from primspace.results.claims import CLAIMS, RULES_VERSION, check_claims, claims_table, codes_of_summary
from primspace.results.layout import LEARNED_CODES


def _run(init, q, seed=0, fit=1e-4, start=1e-2, end=1e-4):
    return {
        "init": init,
        "latent_dim": q,
        "seed": seed,
        "fit": [{"epoch": 0, "loss": 1.0}, {"epoch": 1, "loss": fit}],
        "infer": [{"epoch": 0, "loss": start}, {"epoch": 1, "loss": end}],
    }


def _fold(init, f, early, last, seed=0):
    curve = [{"epoch": e, "loss": v} for e, v in enumerate([1.0] + [early] * 8 + [last])]
    return {"init": init, "fold": f, "seed": seed, "phase2": curve}


def _inter(better: bool, seeds=(0,)):
    runs = []
    for s in seeds:
        runs += [_fold("zero", f, 0.1, 1e-3 * (1 + f), s) for f in range(7)]
        p = (0.05, 0.5e-3) if better else (0.2, 2e-3)
        runs += [_fold("projection", f, p[0], p[1] * (1 + f), s) for f in range(7)]
    return {"runs": runs}


def test_the_rule_set_is_version_4_and_quotes_the_summary_whole():
    assert RULES_VERSION == 4 == max(c.version for c in CLAIMS)
    claim = next(c for c in CLAIMS if c.key == "central_intra_inter")
    assert claim.experiment == ("intra", "inter")
    assert claim.quote == (
        "Initialization of the latent variable by random linear projections improves intra- and inter-primitive "
        "generalization capabilities compared to conventional initialization methods."
    )
    paper = Path(__file__).resolve().parents[2] / "shared" / "paper.tex"
    if paper.exists():
        text = re.sub(r"\s+", " ", paper.read_text(encoding="utf-8"))
        assert all(c.quote in text for c in CLAIMS)


# ---------------------------------------------------------------- directions, counted


def test_a_direction_is_read_from_the_verdict_and_counted_over_seeds():
    def check(view):
        ok = {0: True, 1: False, 2: PARTLY}[view["runs"][0]["seed"]]
        return Outcome(ok, "", None, {1: IN_FAVOUR, 2: AGAINST}.get(view["runs"][0]["seed"]))

    runs = [_run("projection", 10, s) for s in range(3)]
    row = rule_verdict(check, "intra", {"runs": runs})
    assert row["direction"] == "in the paper's favour in seed 1; against the paper in seed 2"
    assert rule_verdict(check, "intra", {"runs": runs[:1]})["direction"] == AS_SAID
    # the seeds that hold aside, one direction is the row's
    assert rule_verdict(check, "intra", {"runs": runs[:2]})["direction"] == IN_FAVOUR
    # a rule that names no direction: a failure is against the paper; None cannot be checked
    assert rule_verdict(lambda v: (False, ""), "intra", {"runs": runs[:1]})["direction"] == AGAINST
    assert rule_verdict(lambda v: (None, ""), "intra", {"runs": runs[:1]})["direction"] == UNCHECKABLE


def test_zero_far_above_projection_is_in_the_papers_favour_far_below_against():
    check = zero_within("fit", "fit")
    far_above = {"runs": [_run("projection", 40, fit=1e-5), _run("zero", 40, fit=1e-3)]}
    assert check(far_above).ok is False and check(far_above).direction == IN_FAVOUR
    far_below = {"runs": [_run("projection", 40, fit=1e-3), _run("zero", 40, fit=1e-5)]}
    assert check(far_below).ok is False and check(far_below).direction == AGAINST
    near = {"runs": [_run("projection", 40, fit=1e-5), _run("zero", 40, fit=1.5e-5)]}
    assert check(near).ok is True


def test_clustering_not_similar_because_projection_is_better_is_in_the_papers_favour():
    def results(zero, projection):
        rows = [
            {"init": i, "codes": LEARNED_CODES, "accuracy": a} for i, a in (("zero", zero), ("projection", projection))
        ]
        return {"latent_dim": 40, "latent": rows, "trajectory": {"data": {"k": 7}}}

    assert clustering_similar(results(0.45, 0.9)).direction == IN_FAVOUR
    assert clustering_similar(results(0.9, 0.45)).direction == AGAINST
    near_chance = clustering_similar(results(0.2, 0.25))
    assert near_chance.ok == PARTLY and near_chance.direction == AGAINST  # self-organisation absent


def test_a_sentence_about_a_setting_not_run_cannot_be_checked_at_this_scale():
    only_40 = {"intra": {"runs": [_run("projection", 40), _run("random", 40, fit=1e-2)]}}
    row = next(r for r in check_claims(only_40) if r["key"] == "fit_random")
    assert row["verdict"] == "cannot be checked" and row["direction"] == UNCHECKABLE
    assert random_fit_bad({"runs": [_run("projection", 10), _run("random", 10, fit=2e-4)]}).direction == AGAINST
    assert next(r for r in check_claims(only_40) if r["key"] == "inter")["direction"] == UNCHECKABLE  # not run


# ---------------------------------------------------------------- verdicts at every q


def test_rules_about_every_q_give_the_verdict_at_each():
    runs = [_run("projection", 10), _run("zero", 10, end=1e-3), _run("projection", 20), _run("zero", 20, end=1.5e-4)]
    rows = {r["key"]: r for r in check_claims({"intra": {"runs": runs}})}
    central = rows["central_generalisation"]
    assert central["verdict"] == "partly"  # 10x at q = 10, 1.5x at q = 20
    assert central["by_q"] == {10: "holds", 20: "partly"}
    assert central["direction"] == AGAINST
    _, table = claims_table({"intra": {"runs": runs}})
    text = next(r for r in table if "substantial improvement" in r[0])[2]
    assert "partly — by latent size: q = 10: holds; q = 20: partly" in text
    assert rows["infer_similar"]["by_q"] == {10: "does not hold", 20: "holds"}
    assert rows["infer_similar"]["direction"] == IN_FAVOUR  # zero 10x projection's at q = 10


def test_the_verdict_at_each_q_is_counted_over_seeds():
    runs = [_run("projection", q, s) for q in (10, 20) for s in (0, 1)]
    runs += [_run("zero", 10, s, end=1e-3) for s in (0, 1)]
    runs += [_run("zero", 20, 0, end=1e-3), _run("zero", 20, 1, end=1.5e-4)]
    row = next(r for r in check_claims({"intra": {"runs": runs}}) if r["key"] == "central_generalisation")
    assert row["by_q"] == {10: "holds in every seed (2 of 2)", 20: "holds in 1 of 2 seeds, partly in 1 (seed 1)"}


# ---------------------------------------------------------------- infer_projection, whole


def _good(q=40, seed=0, proj_start=1e-3, zero_end=1e-2):
    return [_run("projection", q, seed, start=proj_start), _run("zero", q, seed, end=zero_end)]


def test_infer_projection_needs_both_halves():
    still, moved = {"q40-s0": 0.05}, {"q40-s0": 0.6}
    both = projection_good_and_still({"runs": _good(), CODE_DRIFT: still})
    assert both.ok is True and both.by_q == {40: True}
    unchecked = projection_good_and_still({"runs": _good()})  # no codes
    assert unchecked.ok == PARTLY and unchecked.direction == UNCHECKABLE
    assert "cannot be checked" in unchecked.numbers
    half = projection_good_and_still({"runs": _good(), CODE_DRIFT: moved})
    assert half.ok == PARTLY and half.direction == AGAINST and f"below {LITTLE_CHANGE:g}" in half.numbers
    bad_start = projection_good_and_still({"runs": _good(proj_start=1e-1), CODE_DRIFT: still})
    assert bad_start.ok == PARTLY and bad_start.direction == AGAINST
    neither = projection_good_and_still({"runs": _good(proj_start=1e-1), CODE_DRIFT: moved})
    assert neither.ok is False and neither.direction == AGAINST
    assert projection_good_and_still({"runs": _good(proj_start=1e-1)}).ok is False  # at most partly, and it fails


def test_infer_projection_gives_each_q_with_the_codes_it_has():
    runs = _good(10) + _good(20)
    outcome = projection_good_and_still({"runs": runs, CODE_DRIFT: {"q10-s0": 0.05}})
    assert outcome.by_q == {10: True, 20: PARTLY}  # q = 20's codes missing
    assert outcome.ok is True  # the codes it has are still, and projection is good at every q


def _codes_npz(path, drift):
    """A codes file of one projection and one zero run, projection's fit moved by ``drift``."""
    rng = np.random.default_rng(0)
    init = rng.standard_normal((20, 40)).astype(np.float32)
    direction = rng.standard_normal((20, 40))
    moved = init + drift * np.linalg.norm(init, axis=1, keepdims=True) * direction / np.linalg.norm(
        direction, axis=1, keepdims=True
    )
    arrays = {"runs": np.array(["intra/zero-q40-s0", "intra/projection-q40-s0"]), "primspace_codes_version": 1}
    for key, fit, fit0 in (("intra/zero-q40-s0", init, np.zeros_like(init)), ("intra/projection-q40-s0", moved, init)):
        for phase in ("fit", "infer"):
            arrays[f"{key}/{phase}/latents"] = fit.astype(np.float32)
            arrays[f"{key}/{phase}/latents_init"] = fit0
            arrays[f"{key}/{phase}/indices"] = np.arange(20)
    np.savez_compressed(path, **arrays)
    return path


def test_the_codes_drift_is_read_from_a_codes_file_and_a_directory(tmp_path):
    npz = _codes_npz(tmp_path / "x.codes.npz", 0.1)
    assert code_drift(npz) == pytest.approx({"q40-s0": 0.1}, rel=1e-4)  # the zero run (|P m| = 0) is left out
    fit = tmp_path / "exp" / "runs" / "intra" / "projection-q10-s2" / "fit"
    fit.mkdir(parents=True)
    np.save(fit / "latents_init.npy", np.ones((4, 10)))
    np.save(fit / "latents.npy", np.full((4, 10), 1.5))
    assert code_drift(tmp_path / "exp") == pytest.approx({"q10-s2": 0.5})
    assert code_drift(tmp_path / "nowhere") == {}


def test_check_claims_reads_the_codes_it_is_given(tmp_path):
    results = {"intra": {"runs": _good()}}
    rows = {r["key"]: r for r in check_claims(results, _codes_npz(tmp_path / "still.codes.npz", 0.1))}
    assert rows["infer_projection"]["verdict"] == "holds" and rows["infer_projection"]["version"] == 4
    assert rows["infer_projection"]["previous"][0]["version"] == 1
    rows = {r["key"]: r for r in check_claims(results, _codes_npz(tmp_path / "moved.codes.npz", 0.5))}
    assert rows["infer_projection"]["verdict"] == "partly"
    assert rows["infer_projection"]["direction"] == AGAINST
    row = next(r for r in check_claims(results) if r["key"] == "infer_projection")
    assert row["verdict"] == "partly" and row["direction"] == UNCHECKABLE
    # a summary names its codes file; it is looked for in the given folder
    assert codes_of_summary({"codes": {"file": "still.codes.npz"}}, tmp_path) == tmp_path / "still.codes.npz"
    assert codes_of_summary({"codes": {"file": "gone.codes.npz"}}, tmp_path) is None
    assert codes_of_summary({}, tmp_path) is None


# ---------------------------------------------------------------- inter, sample std


def test_inter_robustness_compares_the_sample_std_and_keeps_v2_beside_it():
    # projection ran 3 folds, zero 7: the ddof changes projection's std more than zero's
    zero = [_fold("zero", f, 0.1, v) for f, v in enumerate([1.0, 3.0, 1.0, 3.0, 1.0, 3.0, 1.0])]
    proj = [_fold("projection", f, 0.05, v) for f, v in enumerate([0.5, 2.4, 0.5])]
    v4 = inter_improved({"runs": zero + proj})
    assert "sample std (ddof 1)" in v4.numbers and "robustness" in v4.numbers
    rows = {r["key"]: r for r in check_claims({"inter": {"runs": zero + proj}})}
    inter = rows["inter"]
    assert inter["version"] == 4
    assert [p["version"] for p in inter["previous"]] == [1, 2]
    # ddof 0: projection 0.90 < zero 0.99 (robust); ddof 1: 1.10 > 1.07 (not): v2 holds, v4 partly
    assert inter["previous"][1]["verdict"] == "holds"
    assert inter["verdict"] == "partly" and inter["direction"] == AGAINST


# ---------------------------------------------------------------- the Summary's intra and inter


def _summary(intra_factor, inter_better):
    runs = [_run("projection", 20, 0), _run("zero", 20, 0, end=1e-4 * intra_factor)]
    return {"intra": {"runs": runs}, "inter": _inter(inter_better)}


def test_the_summary_sentence_needs_intra_and_inter():
    assert intra_and_inter_improved(_summary(10, True)).ok is True
    assert intra_and_inter_improved(_summary(10, False)).ok == PARTLY  # intra holds, inter does not
    assert intra_and_inter_improved(_summary(0.5, True)).ok == PARTLY  # inter holds, intra does not
    assert intra_and_inter_improved(_summary(1.5, True)).ok == PARTLY  # intra only partly (1.5x)
    neither = intra_and_inter_improved(_summary(0.5, False))
    assert neither.ok is False and neither.direction == AGAINST
    missing = intra_and_inter_improved({"intra": _summary(10, True)["intra"], "inter": None})
    assert missing.ok is None and "inter did not run" in missing.numbers


def test_check_claims_reads_both_experiments_of_the_summary_sentence(tmp_path):
    rows = {r["key"]: r for r in check_claims(_summary(10, True))}
    assert rows["central_intra_inter"]["verdict"] == "holds"
    assert rows["central_intra_inter"]["direction"] == AS_SAID
    rows = {r["key"]: r for r in check_claims({"intra": _summary(10, True)["intra"]})}
    assert rows["central_intra_inter"]["verdict"] == "cannot be checked"
    assert rows["central_intra_inter"]["direction"] == UNCHECKABLE
    assert next(r for r in check_claims({}) if r["key"] == "central_intra_inter")["verdict"] == "not run"
    # from a directory, seed by seed: seed 1's inter is not improved
    (tmp_path / "results").mkdir()
    intra = {"runs": [_run("projection", 20, s) for s in (0, 1)] + [_run("zero", 20, s, end=1e-3) for s in (0, 1)]}
    inter = {"runs": _inter(True, (0,))["runs"] + _inter(False, (1,))["runs"]}
    (tmp_path / "results" / "intra.json").write_text(json.dumps(intra))
    (tmp_path / "results" / "inter.json").write_text(json.dumps(inter))
    row = next(r for r in check_claims(tmp_path) if r["key"] == "central_intra_inter")
    assert row["verdict"] == "holds in 1 of 2 seeds, partly in 1 (seed 1)"
    assert row["direction"] == AGAINST


def test_the_docs_and_report_tables_have_a_direction_column():
    from primspace.report.summary_tables import render_summary

    columns, rows = claims_table(_summary(10, True))
    assert columns == ["the paper (verbatim)", "rule (version): what we test", "verdict", "direction", "ours"]
    assert all(r[3] in (AS_SAID, IN_FAVOUR, AGAINST, UNCHECKABLE) for r in rows)
    summary = {"name": "x", "command": "primspace experiment intra", "results": _summary(10, True)}
    text = render_summary(summary)
    assert "| the paper (verbatim) | rule (version): what we test | verdict | direction | earlier rule |" in text
    assert "| as the paper says |" in text
