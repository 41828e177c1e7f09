"""The rules of the paper's *Experimental Results* sentences as of version 2 (0.6), and the
version-1 rules that version kept (:mod:`primspace.results.claims` quotes the sentences).

Version 2 changed four rules of version 1 (:mod:`primspace.results.claim_rules_v1`):

- a tie never counts as an improvement, and a difference in success rates counts only
  when the Wilson 95 % intervals of the two rates do not overlap;
- "did not converge at all" is tested literally (random's own eval loss falls less than
  2x), "partly" when it falls but ends at least 10x above projection's (the next
  sentence: "no generalization capacity");
- clustering "similar results ... self-organize in a union of close to linear manifolds"
  needs both inits well above chance, "partly" when they are similar but near chance;
- inter "slightly improved ... convergence speed, final value ... robustness": each of
  the three measured, the first two paired fold by fold (:func:`inter_improved_v2`; its
  robustness compares the population std, ddof 0, of the final loss over folds).

Since version 4 every rule here also says the ``direction`` of a verdict other than
"holds" and, where its sentence speaks of every latent size, its verdict at each q
(``by_q``); no verdict changed with that. Reads results only.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from primspace.results.claim_verdicts import AGAINST, IN_FAVOUR, PARTLY, Outcome
from primspace.results.layout import LEARNED_CODES
from primspace.results.measures import chance_level, eighth_loss, has_inits, losses_by_q, paired_lower
from primspace.utils.stats import wilson_interval

__all__ = [
    "LOW_DIMENSIONAL_Q",
    "VERY_BADLY",
    "SIMILAR_FACTOR",
    "NOT_CONVERGED_DROP",
    "NO_GENERALISATION",
    "SIMILAR_ACCURACY",
    "ORGANISED_SHARE",
    "PAIRED_SHARE",
    "SENSITIVE",
    "random_fit_bad",
    "zero_within",
    "random_not_converged",
    "projection_good_untrained",
    "success_projection_higher",
    "clustering_similar",
    "inter_measures",
    "inter_improved_v2",
]

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
#: The primitives the paper's success table reports ("sensitive primitives").
SENSITIVE = ("pull", "push", "grasp")


def random_fit_bad(results: dict) -> Outcome:
    """ "random initialization performs very badly for low-dimensional latent space": at the
    smallest q (at most :data:`LOW_DIMENSIONAL_Q`), random's final fit loss at least
    :data:`VERY_BADLY` times projection's; when it is not, random does better than said."""
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
    return Outcome(ratio >= VERY_BADLY, f"q = {q}: random's final fit loss is {ratio:.3g}x projection's", None, AGAINST)


def zero_within(phase: str, what: str) -> Callable[[dict], Outcome]:
    """The check "zero's final ``phase`` loss lies within :data:`SIMILAR_FACTOR` of projection's
    at every q"; outside it the direction says which is lower (zero far above: in the paper's
    favour)."""

    def check(results: dict) -> Outcome:
        finals = losses_by_q(results, phase)
        ratios = {q: d["zero"] / d["projection"] for q, d in finals.items() if has_inits(d, "zero", "projection")}
        if not ratios:
            return Outcome(None, "needs zero and projection runs")
        by_q = {q: 1 / SIMILAR_FACTOR <= r <= SIMILAR_FACTOR for q, r in ratios.items()}
        direction = AGAINST if any(r < 1 / SIMILAR_FACTOR for r in ratios.values()) else IN_FAVOUR
        numbers = f"zero / projection final {what} loss: " + ", ".join(f"q = {q}: {r:.3g}" for q, r in ratios.items())
        return Outcome(all(by_q.values()), numbers, None, direction, by_q)

    return check


def _not_converged(drop: float, ratio: float) -> bool | str:
    return True if drop < NOT_CONVERGED_DROP else PARTLY if ratio >= NO_GENERALISATION else False


