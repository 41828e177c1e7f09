"""The regime where codes help: prediction with few fitted demonstrations per primitive.

For each seed and each ``n`` of ``fitted_per_primitive``, a run keeps only ``n`` fitted
demonstrations per primitive (:func:`per_label_subset` of the preset's fitted split, the
intra split of :func:`~primspace.experiments.intra.split_indices`; nested: the ``n``
demonstrations of a smaller ``n`` are among those of a larger one), trains the decoder and
the codes on them (the projection start and the preset's schedule,
:func:`~primspace.experiments.runs.point_jobs`'s fit) and predicts the same evaluation
motions (the preset's evaluation split, at most ``eval_per_primitive`` per primitive, drawn
with the seed) at each observed fraction, with the primitive given and without it
(:data:`REGIME_ROWS`, every one a predictor of :mod:`primspace.predict`, fitted by
:func:`~primspace.predict.registry.fit_predictor`): the prior with its blend chosen by its
K-fold and with the decoded draws forced (blend 0), the Gaussian over the raw trajectories,
the tuned ProMP, the mixture and the nearest neighbour. MSE of the unobserved steps
(:func:`~primspace.predict.metrics.unobserved_mse`) and, on simulator data, the share the
simulator judges a success; each also per primitive.

The mixed variant (``mixed``): one primitive (the seed's, :func:`few_primitive`) keeps
:data:`MIXED_FEW` demonstrations while every other keeps the largest ``n``; its evaluation
motions alone are predicted, to set beside the run where every primitive keeps
:data:`MIXED_FEW` (does the shared decoder carry what the other primitives taught it?).

Each point is a grid point (``runs/regime<version>/...``): a finished point is not run again,
and the same seed gives the same numbers. A row that cannot be fitted or run at some ``n``
(e.g. a ProMP's EM on one demonstration) is recorded with its error, the others go on.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from primspace.data import MotionDataset
from primspace.experiments.intra import split_indices
from primspace.experiments.presets import ExperimentPreset
from primspace.experiments.runs import load_run_data, point_jobs
from primspace.experiments.sweep import GridPoint
from primspace.experiments.workspace import ExperimentDir
from primspace.utils.errors import UserError

__all__ = [
    "REGIME_VERSION",
    "REGIME_N",
    "REGIME_FRACTIONS",
    "REGIME_ROWS",
    "REGIME_GIVEN",
    "MIXED_FEW",
    "REGIME_RESULTS",
    "per_label_subset",
    "few_primitive",
    "check_counts",
    "regime_predictors",
    "run_regime_point",
    "run_regime",
    "regime_table",
]

#: Bumped when a point's content changes: points of another version are not reused.
REGIME_VERSION = 1
#: Fitted demonstrations per primitive (the command's default ``--fitted-per-primitive``).
REGIME_N = (2, 3, 5, 10, 20, 49)
#: Observed fractions.
REGIME_FRACTIONS = (0.1, 0.25, 0.5)
#: Demonstrations of the one primitive with few in the mixed variant.
MIXED_FEW = 2
#: The results' name (``OUT/results/regime.json``).
REGIME_RESULTS = "regime"
#: The rows: (name, given the test motion's primitive).
REGIME_ROWS = (
    ("prior (labels)", True),
    ("prior decoded (labels)", True),
    ("raw gaussian (labels)", True),
    ("promp tuned (labels)", True),
    ("mixture (labels)", True),
    ("nearest neighbour (labels)", True),
    ("prior (posterior)", False),
    ("prior decoded (posterior)", False),
    ("raw gaussian", False),
    ("promp tuned (one for all)", False),
    ("mixture", False),
    ("nearest neighbour", False),
)
#: The rows given the test motion's primitive.
REGIME_GIVEN = tuple(name for name, given in REGIME_ROWS if given)


def per_label_subset(indices, labels, count, seed: int, salt: int) -> np.ndarray:
    """The first ``count`` of each label's ``indices`` (``count``: one number, or ``{label: number}``)
    in an order drawn with ``seed`` and ``salt`` (the same order for every count, so a smaller
    subset lies in a larger one), sorted; a label with fewer keeps them all."""
    indices, labels = np.asarray(indices, dtype=np.int64), np.asarray(labels)
    kept = []
    for k, label in enumerate(np.unique(labels)):
        members = indices[labels == label]
        order = np.random.default_rng(np.random.SeedSequence([int(seed), int(salt), k])).permutation(len(members))
        take = count.get(int(label), 0) if isinstance(count, dict) else count
        kept.append(members[order[: int(take)]])
    return np.sort(np.concatenate(kept)) if kept else indices[:0]


def few_primitive(labels, seed: int) -> int:
    """The primitive that keeps :data:`MIXED_FEW` demonstrations in the mixed variant of ``seed``
    (the labels in turn, one per seed)."""
    names = np.unique(np.asarray(labels))
    return int(names[int(seed) % len(names)])


def check_counts(counts, available: int, option: str = "fitted_per_primitive") -> tuple[int, ...]:
    """``counts`` sorted, each checked: a whole number from 1 to ``available`` (the fewest fitted
    demonstrations any primitive has); one UserError naming ``option`` otherwise."""
    values = tuple(counts)
    if not values:
        raise UserError(f"{option} is empty")
    for n in values:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise UserError(f"{option}: {n!r} is not a whole number >= 1")
        if n > available:
            raise UserError(
                f"{option}: {n} is more than the {available} fitted demonstrations every primitive has "
                "(the preset's fitted split)"
            )
    return tuple(sorted(set(int(n) for n in values)))


def regime_predictors(run, fitted_data: MotionDataset, settings: dict | None = None) -> dict:
    """Every row of :data:`REGIME_ROWS`, fitted on ``run``'s fitted demonstrations; a row that cannot
    be fitted is its error instead. ``settings``: keywords of the rows' constructors by kind (``prior``,
    ``promp_tuned``, ``raw_gaussian``; tests pass small ones); the decoded prior's blend is 0 whatever they say."""
    from primspace.predict import MixturePredictor, NearestPeer, PriorPredictor
    from primspace.predict.gaussian_peers import RawGaussianPeer, TunedProMPPeer
    from primspace.predict.mixture import code_mixture
    from primspace.predict.registry import fit_predictor

    settings = dict(settings or {})
    prior, seed = dict(settings.get("prior") or {}), int(run.train_config.seed)
    promp, gauss = (dict(settings.get(cls.name) or {}) for cls in (TunedProMPPeer, RawGaussianPeer))
    candidates = code_mixture(run)
    builders = {
        "prior (labels)": lambda: PriorPredictor(run, given=True, **prior),
        "prior decoded (labels)": lambda: PriorPredictor(run, given=True, **(prior | {"blend": 0.0})),
        "raw gaussian (labels)": lambda: RawGaussianPeer(per_label=True, random_state=seed, **gauss),
        "promp tuned (labels)": lambda: TunedProMPPeer(per_label=True, random_state=seed, **promp),
        "mixture (labels)": lambda: MixturePredictor(run, condition=False, candidates=candidates, per_label=True),
        "nearest neighbour (labels)": lambda: NearestPeer(per_label=True),
        "raw gaussian": lambda: RawGaussianPeer(per_label=False, random_state=seed, **gauss),
        "promp tuned (one for all)": lambda: TunedProMPPeer(per_label=False, random_state=seed, **promp),
        "mixture": lambda: MixturePredictor(run, candidates=candidates),
        "nearest neighbour": lambda: NearestPeer(),
    }
    rows: dict = {}
    for name, build in builders.items():
        try:
            rows[name] = fit_predictor(build(), run, fitted_data)
        except (UserError, np.linalg.LinAlgError, ValueError) as exc:
            rows[name] = exc
    for name in ("prior", "prior decoded"):  # the same fitted prior, asked without the primitive
        given = rows[f"{name} (labels)"]
        rows[f"{name} (posterior)"] = given if isinstance(given, Exception) else given.asked()
    return {name: rows[name] for name, _ in REGIME_ROWS}


