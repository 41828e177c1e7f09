"""Version 1 of the rules that test the paper's claims (primspace 0.2-0.5), kept so that
their verdicts stay readable beside the current rules' (:mod:`primspace.results.claims`).

Frozen: a rule that changes gets a new version there; nothing here is edited except to
keep it running. What was wrong with some of them (issue 23): a tie counted as an
improvement (success: projection "at least" zero's), "did not converge at all" was
tested by another sentence (random ends 10x above projection, while its own loss falls
6-12x), clustering "similar" held when both inits were near chance, and the inter rule
compared means without their spread.

Its claims are of the one class :class:`~primspace.results.claim_verdicts.Claim` (version 1,
the rule's threshold in words); the measures its rules read are those of
:mod:`primspace.results.measures`, which every version shares.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from primspace.results.claim_verdicts import Claim
from primspace.results.layout import LEARNED_CODES
from primspace.results.measures import has_inits, losses_by_q

__all__ = ["CLAIMS_V1"]


def _final(curve: list) -> float:
    vals = [h["loss"] for h in curve if h.get("loss") is not None]
    return float(vals[-1]) if vals else float("nan")


#: The largest latent size read as "low-dimensional latent space" (the paper's figure
#: shows several sizes without naming them; our grid is 10, 20, 40).
LOW_DIMENSIONAL_Q = 20


def _random_fit_bad(results: dict) -> tuple[bool | None, str]:
    fits = losses_by_q(results, "fit")
    qs = [q for q, d in fits.items() if has_inits(d, "random", "projection")]
    if not qs:
        return None, "needs random and projection runs"
    q = min(qs)
    if q > LOW_DIMENSIONAL_Q:
        return None, (
            f"needs runs at a low-dimensional latent size (q <= {LOW_DIMENSIONAL_Q}); the smallest here is q = {q}"
        )
    ratio = fits[q]["random"] / fits[q]["projection"]
    return ratio >= 5, f"q = {q}: random's final fit loss is {ratio:.3g}x projection's"


def _zero_within_2x(phase: str, what: str) -> Callable[[dict], tuple[bool | None, str]]:
    """The check "zero's final ``phase`` loss lies within a factor of 2 of projection's at every q"."""

    def check(results: dict) -> tuple[bool | None, str]:
        finals = losses_by_q(results, phase)
        ratios = {q: d["zero"] / d["projection"] for q, d in finals.items() if has_inits(d, "zero", "projection")}
        if not ratios:
            return None, "needs zero and projection runs"
        ok = all(0.5 <= r <= 2 for r in ratios.values())
        return ok, f"zero / projection final {what} loss: " + ", ".join(f"q = {q}: {r:.3g}" for q, r in ratios.items())

    return check


def _random_infer_fails(results: dict) -> tuple[bool | None, str]:
    finals, starts = losses_by_q(results, "infer"), losses_by_q(results, "infer", 0)
    qs = [q for q, d in finals.items() if has_inits(d, "random", "projection")]
    if not qs:
        return None, "needs random and projection runs"
    ratios = {q: finals[q]["random"] / finals[q]["projection"] for q in qs}
    drops = {q: starts[q]["random"] / finals[q]["random"] for q in qs}
    ok = all(r >= 10 for r in ratios.values())
    return ok, (
        "random / projection final eval loss: "
        + ", ".join(f"q = {q}: {r:.3g}x" for q, r in ratios.items())
        + "; random's own eval loss still falls "
        + ", ".join(f"{d:.2g}x" for d in drops.values())
        + " (it converges, to a poor value)"
    )


def _projection_good_untrained(results: dict) -> tuple[bool | None, str]:
    finals, starts = losses_by_q(results, "infer"), losses_by_q(results, "infer", 0)
    qs = [q for q, d in finals.items() if has_inits(d, "zero", "projection")]
    if not qs:
        return None, "needs zero and projection runs"
    cmp = {q: (starts[q]["projection"], finals[q]["zero"]) for q in qs}
    ok = all(a < b for a, b in cmp.values())
    return ok, "projection's eval loss before any inference step vs zero's after the last: " + ", ".join(
        f"q = {q}: {a:.2g} vs {b:.2g}" for q, (a, b) in cmp.items()
    )


def _success_projection_higher(results: dict) -> tuple[bool | None, str]:
    gen = results.get("generated", {})
    if not has_inits(gen, "zero", "projection"):
        return None, "needs zero and projection runs"
    parts, ok = [], True
    for prim in ("pull", "push", "grasp"):
        z, p = gen["zero"]["rates"].get(prim), gen["projection"]["rates"].get(prim)
        if z is None or p is None:
            continue
        ok = ok and p >= z
        parts.append(f"{prim} {z:.2f} / {p:.2f}")
    if not parts:
        return None, "no pull, push or grasp motions judged"
    return ok, "zero / projection success: " + ", ".join(parts)


def _clustering_similar(results: dict) -> tuple[bool | None, str]:
    acc = {r["init"]: r["accuracy"] for r in results.get("latent", []) if r.get("codes") == LEARNED_CODES}
    if not has_inits(acc, "zero", "projection"):
        return None, "needs zero and projection codes"
    diff = acc["projection"] - acc["zero"]
    return abs(
        diff
    ) <= 0.1, f"accuracy zero {acc['zero']:.2f}, projection {acc['projection']:.2f} (q = {results.get('latent_dim')})"


def _inter_improved(results: dict) -> tuple[bool | None, str]:
    by: dict[str, list] = {}
    for r in results["runs"]:
        by.setdefault(r["init"], []).append(r)
    if not has_inits(by, "zero", "projection"):
        return None, "needs zero and projection folds"
    stats = {}
    for init, runs in by.items():
        final = np.array([_final(r["phase2"]) for r in runs])
        start = np.array([r["phase2"][0]["loss"] for r in runs])
        stats[init] = (start.mean(), final.mean(), final.std())
    z, p = stats["zero"], stats["projection"]
    ok = p[0] < z[0] and p[1] < z[1] and p[2] <= z[2]
    return ok, (
        f"phase 2, zero vs projection: start {z[0]:.2g} vs {p[0]:.2g}, final {z[1]:.2g} ± {z[2]:.1g} "
        f"vs {p[1]:.2g} ± {p[2]:.1g}"
    )


#: The version-1 rules, in the paper's order (quotes as they were: some cut short).
CLAIMS_V1: tuple[Claim, ...] = (
    Claim(
        "fit_random",
        "intra",
        "Intra-primitive generalisation, Fig. loss_train",
        "random initialization performs very badly for low-dimensional latent space.",
        "final fit loss at the smallest q (at most 20): random at least 5x projection's",
        ">= 5x",
        1,
        _random_fit_bad,
    ),
    Claim(
        "fit_zero",
        "intra",
        "Intra-primitive generalisation, Fig. loss_train",
        "Zero initialization, on the other hand, differs very slightly from random linear projection case.",
        "final fit loss of zero within a factor of 2 of projection's at every q",
        "within 2x",
        1,
        _zero_within_2x("fit", "fit"),
    ),
    Claim(
        "infer_random",
        "intra",
        "Intra-primitive generalisation, Fig. loss_test",
        "Notice that the case with random initialization did not converge at all.",
        "final eval loss (θ frozen) of random at least 10x projection's at every q",
        ">= 10x",
        1,
        _random_infer_fails,
    ),
    Claim(
        "infer_projection",
        "intra",
        "Intra-primitive generalisation, Fig. loss_test",
        "initialization with random linear projection yields good results already without any training",
        "projection's eval loss before any inference step below zero's after the last, at every q",
        "strictly below",
        1,
        _projection_good_untrained,
    ),
    Claim(
        "infer_similar",
        "intra",
        "Intra-primitive generalisation",
        "It may look like resulting performance of trained models for zero latent initialization and random "
        "projection latent initialization is very similar",
        "final eval loss of zero within a factor of 2 of projection's at every q",
        "within 2x",
        1,
        _zero_within_2x("infer", "eval"),
    ),
    Claim(
        "success",
        "success",
        "Intra-primitive generalisation, Table assessment_table",
        "some primitives from the experimental setup require more precision than others. In particular, "
        "pushing and pulling the block as well as grasping is easy to fail if the gripper fingers miss just a bit.",
        "success rate of projection at least zero's for pull, push and grasp (paper: 0.92/0.86, 0.94/0.9, 1.0/0.8)",
        "at least zero's",
        1,
        _success_projection_higher,
    ),
    Claim(
        "clustering",
        "clustering",
        "Affine subspace clustering of latent space, Fig. arm_clustering",
        "They yield similar results,",
        "clustering accuracy of zero and projection codes (q = 40, R² = 0.9999) within 0.1",
        "within 0.1",
        1,
        _clustering_similar,
    ),
    Claim(
        "inter",
        "inter",
        "Inter-primitive generalisation, Fig. loss_inter",
        "Proposed method shows slightly improved results in terms of convergence speed, final value of the loss "
        "function and robustness of the learning.",
        "phase-2 loss over folds: projection's start and final mean below zero's, its final std not above",
        "lower mean and std",
        1,
        _inter_improved,
    ),
)