def random_not_converged(results: dict) -> Outcome:
    """ "did not converge at all ... no generalization capacity": random's own eval loss falls
    less than :data:`NOT_CONVERGED_DROP` at every q; partly: it falls but ends at least
    :data:`NO_GENERALISATION` times projection's at every q. Otherwise random does better
    than said: against the paper."""
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
    numbers = (
        "random's own eval loss falls "
        + ", ".join(f"q = {q}: {d:.2g}x" for q, d in drops.items())
        + "; it ends at "
        + ", ".join(f"{r:.3g}x" for r in ratios.values())
        + " projection's"
    )
    return Outcome(ok, numbers, None, AGAINST, {q: _not_converged(drops[q], ratios[q]) for q in qs})


def projection_good_untrained(results: dict) -> Outcome:
    """ "random linear projection yields good results already without any training":
    projection's eval loss before any inference step below zero's after the last, at every q."""
    finals, starts = losses_by_q(results, "infer"), losses_by_q(results, "infer", 0)
    qs = [q for q, d in finals.items() if has_inits(d, "zero", "projection")]
    if not qs:
        return Outcome(None, "needs zero and projection runs")
    cmp = {q: (starts[q]["projection"], finals[q]["zero"]) for q in qs}
    by_q = {q: a < b for q, (a, b) in cmp.items()}
    return Outcome(
        all(by_q.values()),
        "projection's eval loss before any inference step vs zero's after the last: "
        + ", ".join(f"q = {q}: {a:.2g} vs {b:.2g}" for q, (a, b) in cmp.items()),
        None,
        AGAINST,
        by_q,
    )


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


def success_projection_higher(results: dict) -> Outcome:
    """Projection's success rate above zero's for pull, push and grasp beyond both Wilson
    intervals, at the judge's default tolerance and at every one of its sweep; a rate not
    higher is the paper's method doing worse than its table."""
    gen = results.get("generated", {})
    if not has_inits(gen, "zero", "projection"):
        return Outcome(None, "needs zero and projection runs")
    ok, parts = _success_at(gen, None)
    if ok is None:
        return Outcome(None, "no pull, push or grasp motions judged")
    tolerances = sorted(gen["zero"].get("by_tolerance", {}), key=float)
    sweep = {t: _success_at(gen, t)[0] for t in tolerances} or None
    return Outcome(ok, "zero / projection success: " + ", ".join(parts), sweep, AGAINST)


def clustering_similar(results: dict) -> Outcome:
    """Clustering accuracies of zero's and projection's codes within :data:`SIMILAR_ACCURACY`,
    both at least :data:`ORGANISED_SHARE` of the way from chance to 1; not similar because
    projection's is higher: in the paper's favour."""
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
    direction = IN_FAVOUR if not similar and acc["projection"] > acc["zero"] else AGAINST
    return Outcome(ok, numbers + f"; chance {chance:.2f}, organised from {bar:.2f}", None, direction)


def inter_measures(results: dict, ddof: int) -> Outcome:
    """Inter "slightly improved results in terms of convergence speed, final value of the loss
    function and robustness": projection's loss after 1/8 of phase 2 and its final loss lower
    in mean and in at least :data:`PAIRED_SHARE` of the paired folds, and the std (with
    ``ddof``) of its final loss over folds lower; holds for all three, partly for one or two."""
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
        share, n = paired_lower(za, pa)
        better = np.mean(list(pa.values())) < np.mean(list(za.values())) and share >= PAIRED_SHARE
        measures.append(
            (
                better,
                f"{name}: zero {np.mean(list(za.values())):.2g} vs projection "
                f"{np.mean(list(pa.values())):.2g}, projection lower in {share * n:.0f} of {n} folds",
            )
        )
    zs, ps = (np.std([v[1] for v in d.values()], ddof=ddof) if len(d) > ddof else np.nan for d in (z, p))
    label = "std" if ddof == 0 else f"sample std (ddof {ddof})"
    measures.append(
        (ps < zs, f"robustness ({label} of the final value over folds): zero {zs:.2g} vs projection {ps:.2g}")
    )
    wins = sum(bool(b) for b, _ in measures)
    ok: bool | str = True if wins == 3 else False if wins == 0 else PARTLY
    return Outcome(ok, "; ".join(text + (" (improved)" if b else "") for b, text in measures), None, AGAINST)


def inter_improved_v2(results: dict) -> Outcome:
    """The version-2 inter rule: :func:`inter_measures` with the population std (ddof 0)."""
    return inter_measures(results, 0)
