"""The paper's claims, quoted verbatim, and the check of each against our results.

Where docs or the report say what "the paper" says, they quote it: :data:`CLAIMS` holds
whole sentences exactly as in shared/paper.tex (section *Experimental Results*), with the
sentence that carries their meaning where one leans on the next ("It may look like ...
very similar, but ..."), what we measure to test it, and the rule that decides.

**Rules are fixed before runs and versioned.** Each rule has a ``version`` and its
``threshold`` (the effect size it asks for). A rule that changes gets a new version and
its earlier versions stay in ``previous``: :func:`check_claims` gives every earlier
verdict beside the current one, so a reader sees what the change did. Version 1 (0.2-0.5)
is :mod:`primspace.experiments.claim_rules_v1`; version 2 (0.6) changed four rules:

- a tie never counts as an improvement, and a difference in success rates counts only
  when the Wilson 95 % intervals of the two rates do not overlap;
- "did not converge at all" is tested literally (random's own eval loss falls less than
  2x), "partly" when it falls but ends at least 10x above projection's (the next
  sentence: "no generalization capacity");
- clustering "similar results ... self-organize in a union of close to linear manifolds"
  needs both inits well above chance, "partly" when they are similar but near chance;
- inter "slightly improved ... convergence speed, final value ... robustness": each of
  the three measured, the first two paired fold by fold.

Version 3 (0.9) added the abstract's two central claims, first in the table
(:mod:`primspace.experiments.claim_rules_central`).

Verdicts: ``holds``, ``partly`` (the sentence half holds: the numbers say which half),
``does not hold``, ``cannot be checked`` (the runs it needs are missing), ``not run``.
With several seeds each seed is checked on its own (its own split, weights and P) and the
verdict counts them (:mod:`primspace.experiments.claim_verdicts`). The success rule is
also judged at every tolerance of the judge's declared sweep
(:data:`primspace.sim.success.SEPARATION_SWEEP`), with a robustness flag.

:func:`check_claims` reads an experiment directory, or the results held in a stored
summary (:mod:`primspace.experiments.summary`), through the same readers; this module
imports no experiment.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from primspace.experiments.claim_rules_central import (
    SUBSTANTIAL,
    WELL_SEPARATED_SHARE,
    chance_level,
    generalisation_improved,
    separated_from_the_onset,
)
from primspace.experiments.claim_rules_v1 import CLAIMS_V1, has_inits, losses_by_q  # the same readings of the results
from primspace.experiments.claim_verdicts import PARTLY, Outcome, rule_verdict
from primspace.experiments.results import LEARNED_CODES, read_results
from primspace.stats import wilson_interval

__all__ = ["Outcome", "Claim", "CLAIMS", "RULES_VERSION", "check_claims", "claims_table", "eighth_loss", "PARTLY"]

#: The version of the rule set as a whole (the highest version of any rule).
RULES_VERSION = 3


@dataclass(frozen=True)
class Claim:
    """One or more whole sentences of the paper and how we test them."""

    key: str
    experiment: str  # the results it reads: intra, clustering, success, inter
    where: str  # the paper's section / figure
    quote: str  # whole sentences, verbatim from shared/paper.tex
    test: str  # what we measure and the rule
    threshold: str  # the effect size the rule asks for, in words
    version: int
    check: Callable[[dict], Outcome]
    previous: tuple = field(default=(), compare=False)  # earlier rules (claim_rules_v1.Claim)


#: The largest latent size read as "low-dimensional latent space" (the paper's figure
#: shows several sizes without naming them; our grid is 10, 20, 40).
LOW_DIMENSIONAL_Q = 20
#: "performs very badly": random's final fit loss at least this many times projection's.
VERY_BADLY = 5.0
#: "differs very slightly" / "very similar": within this factor either way.
SIMILAR_FACTOR = 2.0
#: "did not converge at all": random's own eval loss falls by less than this factor.
NOT_CONVERGED_DROP = 2.0
#: "no generalization capacity": random's final eval loss at least this many times projection's.
NO_GENERALISATION = 10.0
#: "similar results" of clustering: accuracies within this distance.
SIMILAR_ACCURACY = 0.1
#: "self-organize in a union of close to linear manifolds": accuracy at least this far
#: from chance (1/k) towards 1 (0.5: halfway).
ORGANISED_SHARE = 0.5
#: Inter: "improved" in a paired comparison when projection is lower in at least this share of folds.
PAIRED_SHARE = 0.8


def _random_fit_bad(results: dict) -> Outcome:
    fits = losses_by_q(results, "fit")
    qs = [q for q, d in fits.items() if has_inits(d, "random", "projection")]
    if not qs:
        return Outcome(None, "needs random and projection runs")
    q = min(qs)
    if q > LOW_DIMENSIONAL_Q:
        return Outcome(
            None,
            f"needs runs at a low-dimensional latent size (q <= {LOW_DIMENSIONAL_Q}); the smallest here is q = {q}",
        )
    ratio = fits[q]["random"] / fits[q]["projection"]
    return Outcome(ratio >= VERY_BADLY, f"q = {q}: random's final fit loss is {ratio:.3g}x projection's")


def _zero_within(phase: str, what: str) -> Callable[[dict], Outcome]:
    """The check "zero's final ``phase`` loss lies within :data:`SIMILAR_FACTOR` of projection's at every q"."""

    def check(results: dict) -> Outcome:
        finals = losses_by_q(results, phase)
        ratios = {q: d["zero"] / d["projection"] for q, d in finals.items() if has_inits(d, "zero", "projection")}
        if not ratios:
            return Outcome(None, "needs zero and projection runs")
        ok = all(1 / SIMILAR_FACTOR <= r <= SIMILAR_FACTOR for r in ratios.values())
        return Outcome(
            ok, f"zero / projection final {what} loss: " + ", ".join(f"q = {q}: {r:.3g}" for q, r in ratios.items())
        )

    return check


def _random_not_converged(results: dict) -> Outcome:
    finals, starts = losses_by_q(results, "infer"), losses_by_q(results, "infer", 0)
    qs = [q for q, d in finals.items() if has_inits(d, "random", "projection")]
    if not qs:
        return Outcome(None, "needs random and projection runs")
    drops = {q: starts[q]["random"] / finals[q]["random"] for q in qs}
    ratios = {q: finals[q]["random"] / finals[q]["projection"] for q in qs}
    if all(d < NOT_CONVERGED_DROP for d in drops.values()):
        ok: bool | str = True
    elif all(r >= NO_GENERALISATION for r in ratios.values()):
        ok = PARTLY
    else:
        ok = False
    return Outcome(
        ok,
        "random's own eval loss falls "
        + ", ".join(f"q = {q}: {d:.2g}x" for q, d in drops.items())
        + "; it ends at "
        + ", ".join(f"{r:.3g}x" for r in ratios.values())
        + " projection's",
    )


def _projection_good_untrained(results: dict) -> Outcome:
    finals, starts = losses_by_q(results, "infer"), losses_by_q(results, "infer", 0)
    qs = [q for q, d in finals.items() if has_inits(d, "zero", "projection")]
    if not qs:
        return Outcome(None, "needs zero and projection runs")
    cmp = {q: (starts[q]["projection"], finals[q]["zero"]) for q in qs}
    ok = all(a < b for a, b in cmp.values())
    return Outcome(
        ok,
        "projection's eval loss before any inference step vs zero's after the last: "
        + ", ".join(f"q = {q}: {a:.2g} vs {b:.2g}" for q, (a, b) in cmp.items()),
    )


#: The primitives the paper's success table reports ("sensitive primitives").
SENSITIVE = ("pull", "push", "grasp")


def _successes(res: dict, prim: str, tolerance: str | None) -> tuple[int, int] | None:
    """(successes, judged) of ``prim`` in one init's success results, at ``tolerance``
    (a key of ``by_tolerance``; None: the judge's default)."""
    n = res.get("counts", {}).get(prim)
    rates = res["rates"] if tolerance is None else res.get("by_tolerance", {}).get(tolerance, {}).get("rates")
    if n is None or rates is None or prim not in rates:
        return None
    if tolerance is None and "successes" in res:
        return int(res["successes"][prim]), int(n)
    if tolerance is not None and "successes" in res["by_tolerance"][tolerance]:
        return int(res["by_tolerance"][tolerance]["successes"][prim]), int(n)
    return int(round(rates[prim] * n)), int(n)


def _compare_rates(zero: tuple[int, int], proj: tuple[int, int]) -> int:
    """+1: projection's rate above zero's beyond both Wilson 95 % intervals; -1: below; 0: within."""
    zl, zh = wilson_interval(*zero)
    pl, ph = wilson_interval(*proj)
    return 1 if pl > zh else -1 if ph < zl else 0


def _success_at(gen: dict, tolerance: str | None) -> tuple[bool | str | None, list[str]]:
    signs, parts = [], []
    for prim in SENSITIVE:
        z, p = _successes(gen["zero"], prim, tolerance), _successes(gen["projection"], prim, tolerance)
        if z is None or p is None:
            continue
        sign = _compare_rates(z, p)
        signs.append(sign)
        parts.append(f"{prim} {z[0] / z[1]:.2f} / {p[0] / p[1]:.2f}" + {1: " (higher)", -1: " (lower)", 0: ""}[sign])
    if not signs:
        return None, parts
    if all(s == 1 for s in signs):
        return True, parts
    if any(s == 1 for s in signs) and not any(s == -1 for s in signs):
        return PARTLY, parts
    return False, parts


def _success_projection_higher(results: dict) -> Outcome:
    gen = results.get("generated", {})
    if not has_inits(gen, "zero", "projection"):
        return Outcome(None, "needs zero and projection runs")
    ok, parts = _success_at(gen, None)
    if ok is None:
        return Outcome(None, "no pull, push or grasp motions judged")
    tolerances = sorted(gen["zero"].get("by_tolerance", {}), key=float)
    sweep = {t: _success_at(gen, t)[0] for t in tolerances} or None
    return Outcome(ok, "zero / projection success: " + ", ".join(parts), sweep)


def _clustering_similar(results: dict) -> Outcome:
    acc = {r["init"]: r["accuracy"] for r in results.get("latent", []) if r.get("codes") == LEARNED_CODES}
    if not has_inits(acc, "zero", "projection"):
        return Outcome(None, "needs zero and projection codes")
    numbers = f"accuracy zero {acc['zero']:.2f}, projection {acc['projection']:.2f} (q = {results.get('latent_dim')})"
    similar = abs(acc["projection"] - acc["zero"]) <= SIMILAR_ACCURACY
    chance = chance_level(results)
    if chance is None:
        return Outcome(None, numbers + "; the number of primitives is not in the results")
    bar = chance + ORGANISED_SHARE * (1 - chance)
    organised = min(acc["zero"], acc["projection"]) >= bar
    ok: bool | str = (True if organised else PARTLY) if similar else False
    return Outcome(ok, numbers + f"; chance {chance:.2f}, organised from {bar:.2f}")


def _paired_lower(a: dict, b: dict) -> tuple[float, int]:
    """Share of the common keys where ``b`` < ``a`` (strictly), and their number."""
    keys = sorted(set(a) & set(b))
    return (float(np.mean([b[k] < a[k] for k in keys])) if keys else float("nan")), len(keys)


def eighth_loss(curve: list[dict]) -> float:
    """The loss an eighth of the way through a curve (at least epoch 1): the inter claim's
    "convergence speed" (a stored summary keeps this epoch)."""
    eighth = max(1, round(curve[-1]["epoch"] / 8))
    return min(curve, key=lambda h: abs(h["epoch"] - eighth))["loss"]


def _inter_improved(results: dict) -> Outcome:
    by: dict[str, dict] = {}
    for r in results["runs"]:
        points = [h for h in r["phase2"] if h.get("loss") is not None]
        by.setdefault(r["init"], {})[(r["fold"], r.get("seed", 0))] = (eighth_loss(points), points[-1]["loss"])
    if not has_inits(by, "zero", "projection"):
        return Outcome(None, "needs zero and projection folds")
    z, p = by["zero"], by["projection"]
    measures = []
    for name, which in (("convergence speed (loss after 1/8 of phase 2)", 0), ("final value", 1)):
        za, pa = {k: v[which] for k, v in z.items()}, {k: v[which] for k, v in p.items()}
        share, n = _paired_lower(za, pa)
        better = np.mean(list(pa.values())) < np.mean(list(za.values())) and share >= PAIRED_SHARE
        measures.append(
            (
                better,
                f"{name}: zero {np.mean(list(za.values())):.2g} vs projection "
                f"{np.mean(list(pa.values())):.2g}, projection lower in {share * n:.0f} of {n} folds",
            )
        )
    zs, ps = np.std([v[1] for v in z.values()]), np.std([v[1] for v in p.values()])
    measures.append((ps < zs, f"robustness (std of the final value over folds): zero {zs:.2g} vs projection {ps:.2g}"))
    wins = sum(bool(b) for b, _ in measures)
    ok: bool | str = True if wins == 3 else False if wins == 0 else PARTLY
    return Outcome(ok, "; ".join(text + (" (improved)" if b else "") for b, text in measures))


def _v1(key: str) -> tuple:
    return tuple(c for c in CLAIMS_V1 if c.key == key)


_INFER_SIMILAR = (
    "It may look like resulting performance of trained models for zero latent initialization and random "
    "projection latent initialization is very similar, but some primitives from the experimental setup "
    "require more precision than others."
)

#: The paper's sentences (verbatim, whole) and our rules: the central claims of its abstract
#: first (:mod:`primspace.experiments.claim_rules_central`), then *Experimental Results* in order.
CLAIMS: tuple[Claim, ...] = (
    Claim(
        "central_generalisation",
        "intra",
        "Abstract (central)",
        "Experimental results demonstrate substantial improvement in generalisation abilities for unobserved "
        "samples in the case of initialization of latent variables with random linear projection of motor data over "
        "initialization with zero or random values.",
        f"final eval loss (codes inferred with θ frozen) of zero and of random (those run) at least {SUBSTANTIAL:g}x "
        "projection's at every q; partly: above projection's at every q, not by that factor everywhere",
        f">= {SUBSTANTIAL:g}x",
        3,
        generalisation_improved,
    ),
    Claim(
        "central_separated",
        "clustering",
        "Abstract (central)",
        "Moreover, latent space is well-structured wherein samples belonging to different primitives are well "
        "separated from the onset of training process.",
        f"the untrained projection codes P m cluster by primitive at least {WELL_SEPARATED_SHARE:g} of the way from "
        "chance (1/k) to 1 (R² = 0.9999); partly: only the trained codes do",
        f">= chance + {WELL_SEPARATED_SHARE:g}(1 - chance)",
        3,
        separated_from_the_onset,
    ),
    Claim(
        "fit_random",
        "intra",
        "Intra-primitive generalisation, Fig. loss_train",
        "As you can see, random initialization performs very badly for low-dimensional latent space.",
        f"final fit loss at the smallest q (at most {LOW_DIMENSIONAL_Q}): random at least {VERY_BADLY:g}x projection's",
        f">= {VERY_BADLY:g}x",
        1,
        _random_fit_bad,
    ),
    Claim(
        "fit_zero",
        "intra",
        "Intra-primitive generalisation, Fig. loss_train",
        "Zero initialization, on the other hand, differs very slightly from random linear projection case.",
        f"final fit loss of zero within a factor of {SIMILAR_FACTOR:g} of projection's at every q",
        f"within {SIMILAR_FACTOR:g}x",
        1,
        _zero_within("fit", "fit"),
    ),
    Claim(
        "infer_random",
        "intra",
        "Intra-primitive generalisation, Fig. loss_test",
        "Notice that the case with random initialization did not converge at all. This means the model trained in "
        "this way has no generalization capacity and is not capable to represent trajectories it did not see during "
        "the first training part.",
        f"random's own eval loss (θ frozen) falls less than {NOT_CONVERGED_DROP:g}x at every q (did not converge); "
        f"partly: it falls, but ends at least {NO_GENERALISATION:g}x above projection's at every q (no generalisation)",
        f"drop < {NOT_CONVERGED_DROP:g}x; partly: >= {NO_GENERALISATION:g}x projection",
        2,
        _random_not_converged,
        _v1("infer_random"),
    ),
    Claim(
        "infer_projection",
        "intra",
        "Intra-primitive generalisation, Fig. loss_test",
        "On the other hand, initialization with random linear projection yields good results already without any "
        "training, which means the initial distribution of projected points did not change much during the first "
        "part of the training.",
        "projection's eval loss before any inference step below zero's after the last, at every q",
        "strictly below",
        1,
        _projection_good_untrained,
    ),
    Claim(
        "infer_similar",
        "intra",
        "Intra-primitive generalisation",
        _INFER_SIMILAR,
        f'the first half ("may look like ... very similar"): final eval loss of zero within a factor of '
        f"{SIMILAR_FACTOR:g} of projection's at every q; the second half is the success claim below",
        f"within {SIMILAR_FACTOR:g}x",
        1,
        _zero_within("infer", "eval"),
    ),
    Claim(
        "success",
        "success",
        "Intra-primitive generalisation, Table assessment_table",
        "In particular, pushing and pulling the block as well as grasping is easy to fail if the gripper fingers "
        "miss just a bit.",
        "success rate of projection above zero's for pull, push and grasp (paper: 0.92/0.86, 0.94/0.9, 1.0/0.8), a "
        "difference counting only when the two Wilson 95 % intervals do not overlap; partly: higher on some, "
        "lower on none; at every judge tolerance of the sweep",
        "Wilson 95 % intervals apart",
        2,
        _success_projection_higher,
        _v1("success"),
    ),
    Claim(
        "clustering",
        "clustering",
        "Affine subspace clustering of latent space, Fig. arm_clustering",
        "They yield similar results, meaning even without presenting motion information for initial values of "
        "latent variables, they self-organize in a union of close to linear manifolds.",
        f"clustering accuracy of zero and projection codes (at the clustered q, the paper's 40; R² = 0.9999) within "
        f"{SIMILAR_ACCURACY:g}, and "
        f"both at least halfway from chance (1/k) to 1; partly: similar but not both above that",
        f"within {SIMILAR_ACCURACY:g}; >= chance + {ORGANISED_SHARE:g}(1 - chance)",
        2,
        _clustering_similar,
        _v1("clustering"),
    ),
    Claim(
        "inter",
        "inter",
        "Inter-primitive generalisation, Fig. loss_inter",
        "Proposed method shows slightly improved results in terms of convergence speed, final value of the loss "
        "function and robustness of the learning.",
        f"phase 2 over folds: projection's loss after 1/8 of the epochs and its final loss lower in mean and in at "
        f"least {PAIRED_SHARE:.0%} of the paired folds, and the std of its final loss over folds lower; holds for "
        "all three, partly for one or two",
        f"paired, >= {PAIRED_SHARE:.0%} of folds",
        2,
        _inter_improved,
        _v1("inter"),
    ),
)


Source = str | Path | Mapping


def _reader(source: Source) -> Callable[[str], dict | None]:
    """Results by experiment name, from a directory or from a mapping (a summary's ``results``)."""
    if isinstance(source, Mapping):
        return lambda name: source.get(name)
    return lambda name: read_results(source, name)


def check_claims(source: Source) -> list[dict]:
    """Each claim with its verdict on ``source`` (an experiment directory, or a mapping of
    results by experiment name): ``verdict`` (``holds`` / ``partly`` / ``does not hold`` /
    ``cannot be checked`` / ``not run``, counted over seeds), ``per_seed``, the numbers
    behind it (``ours``), the rule's ``version`` and ``threshold``, ``sweep`` and
    ``robust`` where the rule is judged at several tolerances, and ``previous``: each
    earlier version's rule and verdict."""
    read = _reader(source)
    cache: dict[str, dict | None] = {}
    rows = []
    for claim in CLAIMS:
        if claim.experiment not in cache:
            cache[claim.experiment] = read(claim.experiment)
        results = cache[claim.experiment]
        row = {
            "key": claim.key,
            "where": claim.where,
            "quote": claim.quote,
            "test": claim.test,
            "threshold": claim.threshold,
            "version": claim.version,
        }
        if results is None:
            rows.append(row | {"verdict": "not run", "ours": "", "per_seed": {}, "previous": []})
            continue
        row |= rule_verdict(claim.check, claim.experiment, results)

        row["previous"] = [
            {
                "version": 1,
                "test": old.test,
                "verdict": rule_verdict(lambda view, old=old: Outcome(*old.check(view)), claim.experiment, results)[
                    "verdict"
                ],
            }
            for old in claim.previous
        ]
        rows.append(row)
    return rows


def claims_table(source: Source) -> tuple[list[str], list[list]]:
    """The claims as a table: the paper's sentences, our rule (version, threshold), the
    verdict (with the tolerance sweep where there is one, and the earlier rule's verdict
    where the rule changed), our numbers."""
    rows = []
    for r in check_claims(source):
        verdict = r["verdict"]
        if r.get("sweep"):
            verdict += (
                " — by judge tolerance: "
                + ", ".join(f"{float(t) * 1000:g} mm {v}" for t, v in r["sweep"].items())
                + (" (robust)" if r["robust"] else " (NOT robust to the tolerance)")
            )
        for old in r["previous"]:
            verdict += f" [rule v{old['version']}: {old['verdict']}]"
        rows.append([f"“{r['quote']}” ({r['where']})", f"v{r['version']}: {r['test']}", verdict, r["ours"]])
    return ["the paper (verbatim)", "rule (version): what we test", "verdict", "ours"], rows