def _entry(run, scaled, truth, observed, test: MotionDataset, judge: bool, model_share: float) -> dict:
    """One row's numbers at one fraction (``scaled``: its prediction in the run's scaled units): mean
    MSE, success where judged (the prediction replayed in physical units), the model share, and each per label."""
    from primspace.predict.metrics import finite_mean, unobserved_mse

    errors = unobserved_mse(scaled, truth, observed, test.lengths)
    labels = np.asarray(test.labels)
    entry = {"mse": finite_mean(errors), "model_share": model_share, "by_label": {}}
    success = None
    if judge:
        from primspace.sim.success import evaluate_dataset

        motor = run.scaler.inverse_transform(scaled).astype(np.float32)
        success = np.array([r.success for r in evaluate_dataset(test, motor)], dtype=np.float64)
        entry["success"] = float(success.mean())
    for label in np.unique(labels):
        mine = labels == label
        cell = {"mse": finite_mean(errors[mine])}
        if success is not None:
            cell["success"] = float(success[mine].mean())
        entry["by_label"][str(int(label))] = cell
    return entry


def run_regime_point(
    run_dir: Path,
    data_path: str,
    preset: dict,
    seed: int,
    latent_dim: int,
    fitted_idx: list,
    eval_idx: list,
    fractions: tuple,
    judge: bool,
    settings: dict | None = None,
) -> dict:
    """One point: fit θ and the codes on ``fitted_idx`` (projection start, the preset's schedule;
    resumed from its checkpoint) into ``run_dir/fit``, then every row on ``eval_idx`` at each fraction."""
    from primspace.predict.registry import built_on_run, model_share, run_predictor
    from primspace.train import configure_process, fit
    from primspace.train.observe import Observation

    preset_obj = ExperimentPreset.from_dict(preset)
    data, use_images = load_run_data(data_path, preset_obj)
    fit_job = point_jobs(run_dir, data, preset_obj, "projection", latent_dim, seed, fitted_idx, eval_idx, use_images)[0]
    configure_process(fit_job["train_config"])
    run = fit(**fit_job, progress=False)
    data = data.without_images()
    rows = regime_predictors(run, data, settings)
    test = data.subset(np.asarray(eval_idx))
    truth = run.scaler.transform(test.motor)
    table: dict = {}
    for f in fractions:
        rule = Observation.build(f)
        observed = rule.masks(test.valid_lengths, test.length)[0]
        for name, predictor in rows.items():
            cell = table.setdefault(name, {})
            if isinstance(predictor, Exception):
                cell[f"{f:g}"] = {"error": f"{type(predictor).__name__}: {predictor}"}
                continue
            try:
                forecast = run_predictor(predictor, run, test, rule)
            except (UserError, np.linalg.LinAlgError, ValueError) as exc:
                cell[f"{f:g}"] = {"error": f"{type(exc).__name__}: {exc}"}
                continue
            share = model_share(forecast.details, built_on_run(predictor))
            cell[f"{f:g}"] = _entry(run, forecast.motor, truth, observed, test, judge, share)
    return {"methods": table, "n_fitted": len(fitted_idx), "n_test": len(eval_idx)}


