"""The paper's claims, quoted verbatim, and the check of each against our results.

Where docs or the report say what "the paper" says, they quote it: :data:`CLAIMS` holds
whole sentences exactly as in shared/paper.tex (its abstract, *Experimental Results* and
*Summary*), with the sentence that carries their meaning where one leans on the next ("It
may look like ... very similar, but ..."), what we measure to test it, and the rule that
decides.

**Rules are fixed before runs and versioned.** Each rule has a ``version`` and its
``threshold`` (the effect size it asks for). A rule that changes gets a new version and
its earlier versions stay in ``previous``: :func:`check_claims` gives every earlier
verdict beside the current one, so a reader sees what the change did. The versions:

- 1 (0.2-0.5): :mod:`primspace.results.claim_rules_v1`, frozen;
- 2 (0.6): four rules changed (ties, "did not converge", clustering near chance, inter
  paired by fold), :mod:`primspace.results.claim_rules_v2`, which also holds the
  version-1 rules still current;
- 3 (0.9): the abstract's two central claims, first in the table
  (:mod:`primspace.results.claim_rules_central`);
- 4: ``infer_projection`` reads its whole sentence (the codes' drift from ``P m``), inter
  compares the sample std over folds, and the Summary's sentence on intra and inter
  generalisation is checked (:mod:`primspace.results.claim_rules_v4`).

Verdicts: ``holds``, ``partly`` (the sentence half holds: the numbers say which half),
``does not hold``, ``cannot be checked`` (the runs it needs are missing), ``not run``.
Each verdict has a ``direction`` (:data:`primspace.results.claim_verdicts.DIRECTIONS`):
"as the paper says" where it holds; "in the paper's favour" where the sentence fails
because random-projection initialisation does better than it says; "against the paper"
where it does worse or the effect is absent; "cannot be checked at this scale" where the
runs are missing or the sentence speaks of a setting not run. Each rule decides its
direction from its numbers. With several seeds each seed is checked on its own (its own
split, weights and P) and the verdict counts them
(:mod:`primspace.results.claim_verdicts`). A rule about every latent size gives its
verdict at each (``by_q``); the success rule is also judged at every tolerance of the
judge's declared sweep (:data:`primspace.sim.success.SEPARATION_SWEEP`), with a
robustness flag.

:func:`check_claims` reads an experiment directory, or the results held in a stored
summary (:mod:`primspace.results.summary`), through the same readers, and the codes
(for ``infer_projection``'s second half) where it is given them; :func:`claims_table` is
the table docs and the report print. This module imports no experiment.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

from primspace.results.claim_rules_central import (
    SUBSTANTIAL,
    WELL_SEPARATED_SHARE,
    generalisation_improved,
    separated_from_the_onset,
)
from primspace.results.claim_rules_v1 import CLAIMS_V1
from primspace.results.claim_rules_v2 import (
    LOW_DIMENSIONAL_Q,
    NO_GENERALISATION,
    NOT_CONVERGED_DROP,
    ORGANISED_SHARE,
    PAIRED_SHARE,
    SIMILAR_ACCURACY,
    SIMILAR_FACTOR,
    VERY_BADLY,
    clustering_similar,
    inter_improved_v2,
    random_fit_bad,
    random_not_converged,
    success_projection_higher,
    zero_within,
)
from primspace.results.claim_rules_v4 import (
    CODE_DRIFT,
    LITTLE_CHANGE,
    code_drift,
    inter_improved,
    intra_and_inter_improved,
    projection_good_and_still,
)
from primspace.results.claim_verdicts import PARTLY, UNCHECKABLE, Claim, Earlier, Outcome, rule_verdict
from primspace.results.measures import eighth_loss
from primspace.results.readers import read_results

__all__ = [
    "Outcome",
    "Claim",
    "Earlier",
    "CLAIMS",
    "RULES_VERSION",
    "check_claims",
    "codes_of_summary",
    "CODES_DIR",
    "verdict_text",
    "claims_table",
    "eighth_loss",
    "PARTLY",
]

#: The version of the rule set as a whole (the highest version of any rule).
RULES_VERSION = 4


def _v1(key: str) -> tuple[Earlier, ...]:
    return tuple(Earlier(1, c.test, c.check) for c in CLAIMS_V1 if c.key == key)


_INTER_V2 = (
    f"phase 2 over folds: projection's loss after 1/8 of the epochs and its final loss lower in mean and in at least "
    f"{PAIRED_SHARE:.0%} of the paired folds, and the std (ddof 0) of its final loss over folds lower; holds for all "
    "three, partly for one or two"
)

_INFER_SIMILAR = (
    "It may look like resulting performance of trained models for zero latent initialization and random "
    "projection latent initialization is very similar, but some primitives from the experimental setup "
    "require more precision than others."
)

#: The paper's sentences (verbatim, whole) and our rules: the central claims of its abstract
#: and Summary first (:mod:`primspace.results.claim_rules_central`,
#: :mod:`primspace.results.claim_rules_v4`), then *Experimental Results* in order.
CLAIMS: tuple[Claim, ...] = (
    Claim(
        "central_generalisation",
        "intra",
        "Abstract (central)",
        "Experimental results demonstrate substantial improvement in generalisation abilities for unobserved "
        "samples in the case of initialization of latent variables with random linear projection of motor data over "
        "initialization with zero or random values.",
        f"final eval loss (codes inferred with θ frozen) of zero and of random (those run) at least {SUBSTANTIAL:g}x "
        "projection's at every q; partly: above projection's at every q, not by that factor everywhere "
        "(the loss only: success in the simulator is the success row's)",
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
        "chance (1/k) to 1 (R² = 0.9999); partly: only the trained codes do (the codes are clustered before and "
        "after training, not during it)",
        f">= chance + {WELL_SEPARATED_SHARE:g}(1 - chance)",
        3,
        separated_from_the_onset,
    ),
    Claim(
        "central_intra_inter",
        ("intra", "inter"),
        "Summary and Discussion (central)",
        "Initialization of the latent variable by random linear projections improves intra- and inter-primitive "
        "generalization capabilities compared to conventional initialization methods.",
        "intra: the abstract's rule above (final eval loss of zero and random at least "
        f"{SUBSTANTIAL:g}x projection's at every q); inter: the inter rule below (v4); holds when both hold, partly "
        "when one holds or either holds partly, cannot be checked when either experiment is missing",
        f"both: >= {SUBSTANTIAL:g}x; paired, >= {PAIRED_SHARE:.0%} of folds",
        4,
        intra_and_inter_improved,
    ),
    Claim(
        "fit_random",
        "intra",
        "Intra-primitive generalisation, Fig. loss_train",
        "As you can see, random initialization performs very badly for low-dimensional latent space.",
        f"final fit loss at the smallest q (at most {LOW_DIMENSIONAL_Q}): random at least {VERY_BADLY:g}x projection's",
        f">= {VERY_BADLY:g}x",
        1,
        random_fit_bad,
    ),
    Claim(
        "fit_zero",
        "intra",
        "Intra-primitive generalisation, Fig. loss_train",
        "Zero initialization, on the other hand, differs very slightly from random linear projection case.",
        f"final fit loss of zero within a factor of {SIMILAR_FACTOR:g} of projection's at every q",
        f"within {SIMILAR_FACTOR:g}x",
        1,
        zero_within("fit", "fit"),
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
        random_not_converged,
        _v1("infer_random"),
    ),
    Claim(
        "infer_projection",
        "intra",
        "Intra-primitive generalisation, Fig. loss_test",
        "On the other hand, initialization with random linear projection yields good results already without any "
        "training, which means the initial distribution of projected points did not change much during the first "
        "part of the training.",
        "projection's eval loss before any inference step below zero's after the last, at every q; and the codes "
        f"fitted in the first part stay near their initial P m: mean ‖z_fit − P m‖ / ‖P m‖ below {LITTLE_CHANGE:g} "
        "at every q (needs the codes; without them that half cannot be checked and the verdict is at most partly)",
        f"strictly below; drift < {LITTLE_CHANGE:g}",
        4,
        projection_good_and_still,
        _v1("infer_projection"),
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
        zero_within("infer", "eval"),
    ),
    Claim(
        "success",
        "success",
        "Intra-primitive generalisation, Table assessment_table",
        "In particular, pushing and pulling the block as well as grasping is easy to fail if the gripper fingers "
        "miss just a bit.",
        "success rate of projection above zero's for pull, push and grasp (paper: 0.92/0.86, 0.94/0.9, 1.0/0.8), a "
        "difference counting only when the two Wilson 95 % intervals do not overlap; partly: higher on some, "
        "lower on none; at every judge tolerance of the sweep. The sentence's own point (these three fail more "
        "easily than the others) is not tested: the rule reads the paper's table beside it",
        "Wilson 95 % intervals apart",
        2,
        success_projection_higher,
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
        clustering_similar,
        _v1("clustering"),
    ),
    Claim(
        "inter",
        "inter",
        "Inter-primitive generalisation, Fig. loss_inter",
        "Proposed method shows slightly improved results in terms of convergence speed, final value of the loss "
        "function and robustness of the learning.",
        f"phase 2 over folds: projection's loss after 1/8 of the epochs and its final loss lower in mean and in at "
        f"least {PAIRED_SHARE:.0%} of the paired folds, and the sample std (ddof 1) of its final loss over folds "
        'lower; holds for all three, partly for one or two ("slightly" is not tested: no upper bound)',
        f"paired, >= {PAIRED_SHARE:.0%} of folds",
        4,
        inter_improved,
        _v1("inter") + (Earlier(2, _INTER_V2, inter_improved_v2),),
    ),
)


Source = str | Path | Mapping


#: Where :func:`codes_of_summary` looks for a summary's codes file: the stored summaries'
#: folder, relative to the working directory (the repository's root, where ``python -m
#: primspace.report.markdown`` runs).
CODES_DIR = Path("docs") / "results"


def codes_of_summary(summary: Mapping, folder: str | Path = CODES_DIR) -> Path | None:
    """The codes file a stored summary names (its ``codes.file``) in ``folder``, for
    :func:`check_claims`; None where it names none or the file is not there."""
    name = (summary.get("codes") or {}).get("file")
    return Path(folder) / name if name and (Path(folder) / name).is_file() else None


def _reader(source: Source) -> Callable[[str], dict | None]:
    """Results by experiment name, from a directory or from a mapping (a summary's ``results``)."""
    if isinstance(source, Mapping):
        return lambda name: source.get(name)
    return lambda name: read_results(source, name)


def _results(claim: Claim, read: Callable[[str], dict | None], cache: dict) -> dict | None:
    """The results ``claim`` reads: one experiment's, or for several ``{name: results or None}``
    (None when none ran)."""
    names = (claim.experiment,) if isinstance(claim.experiment, str) else claim.experiment
    for name in names:
        if name not in cache:
            cache[name] = read(name)
    if isinstance(claim.experiment, str):
        return cache[claim.experiment]
    found = {name: cache[name] for name in names}
    return found if any(v is not None for v in found.values()) else None


def check_claims(source: Source, codes: str | Path | None = None) -> list[dict]:
    """Each claim with its verdict on ``source`` (an experiment directory, or a mapping of
    results by experiment name): ``verdict`` (``holds`` / ``partly`` / ``does not hold`` /
    ``cannot be checked`` / ``not run``, counted over seeds), its ``direction``,
    ``per_seed``, the numbers behind it (``ours``), the rule's ``version`` and
    ``threshold``, ``sweep`` and ``robust`` where the rule is judged at several
    tolerances, ``by_q`` where at every latent size, and ``previous``: each earlier
    version's rule and verdict. ``codes``: an experiment directory or a summary's codes
    file (``NAME.codes.npz``) whose fitted codes ``infer_projection`` reads (None: that
    half cannot be checked)."""
    read = _reader(source)
    cache: dict[str, dict | None] = {}
    if codes is not None:
        intra, drift = read("intra"), code_drift(codes)
        cache["intra"] = intra if intra is None or not drift else intra | {CODE_DRIFT: drift}
    rows = []
    for claim in CLAIMS:
        results = _results(claim, read, cache)
        row = {
            "key": claim.key,
            "where": claim.where,
            "quote": claim.quote,
            "test": claim.test,
            "threshold": claim.threshold,
            "version": claim.version,
        }
        if results is None:
            rows.append(
                row | {"verdict": "not run", "direction": UNCHECKABLE, "ours": "", "per_seed": {}, "previous": []}
            )
            continue
        row |= rule_verdict(claim.check, claim.experiment, results)
        row["previous"] = [
            {
                "version": old.version,
                "test": old.test,
                "verdict": rule_verdict(old.check, claim.experiment, results)["verdict"],
            }
            for old in claim.previous
        ]
        rows.append(row)
    return rows


def verdict_text(row: dict, markdown: bool = False) -> str:
    """A row's verdict with its verdict at each latent size (at one: which) and at each judge
    tolerance, where the rule gives them: "partly — by latent size: q = 10: holds; q = 20:
    partly". ``markdown``: the verdict in bold, each seed's verdict beside it, "; " between
    the parts (the docs' tables); else " — " (the report's)."""
    sep = "; " if markdown else " — "
    text = f"**{row['verdict']}**" if markdown else row["verdict"]
    by_q = row.get("by_q") or {}
    if len(by_q) == 1:
        text += f" at q = {next(iter(by_q))}"
    if markdown and len(row.get("per_seed", {})) > 1:
        text += " (" + ", ".join(f"seed {s}: {v}" for s, v in row["per_seed"].items()) + ")"
    if len(by_q) > 1:
        text += f"{sep}by latent size: " + "; ".join(f"q = {q}: {v}" for q, v in by_q.items())
    if row.get("sweep"):
        robust = (
            "(robust)"
            if row["robust"]
            else "(**not robust** to the tolerance)"
            if markdown
            else "(NOT robust to the tolerance)"
        )
        text += f"{sep}by judge tolerance: " + ", ".join(f"{float(t) * 1000:g} mm {v}" for t, v in row["sweep"].items())
        text += f" {robust}"
    return text


def claims_table(source: Source, codes: str | Path | None = None) -> tuple[list[str], list[list]]:
    """The claims as a table: the paper's sentences, our rule (version, threshold), the
    verdict (at every latent size and judge tolerance where the rule gives them, and the
    earlier rules' verdicts where the rule changed), its direction, our numbers."""
    rows = []
    for r in check_claims(source, codes):
        verdict = verdict_text(r)
        for old in r["previous"]:
            verdict += f" [rule v{old['version']}: {old['verdict']}]"
        rows.append(
            [f"“{r['quote']}” ({r['where']})", f"v{r['version']}: {r['test']}", verdict, r["direction"], r["ours"]]
        )
    return ["the paper (verbatim)", "rule (version): what we test", "verdict", "direction", "ours"], rows
