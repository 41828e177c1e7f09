"""A claim (:class:`Claim`: a sentence of the paper, its rule and the rule's earlier versions),
a rule's outcome and its verdict, seed by seed, counted (:mod:`primspace.results.claims`).

A rule (a claim's ``check``) reads one set of results and says an :class:`Outcome`: True,
False, :data:`PARTLY` or None (cannot be checked), with the numbers behind it, the
``direction`` of a verdict other than "holds" (:data:`DIRECTIONS`: whether the paper's
method, random-projection initialisation, does better or worse than the sentence says),
and for a sentence about every latent size the verdict at each (``by_q``).
:func:`rule_verdict` applies a rule to an experiment's results (or to several
experiments', for a claim that reads more than one): with several seeds, each seed on
its own (its own split, weights and projection), and the verdicts counted in words
("holds in 2 of 3 seeds (not in seed 1)"), at every tolerance of a sweep and every
latent size too. Every rule version's claims are of the one class :class:`Claim`. Reads
results only; imports no experiment.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

__all__ = [
    "Claim",
    "Earlier",
    "Outcome",
    "PARTLY",
    "AS_SAID",
    "IN_FAVOUR",
    "AGAINST",
    "UNCHECKABLE",
    "DIRECTIONS",
    "verdict_word",
    "rule_verdict",
]

#: The verdict of a sentence that half holds.
PARTLY = "partly"

#: The verdict holds.
AS_SAID = "as the paper says"
#: The sentence fails (or half holds) because the paper's method does better than it says.
IN_FAVOUR = "in the paper's favour"
#: The paper's method does worse than said, or the effect the paper claims is absent.
AGAINST = "against the paper"
#: The runs it needs are missing, or the sentence speaks of a setting not run.
UNCHECKABLE = "cannot be checked at this scale"
#: The directions a verdict can take, in that order.
DIRECTIONS = (AS_SAID, IN_FAVOUR, AGAINST, UNCHECKABLE)


class Outcome(NamedTuple):
    """What a rule says of one set of results: ``ok`` (True, False, :data:`PARTLY`, or None
    when it cannot be checked), the numbers behind it, for rules judged at several
    tolerances ``{tolerance: ok}``, the ``direction`` of a verdict other than "holds"
    (:data:`IN_FAVOUR`, :data:`AGAINST`, :data:`UNCHECKABLE`; None: :func:`rule_verdict`
    reads it from ``ok``, a failure counting as against the paper), and for a sentence about every latent size ``{q: ok}``."""

    ok: bool | str | None
    numbers: str
    sweep: dict | None = None
    direction: str | None = None
    by_q: dict | None = None


_VERDICTS = {True: "holds", False: "does not hold", PARTLY: PARTLY, None: "cannot be checked"}


def verdict_word(ok: bool | str | None) -> str:
    """``holds`` / ``does not hold`` / ``partly`` / ``cannot be checked`` of a rule's ``ok``."""
    return _VERDICTS[_plain(ok)]


def _direction_of(o: Outcome) -> str:
    """The direction of one outcome: "as the paper says" where it holds, "cannot be checked"
    where it cannot be, else the rule's (a rule that names none: against the paper)."""
    if o.ok is True:
        return AS_SAID
    if o.ok is None:
        return UNCHECKABLE
    return o.direction or AGAINST


def _views(experiment: str, results: dict) -> dict:
    """``{seed: results as one seed's}`` of one experiment: intra and inter runs filtered by
    seed; success and clustering results with their focus seed's entries replaced by each
    seed's (``by_seed``); empty for anything else."""
    if experiment in ("intra", "inter"):
        seeds = sorted({r.get("seed", 0) for r in results.get("runs", [])})
        return {s: results | {"runs": [r for r in results["runs"] if r.get("seed", 0) == s]} for s in seeds}
    field_ = {"success": "generated", "clustering": "latent"}.get(experiment)
    if field_ is None or not results.get("by_seed"):
        return {}
    views = {results.get("seed", 0): results}
    views |= {int(s): results | {field_: v} for s, v in results["by_seed"].items()}
    return dict(sorted(views.items()))


def _seed_views(experiment: str | tuple, results: dict) -> dict:
    """``{seed: results as one seed's}``; for a claim reading several experiments
    (``experiment`` a tuple, ``results`` by experiment name, None where one did not run),
    each seed run anywhere, with every experiment's view of it (None where it lacks it)."""
    if isinstance(experiment, str):
        return _views(experiment, results)
    parts = {e: _views(e, results[e]) if results.get(e) is not None else {} for e in experiment}
    seeds = sorted({s for v in parts.values() for s in v})
    return {s: {e: parts[e].get(s, results.get(e)) for e in experiment} for s in seeds}


