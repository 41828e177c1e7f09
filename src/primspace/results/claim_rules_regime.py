"""The rule that decides issue 50's hypothesis on the regime of few demonstrations, written
before any run (version 1) and versioned like the paper's rules (:mod:`primspace.results.claims`).

The hypothesis (:data:`HYPOTHESIS`): at ``n <= 5`` fitted demonstrations per primitive on the
paper preset, the prior through the decoder beats the best tuned peer by more than both spreads
at 25 % observed, in MSE and in success.

The rule (:func:`codes_help`, :data:`RULE`): the model's row is the prior with its decoded draws
forced (blend 0: the whole prediction through the decoder, :data:`~primspace.results.regime.MODEL_ROWS`),
in each task (the primitive given, and not); the peers are every peer row of the same task (the tuned
ProMP, the Gaussian over the raw trajectories, the nearest neighbour), the best by mean at each
``n``. At every ``n <= 5`` run, each task and each metric (MSE; success where the simulator judged,
else MSE alone), the model's mean must be better than the best peer's by more than both standard
deviations over seeds (ddof 1; one seed has none). Holds when every such comparison holds; partly
when some do; does not hold when none does; cannot be checked when no ``n <= 5`` ran. Reads results
only; imports no experiment.
"""

from __future__ import annotations

from primspace.results.claim_verdicts import PARTLY, Outcome, verdict_word
from primspace.results.regime import METRICS, TASKS, comparisons

__all__ = ["HYPOTHESIS", "RULE", "RULE_VERSION", "FEW", "FRACTION", "codes_help", "check_regime"]

#: The hypothesis, as issue 50 states it.
HYPOTHESIS = (
    "At n <= 5 fitted demonstrations per primitive on the paper preset, the prior through the decoder beats the "
    "best tuned peer by more than both spreads at 25 % observed (MSE and success)."
)
#: The most fitted demonstrations per primitive the hypothesis speaks of.
FEW = 5
#: The observed fraction it speaks of.
FRACTION = 0.25
#: The rule's version (bumped with a changed rule; the earlier kept readable beside it).
RULE_VERSION = 1
#: The rule, as the docs print it.
RULE = (
    f"v{RULE_VERSION}: at every n <= {FEW} run, with the primitive given and without it, in MSE and (where judged) "
    f"success at {FRACTION:.0%} observed, the prior with its decoded draws forced (blend 0) better than the best peer "
    "row of the task (tuned ProMP, raw Gaussian, nearest neighbour) by more than both standard deviations over seeds "
    "(ddof 1); holds when every comparison holds, partly when some do, does not hold when none does"
)


def codes_help(results: dict) -> Outcome:
    """The hypothesis judged on regime ``results`` (module docstring)."""
    metrics = [m for m, _ in METRICS if m != "success" or results.get("judged")]
    verdicts, parts = [], []
    for task, title in TASKS.items():
        for metric in metrics:
            compared = {n: c for n, c in comparisons(results, task, metric, FRACTION).items() if int(n) <= FEW}
            for n, c in compared.items():
                verdicts.append(c["verdict"])
                parts.append(
                    f"{title}, {'MSE' if metric == 'mse' else metric} at n = {n}: {c['verdict']} ({c['ours'][0]:.3g} ± {c['ours'][1]:.2g} against "
                    f"{c['peer']} {c['peer_cell'][0]:.3g} ± {c['peer_cell'][1]:.2g})"
                )
    if not verdicts:
        return Outcome(None, f"no n <= {FEW} with both the model's row and a peer's")
    held = sum(v == "holds" for v in verdicts)
    ok = True if held == len(verdicts) else PARTLY if held else False
    return Outcome(ok, f"{held} of {len(verdicts)} comparisons hold; " + "; ".join(parts))


def check_regime(results: dict) -> dict:
    """The hypothesis's row: ``hypothesis``, ``rule``, ``version``, ``verdict`` and the numbers (``ours``)."""
    outcome = codes_help(results)
    return {
        "hypothesis": HYPOTHESIS,
        "rule": RULE,
        "version": RULE_VERSION,
        "verdict": verdict_word(outcome.ok),
        "ours": outcome.numbers,
    }