def _point_key(tag: str, seed: int, cap: int | None) -> str:
    return f"regime{REGIME_VERSION}/projection-{tag}-s{seed}" + ("" if cap is None else f"-e{cap}")


def _plan(exp: ExperimentDir, counts, cap, mixed: bool, seeds) -> dict:
    """Per seed of ``seeds``: the fitted subsets by ``n`` (and the mixed variant's), the evaluation motions,
    the few primitive."""
    data = exp.dataset()
    labels = np.asarray(data.labels)
    plans = {}
    for seed in seeds:
        fitted, evaluation = split_indices(labels, exp.preset.train_fraction, seed)
        ns = check_counts(counts, int(np.unique(labels[fitted], return_counts=True)[1].min()))
        if cap is not None:
            check_counts((cap,), int(np.unique(labels[evaluation], return_counts=True)[1].min()), "eval_per_primitive")
            evaluation = per_label_subset(evaluation, labels[evaluation], cap, seed, 51)
        plan = {"n": {n: per_label_subset(fitted, labels[fitted], n, seed, 50) for n in ns}, "eval": evaluation}
        if mixed and MIXED_FEW in ns and max(ns) > MIXED_FEW:
            few = few_primitive(labels, seed)
            many = {int(k): max(ns) for k in np.unique(labels)} | {few: MIXED_FEW}
            plan["mixed"] = (few, per_label_subset(fitted, labels[fitted], many, seed, 50))
        plans[seed] = plan
    return plans