def _count(per_seed: dict) -> str:
    """ "holds in every seed (3 of 3)", "holds in 1 of 3 seeds (not in seed 0, 2)",
    "holds in 1 of 3 seeds, partly in 1 (seed 2), not in seed 0", "partly in 1 of 3 seeds (seed 1), not in seed 0, 2"."""
    judged = {s: ok for s, ok in per_seed.items() if ok is not None}
    if not judged:
        return _VERDICTS[None]
    n = len(judged)
    held = [s for s, ok in judged.items() if ok is True]
    partly = [s for s, ok in judged.items() if ok == PARTLY]
    failed = [s for s, ok in judged.items() if ok is False]
    if len(held) == n:
        return f"holds in every seed ({n} of {n})"
    if len(failed) == n:
        return f"does not hold in any seed (0 of {n})"
    if len(partly) == n:
        return f"partly in every seed ({n} of {n})"
    if not partly:
        return f"holds in {len(held)} of {n} seeds (not in seed {', '.join(map(str, failed))})"
    parts = [f"holds in {len(held)} of {n} seeds"] if held else []
    parts.append(f"partly in {len(partly)}{'' if held else f' of {n} seeds'} (seed {', '.join(map(str, partly))})")
    if failed:
        parts.append(f"not in seed {', '.join(map(str, failed))}")
    return ", ".join(parts)


def _count_directions(per_seed: dict[int, str]) -> str:
    """One direction where the seeds agree (those that hold aside, unless all do); else each
    direction with its seeds ("in the paper's favour in seed 0, 2; against the paper in seed 1")."""
    judged = {s: d for s, d in per_seed.items() if d != UNCHECKABLE} or per_seed
    off = {s: d for s, d in judged.items() if d != AS_SAID} or judged
    found = [d for d in DIRECTIONS if d in off.values()]
    if len(found) == 1:
        return found[0]
    return "; ".join(f"{d} in seed {', '.join(str(s) for s, x in off.items() if x == d)}" for d in found)


def _plain(ok):
    """A rule's verdict as True / False / PARTLY / None (numpy booleans made plain)."""
    return ok if ok is None or ok == PARTLY else bool(ok)


def _checked(check: Callable[[dict], Outcome], results: dict) -> Outcome:
    """``check(results)`` with plain verdicts, at every tolerance and latent size too."""
    o = Outcome(*check(results))
    return o._replace(
        ok=_plain(o.ok),
        sweep=o.sweep and {t: _plain(v) for t, v in o.sweep.items()},
        by_q=o.by_q and {q: _plain(v) for q, v in o.by_q.items()},
    )


def _counted(outcomes: dict, field_: str, order=float) -> dict | None:
    """``{tolerance or q: verdict counted over seeds}`` of the outcomes' ``sweep`` or ``by_q``."""
    maps = {s: getattr(o, field_) for s, o in outcomes.items() if getattr(o, field_)}
    if not maps:
        return None
    keys = sorted({k for m in maps.values() for k in m}, key=order)
    by_key = {k: {s: m.get(k) for s, m in maps.items()} for k in keys}
    return {k: (_VERDICTS[next(iter(v.values()))] if len(v) == 1 else _count(v)) for k, v in by_key.items()}


def rule_verdict(check: Callable[[dict], Outcome], experiment: str | tuple, results: dict) -> dict:
    """The verdict of one rule: one seed as the rule says; several seeds each on its own
    (each seed its own split, weights and projection), counted. ``per_seed`` keeps each
    seed's verdict word, ``direction`` the verdict's (counted over seeds where they
    differ); ``sweep`` each tolerance's count (rules judged at several), ``by_q`` each
    latent size's (rules about every q)."""
    views = _seed_views(experiment, results)
    if len(views) < 2:
        views = {results.get("seed", 0) if isinstance(experiment, str) else 0: results}
    outcomes = {s: _checked(check, view) for s, view in views.items()}
    per_seed = {s: o.ok for s, o in outcomes.items()}
    verdict = _VERDICTS[next(iter(per_seed.values()))] if len(per_seed) == 1 else _count(per_seed)
    numbers = (
        next(iter(outcomes.values())).numbers
        if len(outcomes) == 1
        else "; ".join(f"seed {s}: {o.numbers}" for s, o in outcomes.items())
    )
    row = {
        "verdict": verdict,
        "direction": _count_directions({s: _direction_of(o) for s, o in outcomes.items()}),
        "ours": numbers,
        "per_seed": {str(s): _VERDICTS[ok] for s, ok in per_seed.items()},
    }
    sweep = _counted(outcomes, "sweep")
    if sweep:
        row["sweep"] = sweep
        row["robust"] = len(set(sweep.values())) == 1
    by_q = _counted(outcomes, "by_q", int)
    if by_q:
        row["by_q"] = by_q
    return row


class Earlier(NamedTuple):
    """An earlier version of a claim's rule: its version, what it tested, its check."""

    version: int
    test: str
    check: Callable[[dict], tuple]


@dataclass(frozen=True)
class Claim:
    """One or more whole sentences of the paper and how we test them."""

    key: str
    experiment: str | tuple[str, ...]  # the results it reads: intra, clustering, success, inter (or several)
    where: str  # the paper's section / figure
    quote: str  # whole sentences, verbatim from shared/paper.tex
    test: str  # what we measure and the rule
    threshold: str  # the effect size the rule asks for, in words
    version: int
    check: Callable[[dict], Outcome]
    previous: tuple[Earlier, ...] = field(default=(), compare=False)  # earlier rules, oldest first
