"""A rule's outcome and its verdict, seed by seed, counted (:mod:`primspace.experiments.claims`).

A rule (a claim's ``check``) reads one set of results and says an :class:`Outcome`: True,
False, :data:`PARTLY` or None (cannot be checked), with the numbers behind it.
:func:`rule_verdict` applies a rule to an experiment's results: with several seeds, each
seed on its own (its own split, weights and projection), and the verdicts counted in
words ("holds in 2 of 3 seeds (not in seed 1)"), at every tolerance of a sweep too.
Reads results only; imports no experiment.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

__all__ = ["Outcome", "PARTLY", "rule_verdict"]

#: The verdict of a sentence that half holds.
PARTLY = "partly"


class Outcome(NamedTuple):
    """What a rule says of one set of results: ``ok`` (True, False, :data:`PARTLY`, or None
    when it cannot be checked), the numbers behind it, and for rules judged at several
    tolerances ``{tolerance: ok}``."""

    ok: bool | str | None
    numbers: str
    sweep: dict | None = None


_VERDICTS = {True: "holds", False: "does not hold", PARTLY: PARTLY, None: "cannot be checked"}


def _seed_views(experiment: str, results: dict) -> dict:
    """``{seed: results as one seed's}``: intra and inter runs filtered by seed; success and
    clustering results with their focus seed's entries replaced by each seed's
    (``by_seed``); empty for anything else."""
    if experiment in ("intra", "inter"):
        seeds = sorted({r.get("seed", 0) for r in results.get("runs", [])})
        return {s: results | {"runs": [r for r in results["runs"] if r.get("seed", 0) == s]} for s in seeds}
    field_ = {"success": "generated", "clustering": "latent"}.get(experiment)
    if field_ is None or not results.get("by_seed"):
        return {}
    views = {results.get("seed", 0): results}
    views |= {int(s): results | {field_: v} for s, v in results["by_seed"].items()}
    return dict(sorted(views.items()))


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


def _plain(ok):
    """A rule's verdict as True / False / PARTLY / None (numpy booleans made plain)."""
    return ok if ok is None or ok == PARTLY else bool(ok)


def _checked(check: Callable[[dict], Outcome], results: dict) -> Outcome:
    """``check(results)`` with plain verdicts, at every tolerance too."""
    o = check(results)
    return o._replace(ok=_plain(o.ok), sweep=o.sweep and {t: _plain(v) for t, v in o.sweep.items()})


def rule_verdict(check: Callable[[dict], Outcome], experiment: str, results: dict) -> dict:
    """The verdict of one rule: one seed as the rule says; several seeds each on its own
    (each seed its own split, weights and projection), counted. ``per_seed`` keeps each
    seed's verdict word; ``sweep`` each tolerance's count (rules judged at several)."""
    views = _seed_views(experiment, results)
    if len(views) < 2:
        views = {results.get("seed", 0): results}
    outcomes = {s: _checked(check, view) for s, view in views.items()}
    per_seed = {s: o.ok for s, o in outcomes.items()}
    verdict = _VERDICTS[next(iter(per_seed.values()))] if len(per_seed) == 1 else _count(per_seed)
    numbers = (
        next(iter(outcomes.values())).numbers
        if len(outcomes) == 1
        else "; ".join(f"seed {s}: {o.numbers}" for s, o in outcomes.items())
    )
    row = {"verdict": verdict, "ours": numbers, "per_seed": {str(s): _VERDICTS[ok] for s, ok in per_seed.items()}}
    sweeps = [o.sweep for o in outcomes.values() if o.sweep]
    if sweeps:
        tolerances = sorted({t for sw in sweeps for t in sw}, key=float)
        by_tol = {t: {s: o.sweep.get(t) for s, o in outcomes.items() if o.sweep} for t in tolerances}
        row["sweep"] = {t: (_VERDICTS[next(iter(v.values()))] if len(v) == 1 else _count(v)) for t, v in by_tol.items()}
        row["robust"] = len(set(row["sweep"].values())) == 1
    return row