def run_regime(
    exp: ExperimentDir,
    fitted_per_primitive=REGIME_N,
    eval_per_primitive: int | None = None,
    fractions=REGIME_FRACTIONS,
    mixed: bool = True,
    settings: dict | None = None,
    seeds=None,
) -> dict:
    """The regime grid over the preset's seeds (module docstring): write ``results/regime.json`` and
    ``figures/regime_errors.png``. ``fitted_per_primitive``: the ``n`` (each from 1 to the fitted split's
    smallest primitive); ``eval_per_primitive``: at most this many evaluation motions per primitive
    (None: all); ``mixed``: also the variant with one primitive at :data:`MIXED_FEW`; ``settings``:
    the rows' keywords (:func:`regime_predictors`; None: their defaults; not in the points' keys); ``seeds``:
    only those of the preset's seeds (the results then hold those seeds only; None: all)."""
    from primspace.experiments.prediction import judgeable
    from primspace.experiments.runs import focus_runs

    data = exp.dataset()
    if data.labels is None:
        raise UserError("the regime experiment needs labelled data: its n counts demonstrations per primitive")
    chosen = [s for s in exp.preset.seeds if seeds is None or s in set(seeds)]
    plans = _plan(exp, fitted_per_primitive, eval_per_primitive, mixed, chosen)
    q = focus_runs(exp, {"runs": []})[0]
    judge, extra = judgeable(data), () if settings is None else (settings,)
    points, where = [], {}
    for seed, plan in plans.items():
        common = (str(exp.data_path), exp.preset.to_dict(), seed, q)
        for n, subset in plan["n"].items():
            key = _point_key(f"n{n}", seed, eval_per_primitive)
            points.append(
                GridPoint(key, (*common, subset.tolist(), plan["eval"].tolist(), tuple(fractions), judge, *extra))
            )
            where[key] = (seed, str(n))
        if "mixed" in plan:
            few, subset = plan["mixed"]
            test = plan["eval"][np.asarray(data.labels)[plan["eval"]] == few]
            many = max(plan["n"])  # in the key: the others' count changes the point
            key = _point_key(f"mixed{MIXED_FEW}of{many}", seed, eval_per_primitive)
            points.append(GridPoint(key, (*common, subset.tolist(), test.tolist(), tuple(fractions), judge, *extra)))
            where[key] = (seed, "mixed")
    with exp.stage("regime"):
        grid = exp.grid(run_regime_point, points, "regime of few demonstrations")
    by_seed: dict = {}
    for key, (seed, tag) in where.items():
        if key in grid.results:
            entry = by_seed.setdefault(str(seed), {"n": {}, "n_eval": len(plans[seed]["eval"])})
            if tag == "mixed":
                entry["mixed"] = grid.results[key] | {"few": plans[seed]["mixed"][0]}
            else:
                entry["n"][tag] = grid.results[key]
    results = {
        "version": REGIME_VERSION,
        "latent_dim": q,
        "fractions": [float(f) for f in fractions],
        "fitted_per_primitive": sorted({n for plan in plans.values() for n in plan["n"]}),
        "eval_per_primitive": eval_per_primitive,
        "train_fraction": exp.preset.train_fraction,
        "mixed_few": MIXED_FEW,
        "rows": [name for name, _ in REGIME_ROWS],
        "given_rows": list(REGIME_GIVEN),
        "judged": judge,
        "settings": settings or {},
        "label_names": list(data.label_names or []),
        "by_seed": by_seed,
        "failures": grid.failures,
        "table": regime_table(by_seed),
        "mixed": mixed_table(by_seed),
    }
    exp.write_results(REGIME_RESULTS, results)
    _figure(exp, results)
    return results


def _stats(values: list) -> dict:
    from primspace.experiments.prediction_table import mean_std_count

    return mean_std_count(values)


def _gather(cells: list[dict]) -> dict:
    """``{"mse" | "success" | "model_share": [mean, std (ddof 1), n]}`` over the seeds' ``cells`` (those with a number)."""
    out = {}
    for name in ("mse", "success", "model_share"):
        values = [c[name] for c in cells if c.get(name) is not None and np.isfinite(c[name])]
        if values:
            out[name] = _stats(values)
    return out


def regime_table(by_seed: dict) -> dict:
    """``{row: {n: {fraction: {"mse" | "success" | "model_share": [mean, std, count]}}}}`` over seeds
    (a cell only where some seed has a number)."""
    cells: dict = {}
    for seed in by_seed.values():
        for n, point in seed["n"].items():
            for row, fractions in point["methods"].items():
                for f, entry in fractions.items():
                    cells.setdefault(row, {}).setdefault(n, {}).setdefault(f, []).append(entry)
    return {
        row: {n: {f: _gather(v) for f, v in ns[n].items()} for n in sorted(ns, key=int)} for row, ns in cells.items()
    }


def mixed_table(by_seed: dict) -> dict:
    """The mixed variant: ``{row: {fraction: {"mixed": cell, "alone": cell}}}`` over seeds, ``mixed`` the few
    primitive's motions predicted by the run where the others keep the largest ``n``, ``alone`` the same
    primitive's motions by the run where every primitive keeps :data:`MIXED_FEW` (its per-label numbers)."""
    pairs: dict = {}
    for seed in by_seed.values():
        mixed, alone = seed.get("mixed"), seed["n"].get(str(MIXED_FEW))
        if mixed is None or alone is None:
            continue
        few = str(mixed["few"])
        for row, fractions in mixed["methods"].items():
            for f, entry in fractions.items():
                cell = pairs.setdefault(row, {}).setdefault(f, {"mixed": [], "alone": []})
                cell["mixed"].append(entry)
                cell["alone"].append(alone["methods"].get(row, {}).get(f, {}).get("by_label", {}).get(few, {}))
    return {
        row: {f: {part: _gather(v) for part, v in cell.items()} for f, cell in fr.items()} for row, fr in pairs.items()
    }


def _figure(exp: ExperimentDir, results: dict) -> None:
    """figures/regime_errors.png: MSE of the rest against ``n`` per row (log-log), one panel per task."""
    from primspace.plots import save_figure
    from primspace.plots.regime import plot_error_against_n
    from primspace.results.regime import regime_panels

    panels = regime_panels(results, "mse")
    if any(panels.values()):
        save_figure(plot_error_against_n(panels, ylabel="MSE of the rest"), exp.figure("regime_errors"))
