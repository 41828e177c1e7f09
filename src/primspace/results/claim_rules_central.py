"""The rules of the paper's central claims: its abstract's two sentences (issue 42).

The claims table (:mod:`primspace.results.claims`) first checked the sentences of the
paper's *Experimental Results*; the abstract's claims, what a reader takes from the paper,
were not in it. They are (verbatim, shared/paper.tex):

- "Experimental results demonstrate substantial improvement in generalisation abilities for
  unobserved samples in the case of initialization of latent variables with random linear
  projection of motor data over initialization with zero or random values."
  Rule (:func:`generalisation_improved`): projection's final loss on the evaluation part
  (codes inferred with θ frozen: the unobserved samples) at most 1/:data:`SUBSTANTIAL` of
  zero's and of random's (those that ran), at every latent size; partly: below each at every
  q but not by that factor everywhere.
- "Moreover, latent space is well-structured wherein samples belonging to different
  primitives are well separated from the onset of training process."
  Rule (:func:`separated_from_the_onset`): the projection codes before any training
  (``P m``) cluster by primitive at least :data:`WELL_SEPARATED_SHARE` of the way from
  chance to 1 (the clustering rule's bar); partly: only the trained codes do.

Both were written after the results they read were known (the issue that added them quotes
those results), unlike the table's earlier rules; they are version 3. Where they do not
hold, the paper's method does worse than said (direction: against the paper); the first
also gives its verdict at each latent size (``by_q``, since version 4, no verdict changed).
Reads results only.
"""

from __future__ import annotations

from primspace.results.claim_verdicts import AGAINST, PARTLY, Outcome
from primspace.results.layout import INITIAL_CODES, LEARNED_CODES
from primspace.results.measures import chance_level, losses_by_q

__all__ = ["SUBSTANTIAL", "WELL_SEPARATED_SHARE", "generalisation_improved", "separated_from_the_onset"]

#: "substantial improvement": the other init's final eval loss at least this many times projection's.
SUBSTANTIAL = 2.0
#: "well separated": clustering accuracy at least this share of the way from chance (1/k) to 1.
WELL_SEPARATED_SHARE = 0.5


def generalisation_improved(results: dict) -> Outcome:
    """The abstract's first claim, on intra's results (module docstring)."""
    finals = losses_by_q(results, "infer")
    ratios = {
        q: {o: d[o] / d["projection"] for o in ("zero", "random") if o in d}
        for q, d in finals.items()
        if "projection" in d
    }
    ratios = {q: d for q, d in ratios.items() if d}
    if not ratios:
        return Outcome(None, "needs projection runs and zero or random runs")
    by_q = {q: _improved(min(d.values())) for q, d in ratios.items()}
    return Outcome(
        _improved(min(r for d in ratios.values() for r in d.values())),
        "final eval loss over projection's: "
        + "; ".join(f"q = {q}: " + ", ".join(f"{o} {r:.3g}x" for o, r in d.items()) for q, d in ratios.items()),
        None,
        AGAINST,
        by_q,
    )


def _improved(least: float) -> bool | str:
    """The verdict of the smallest ratio of another init's final eval loss to projection's."""
    return True if least >= SUBSTANTIAL else PARTLY if least > 1 else False


def separated_from_the_onset(results: dict) -> Outcome:
    """The abstract's second claim, on clustering's results (module docstring)."""
    rows = results.get("latent", [])
    initial = [r["accuracy"] for r in rows if r.get("codes") == INITIAL_CODES and r.get("init") == "projection"]
    trained = [r["accuracy"] for r in rows if r.get("codes") == LEARNED_CODES and r.get("init") == "projection"]
    if not initial:
        return Outcome(None, "needs the untrained projection codes P m clustered")
    chance = chance_level(results)
    if chance is None:
        return Outcome(None, "the number of primitives is not in the results")
    bar = chance + WELL_SEPARATED_SHARE * (1 - chance)
    after = f", trained {trained[0]:.2f}" if trained else ""
    ok: bool | str = True if initial[0] >= bar else PARTLY if trained and trained[0] >= bar else False
    return Outcome(
        ok,
        f"accuracy of the projection codes before training {initial[0]:.2f}{after} "
        f"(q = {results.get('latent_dim')}); chance {chance:.2f}, well separated from {bar:.2f}",
        None,
        AGAINST,
    )
