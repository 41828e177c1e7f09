"""The measures the claims' rules read from results, shared by every rule version
(:mod:`primspace.results.claim_rules_v1`, :mod:`~primspace.results.claim_rules_v2`,
:mod:`~primspace.results.claim_rules_central`, :mod:`~primspace.results.claim_rules_v4`):
losses per latent size and init, the clustering's chance level, the loss an eighth of the
way through a curve, paired comparisons over folds. Numbers only, no verdict."""

from __future__ import annotations

import numpy as np

__all__ = ["losses_by_q", "has_inits", "chance_level", "eighth_loss", "paired_lower"]


def losses_by_q(results: dict, phase: str, at: int = -1) -> dict[int, dict[str, float]]:
    """``{q: {init: loss}}`` averaged over seeds, at epoch index ``at`` of ``phase``."""
    acc: dict[int, dict[str, list]] = {}
    for r in results["runs"]:
        curve = [h["loss"] for h in r[phase] if h.get("loss") is not None]
        if curve:
            acc.setdefault(r["latent_dim"], {}).setdefault(r["init"], []).append(curve[at])
    return {q: {i: float(np.mean(v)) for i, v in d.items()} for q, d in sorted(acc.items())}


def has_inits(d: dict, *inits: str) -> bool:
    """Whether ``d`` (by init) holds every one of ``inits``."""
    return all(i in d for i in inits)


def chance_level(results: dict) -> float | None:
    """1/k of a clustering result (k primitives), None when k is not in it."""
    k = results.get("trajectory", {}).get("data", {}).get("k") or results.get("n_clusters")
    return 1.0 / k if k else None


def eighth_loss(curve: list[dict]) -> float:
    """The loss an eighth of the way through a curve (at least epoch 1): the inter claim's
    "convergence speed" (a stored summary keeps this epoch)."""
    eighth = max(1, round(curve[-1]["epoch"] / 8))
    return min(curve, key=lambda h: abs(h["epoch"] - eighth))["loss"]


def paired_lower(a: dict, b: dict) -> tuple[float, int]:
    """Share of the common keys where ``b`` < ``a`` (strictly), and their number."""
    keys = sorted(set(a) & set(b))
    return (float(np.mean([b[k] < a[k] for k in keys])) if keys else float("nan")), len(keys)
