"""Priors in code space per primitive, and the primitive as an input.

The paper's latent space is structured: codes of one primitive lie near a common affine
subspace (*Clustering*). :class:`PriorPredictor` makes each primitive a distribution
over codes and predicts the rest of a motion under it, with θ frozen:

1. **Primitives** (:mod:`primspace.predict.primitives`): the labels of the fitted
   demonstrations, or clusters of the fitted codes found without labels (the paper's
   affine low-rank subspace clustering).
2. **A prior per primitive** (:mod:`primspace.predict.code_prior`): a Gaussian over its
   fitted codes, the family (shrunk full covariance, low rank plus diagonal, or the affine
   subspace with an isotropic spread) chosen by the held-out likelihood of the fitted codes.
3. **Draws decoded once**: ``n_samples`` codes per primitive, decoded in :meth:`fit`; the
   decoded motions and their codes form one Gaussian per primitive (their moments).
4. **Conditioning** on the observed entries (the ensemble Kalman update, as ProMP
   conditions its Gaussian over trajectories): given the primitive (``primitive=`` a name
   or id for every motion, or ``given=True``: each motion's label), its conditioned
   mean; without it, the posterior over primitives, each primitive's evidence of the
   observed steps ``log N(x_o; μ_o, Σ_oo + r I)`` tempered by ``T`` plus the log share of
   the fitted codes it holds, and the posterior-weighted conditioned means (the best
   prediction under a squared error when the prefix leaves the primitive ambiguous).
5. The continuity correction (:func:`~primspace.predict.candidates.continuity_correction`).

The noise ``r`` (given the primitive, and without it) and the temperature ``T`` are chosen
per observation rule without the answer, by K-fold prediction of the fitted
demonstrations: each fold's codes are left out of the priors, which are drawn and decoded
again without them; ``r`` by the error of the rest, ``T`` by the log-loss of the held-out
demonstrations' own primitive (calibration), then the label-free ``r`` by the error of the
posterior-weighted prediction.

Online (:meth:`PriorPredictor.predict_online`): the same Gaussians filtered a step at a
time (:class:`~primspace.predict.code_prior.SequentialGaussian`), equal after step ``t``
to the offline forecast of that prefix with the same ``r`` and ``T`` (tested).
"""

from __future__ import annotations

import copy

import numpy as np

from primspace.predict.base import Forecast, Predictor, observation_rule, observed_mask
from primspace.predict.candidates import continuity_correction
from primspace.predict.code_prior import (
    CV_FOLDS,
    DecodedGaussian,
    choose_prior,
    condition_primitives,
    fit_gaussian,
    fold_split,
)
from primspace.predict.metrics import check_labels, check_lengths, check_motor, unobserved_mse, valid_mask
from primspace.predict.primitives import (
    PRIMITIVE_SOURCES,
    primitives_from_clusters,
    primitives_from_labels,
    top1_accuracy,
)
from primspace.predict.prior_stream import PriorStream
from primspace.predict.selection_cache import decoded_draws
from primspace.train.api import reconstruct
from primspace.train.observe import NOTHING, Observation
from primspace.utils.errors import UserError
from primspace.utils.progress import stage

__all__ = ["PriorPredictor", "PRIOR", "NOISE_GRID", "TEMPERATURE_GRID", "BLEND_GRID", "CV_SAMPLES", "MAX_PRIOR_SAMPLES"]

#: The name of the prior predictor among the predictors of :func:`primspace.predict.predict`.
PRIOR = "prior"
#: Observation noise ``r`` per entry (scaled units²) tried by the K-fold choice.
NOISE_GRID = (1e-5, 1e-4, 1e-3, 1e-2)
#: Temperatures of the evidence tried by the K-fold choice (1: the evidence as it is).
TEMPERATURE_GRID = (1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0, 3000.0)
#: Weights of the fitted pairs' Gaussian against the decoded draws' tried by the K-fold choice.
BLEND_GRID = (0.0, 0.5, 0.9, 1.0)
#: Draws per primitive of each fold's priors in the K-fold choice (at most ``n_samples``).
CV_SAMPLES = 500
#: The most draws per primitive (``n_samples``, ``--prior-samples``): each is decoded and kept, so
#: memory grows with it (25 times the default; the K-fold choice reads at most :data:`CV_SAMPLES`).
MAX_PRIOR_SAMPLES = 50_000


class PriorPredictor(Predictor):
    """A prior in code space per primitive, conditioned on the observed steps (module docstring).

    Parameters
    ----------
    run : TrainedRun or path-like
        The trained run (θ frozen; not changed).
    primitive : str or int, optional
        The primitive of every motion (a name of :attr:`primitives_` or an id); None: each
        motion's label when ``given``, else the posterior over primitives.
    given : bool
        Each motion's primitive is its label (``labels`` of :meth:`predict`).
    primitives : {"labels", "clusters"}
        The fitted demonstrations' labels, or clusters of the fitted codes.
    n_clusters : int, optional
        Clusters when ``primitives="clusters"`` (default: the number of labels).
    label_names : list of str, optional
        Names of the labels (set by :func:`~primspace.predict.api.fit_predictor` from the data).
    family : "auto" or (name, setting)
        The prior's family (:data:`~primspace.predict.code_prior.PRIOR_GRID`); auto: chosen by
        held-out likelihood.
    n_samples : int
        Codes drawn and decoded per primitive.
    noise, temperature : "auto" or float
        ``r`` and ``T``; auto: chosen per observation rule by K-fold prediction.
    blend : "auto" or float in [0, 1]
        The weight of the fitted demonstrations' own Gaussian (paired with their codes) against
        the decoded draws' (0: the draws alone); auto: chosen per rule by K-fold prediction.
    continuity : bool
    random_state : int, optional
        Seed of the draws and folds (default: the run's seed).
    progress : bool, optional
    draws_dir : path-like, optional
        A folder to keep the decoded draws of :meth:`fit` in and read them back from (the same codes and
        decoder weights: the same numbers; :func:`~primspace.predict.selection_cache.decoded_draws`);
        None: decoded every time.
    """

    name = PRIOR

    def __init__(
        self,
        run,
        primitive=None,
        given: bool = False,
        primitives: str = "labels",
        n_clusters: int | None = None,
        label_names=None,
        family="auto",
        n_samples: int = 2000,
        noise="auto",
        temperature="auto",
        blend="auto",
        continuity: bool = True,
        random_state: int | None = None,
        progress: bool | None = False,
        draws_dir=None,
    ):
        self.run = run
        self.primitive = primitive
        self.given = given
        self.primitives = primitives
        self.n_clusters = n_clusters
        self.label_names = label_names
        self.family = family
        self.n_samples = n_samples
        self.noise = noise
        self.temperature = temperature
        self.blend = blend
        self.continuity = continuity
        self.random_state = random_state
        self.progress = progress
        self.draws_dir = draws_dir

    @property
    def needs_labels(self) -> bool:
        """Given each motion's primitive by its label."""
        return bool(self.given) and self.primitive is None

    # -- fit ------------------------------------------------------------------------------
    def fit(self, motor, labels=None, lengths=None, frames=None) -> PriorPredictor:
        """Group the run's fitted codes into primitives, choose and fit their priors, draw and decode.
        ``motor`` (scaled, the run's fitted samples in its order) is kept for the choices of ``r`` and ``T``."""
        run = self.resolve_run()
        self._check_params()
        motor = check_motor(motor)
        codes = np.asarray(run.latents, dtype=np.float64)
        if len(motor) != len(codes):
            raise UserError(f"the prior is fitted on the run's {len(codes)} fitted demonstrations, got {len(motor)}")
        labels = check_labels(labels, len(codes))
        self.fitted_, self.fitted_lengths_ = motor, check_lengths(lengths, *motor.shape[:2])
        self.seed_ = int(run.train_config.seed) if self.random_state is None else int(self.random_state)
        self.primitives_ = self._primitives(codes, labels)
        self.primitive_ = None if self.primitive is None else self.primitives_.resolve(self.primitive)
        groups = [codes[self.primitives_.members(k)] for k in range(self.primitives_.count)]
        self.prior_choice_ = (
            choose_prior(groups, seed=self.seed_) if self.family == "auto" else {"family": tuple(self.family)}
        )
        self.shares_ = np.array([len(g) for g in groups], dtype=np.float64) / sum(len(g) for g in groups)
        with stage(
            f"prior: drawing and decoding {self.n_samples} codes for each of {len(groups)} primitives",
            enabled=self.progress,
        ):
            # each primitive's prior in code space (GaussianCode), and its draws decoded
            self.gaussians_, self.ensembles_ = self._ensembles(groups, int(self.n_samples), [self.seed_, 39], True)
        members = [self.primitives_.members(k) for k in range(self.primitives_.count)]
        self.pairs_ = self._pairs(members)  # the fitted demonstrations with their codes, per primitive
        self.blends_: dict = {}
        self.choices_: dict = {}
        self.folds_ = None
        return self

    def _pairs(self, members: list) -> list:
        """Per primitive, the Gaussian of its fitted demonstrations (scaled, flattened) paired with
        their codes, the fitted codes' indices ``members[k]`` (None for fewer than two)."""
        flat = self.fitted_.reshape(len(self.fitted_), -1)
        codes = np.asarray(self.run_.latents, dtype=np.float64)
        return [
            DecodedGaussian(np.concatenate([flat[m], codes[m]], axis=1), flat.shape[1]) if len(m) > 1 else None
            for m in members
        ]

    def blended(self, weight: float) -> list[DecodedGaussian]:
        """Each primitive's Gaussian: ``weight`` of its fitted pairs and ``1 - weight`` of its decoded
        draws (:meth:`~primspace.predict.code_prior.DecodedGaussian.blend`; kept per weight)."""
        if weight not in self.blends_:
            self.blends_[weight] = [DecodedGaussian.blend(d, m, weight) for d, m in zip(self.pairs_, self.ensembles_)]
        return self.blends_[weight]

    def _check_params(self) -> None:
        if self.primitives not in PRIMITIVE_SOURCES:
            raise UserError(f"primitives must be one of {', '.join(PRIMITIVE_SOURCES)}, got {self.primitives!r}")
        n = self.n_samples
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 2 <= n <= MAX_PRIOR_SAMPLES:
            raise UserError(f"n_samples must be a whole number in 2..{MAX_PRIOR_SAMPLES}, got {n!r}")
        for name in ("noise", "temperature"):
            value = getattr(self, name)
            if value != "auto" and not (isinstance(value, (int, float)) and float(value) > 0):
                raise UserError(f"{name} must be 'auto' or a number > 0, got {value!r}")
        if self.blend != "auto" and not (isinstance(self.blend, (int, float)) and 0.0 <= float(self.blend) <= 1.0):
            raise UserError(f"blend must be 'auto' or a number in [0, 1], got {self.blend!r}")

    def _primitives(self, codes: np.ndarray, labels):
        if self.primitives == "labels":
            return primitives_from_labels(labels, self.label_names)
        k = self.n_clusters
        if k is None:
            if labels is None:
                raise UserError("clusters of the codes need n_clusters when the fitted data has no labels")
            k = len(np.unique(labels[labels >= 0]))
        return primitives_from_clusters(codes, k, labels, self.label_names, random_state=self.seed_)

    def _ensembles(self, groups: list, n: int, seed, keep: bool = False) -> tuple[list, list[DecodedGaussian]]:
        """Each primitive's prior fitted on ``groups`` and its ``n`` draws decoded (codes appended; ``keep``:
        the decoded draws kept in :attr:`draws_dir` when it is set)."""
        rng = np.random.default_rng(seed)
        pooled = [g for g in groups if len(g) > 1]
        var = float(np.mean([g.var(axis=0, ddof=1).mean() for g in pooled])) if pooled else 1.0
        family = self.prior_choice_["family"]
        gaussians = [fit_gaussian(g, family, var) for g in groups]
        draws = [g.sample(n, rng) for g in gaussians]
        codes = np.concatenate(draws).astype(np.float32)

        def decode(codes):
            return reconstruct(self.run_, codes, images=False, batch_size=1024)[0]

        kept = keep and self.draws_dir is not None
        decoded = decoded_draws(self.draws_dir, self.run_, codes, decode) if kept else decode(codes)
        scaled = self.run_.scaler.transform(decoded).reshape(len(decoded), -1)
        motion = scaled.shape[1]
        return gaussians, [
            DecodedGaussian(np.concatenate([scaled[i * n : (i + 1) * n], d], axis=1), motion)
            for i, d in enumerate(draws)
        ]

    def asked(self, primitive=None, given: bool = False) -> PriorPredictor:
        """This fitted predictor asked differently (a primitive for every motion, each motion's
        label, or neither: the posterior), sharing its fitted priors, draws and choices."""
        other = copy.copy(self)
        other.primitive, other.given = primitive, given
        other.primitive_ = None if primitive is None else self.primitives_.resolve(primitive)
        return other

    # -- conditioning ---------------------------------------------------------------------
    def posterior_weights(self, evidence: np.ndarray, temperature: float) -> np.ndarray:
        """(n, P) posterior over primitives from the evidences and the fitted codes' shares."""
        logits = evidence / temperature + np.log(self.shares_)[None]
        logits -= logits.max(axis=1, keepdims=True)
        w = np.exp(logits)
        return w / w.sum(axis=1, keepdims=True)

    def forecast(self, motor, observed, labels=None, lengths=None, frames=None) -> Forecast:
        """The conditioned (given) or posterior-weighted (not given) motions, their codes, and
        ``details["prior"]`` (the choices, and per motion the posterior over primitives)."""
        motor = self.check_query(motor)
        n, steps, joints = motor.shape
        rule = observation_rule(observed, lengths, (n, steps))
        if rule.motor == NOTHING:
            raise UserError("the prior conditions on the observed joints, and observe='none' observes none")
        mask = observed_mask(observed, lengths, (n, steps))
        seen = np.where(mask[..., None], motor, 0.0)
        ids = self._given_ids(labels, n)
        choice = self.choice(rule)
        r, weight = self._setting(choice, ids is not None)
        wanted = [[int(k)] for k in ids] if ids is not None else [list(range(self.primitives_.count))] * n
        means, evidence = condition_primitives(self.blended(weight), seen, mask, wanted, r)
        if ids is not None:
            weights = np.eye(self.primitives_.count)[ids]
        else:
            weights = self.posterior_weights(evidence, choice["temperature"])
        out, codes = self.mix(means, weights, seen.shape)
        if self.continuity:
            out = continuity_correction(out, seen, mask, valid_mask(check_lengths(lengths, n, steps), steps))
        details = {"prior": self.summary(choice), "posterior": weights.tolist(), "model_share": 1.0 - weight}
        return Forecast(out, codes, details)

    @staticmethod
    def _setting(choice: dict, given: bool) -> tuple[float, float]:
        """The noise and blend of the task (given the primitive, or not)."""
        return (choice["noise_given"], choice["blend_given"]) if given else (choice["noise"], choice["blend"])

    @property
    def told_primitive(self) -> bool:
        """Whether each motion's primitive is given (``primitive=`` one for all, or ``given``: its label)."""
        return self.primitive_ is not None or bool(self.given)

    def _given_ids(self, labels, n: int):
        """Each motion's primitive when it is given (None: the posterior decides)."""
        if self.primitive_ is not None:
            return np.full(n, self.primitive_, dtype=np.int64)
        if not self.given:
            return None
        labels = check_labels(labels, n)
        if labels is None:
            raise UserError("a prior given the primitive reads each motion's label: pass labels")
        return self.primitives_.for_labels(labels)

    def mix(self, means: np.ndarray, weights: np.ndarray, shape: tuple):
        """Posterior-weighted motions (n, T, J) and the codes of each motion's top primitive."""
        motion = self.ensembles_[0].n_motion
        safe = np.nan_to_num(means)
        out = np.einsum("np,npd->nd", weights, safe[..., :motion]).reshape(shape)
        top = np.argmax(weights, axis=1)
        codes = safe[np.arange(len(top)), top, motion:].astype(np.float32)
        return out, codes

    def summary(self, choice: dict | None = None) -> dict:
        """What ``result.json`` records of the prior and its choices."""
        family = self.prior_choice_["family"]
        return {
            "family": [family[0], float(family[1])],
            "family_scores": self.prior_choice_.get("scores", {}),
            "n_samples": int(self.n_samples),
            "primitives": self.primitives_.summary(),
            "primitive": None if self.primitive_ is None else self.primitives_.names[self.primitive_],
            **({} if choice is None else {k: v for k, v in choice.items() if k != "cv"}),
        }

    # -- choices of r and T ------------------------------------------------------------------
    def choice(self, rule: Observation) -> dict:
        """``noise_given``, ``blend_given``, ``noise``, ``blend``, ``temperature`` (and the K-fold
        scores ``cv``) for ``rule``: the given values, or chosen on first use (module docstring)."""
        if rule.key not in self.choices_:
            fixed = {"noise": self.noise, "temperature": self.temperature, "blend": self.blend}
            if all(v != "auto" for v in fixed.values()):
                r, w, t = float(self.noise), float(self.blend), float(self.temperature)
                self.choices_[rule.key] = dict(noise_given=r, blend_given=w, noise=r, blend=w, temperature=t)
            else:
                with stage("prior: choosing its settings by K-fold prediction", enabled=self.progress):
                    self.choices_[rule.key] = self._cross_validate(rule)
        return self.choices_[rule.key]

    def _folds(self) -> list:
        """K folds of the fitted demonstrations (within each primitive), each with the priors
        fitted, drawn and decoded, and the fitted pairs, without it:
        ``[(held-out indices, draws, pairs)]`` (kept)."""
        if self.folds_ is None:
            members = [self.primitives_.members(k) for k in range(self.primitives_.count)]
            fold_of = fold_split(members, len(self.fitted_), [self.seed_, 39, 2], CV_FOLDS)
            codes = np.asarray(self.run_.latents, dtype=np.float64)
            n = min(int(self.n_samples), CV_SAMPLES)
            self.folds_ = []
            for f in range(CV_FOLDS):
                held = np.flatnonzero(fold_of == f)
                keep = [np.setdiff1d(self.primitives_.members(k), held) for k in range(self.primitives_.count)]
                keep = [kept if len(kept) else self.primitives_.members(k) for k, kept in enumerate(keep)]
                if held.size:
                    draws = self._ensembles([codes[i] for i in keep], n, [self.seed_, 39, 3, f])[1]
                    self.folds_.append((held, draws, self._pairs(keep)))
        return self.folds_

    def _grid(self, name: str, grid) -> list[float]:
        value = getattr(self, name)
        return list(grid) if value == "auto" else [float(value)]

    def _fold_predictions(self, observed: np.ndarray, r: float, weight: float) -> tuple[np.ndarray, np.ndarray]:
        """Every fitted demonstration's conditioned means (m, P, D) and evidences (m, P), each
        predicted by the fold that left it out."""
        fitted, count = self.fitted_, self.primitives_.count
        means = np.full((len(fitted), count, self.ensembles_[0].mean.shape[0]), np.nan)
        evidence = np.full((len(fitted), count), -np.inf)
        for held, draws, pairs in self._folds():
            ensembles = [DecodedGaussian.blend(d, m, weight) for d, m in zip(pairs, draws)]
            seen = np.where(observed[held, :, None], fitted[held], 0.0)
            means[held], evidence[held] = condition_primitives(
                ensembles, seen, observed[held], [range(count)] * len(held), r
            )
        return means, evidence

    def _cross_validate(self, rule: Observation) -> dict:
        """The K-fold choice of ``r`` and the blend (given and not) and ``T`` for ``rule`` (module docstring)."""
        lengths = self.fitted_lengths_
        observed = rule.masks(lengths, self.fitted_.shape[1])[0]
        valid = valid_mask(lengths, self.fitted_.shape[1])
        scored = self.primitives_.assignment >= 0
        truth = self.primitives_.assignment[scored]
        temps = self._grid("temperature", TEMPERATURE_GRID)
        scores: dict = {"given": {}, "posterior": {}}
        best_given, best_free = (np.inf,), (np.inf, np.inf)
        for weight in self._grid("blend", BLEND_GRID):
            for r in self._grid("noise", NOISE_GRID):
                means, evidence = self._fold_predictions(observed, r, weight)
                key = f"blend {weight:g}, noise {r:g}"
                args = (means[scored], observed[scored], valid[scored])
                given = self._fold_error(np.eye(self.primitives_.count)[truth], *args)
                scores["given"][key] = given
                best_given = min(best_given, (given, r, weight), key=lambda x: x[0])
                rows = np.arange(len(truth))
                logloss = {
                    t: -np.log(self.posterior_weights(evidence[scored], t)[rows, truth] + 1e-300).mean() for t in temps
                }
                t = min(logloss, key=logloss.get)
                free = self._fold_error(self.posterior_weights(evidence[scored], t), *args)
                scores["posterior"][key] = {"temperature": t, "log_loss": float(logloss[t]), "mse": free}
                # nothing left to predict (every step observed): the log-loss decides
                best_free = min(best_free, (free, float(logloss[t]), r, weight, t), key=lambda x: x[:2])
        return {
            "noise_given": best_given[1],
            "blend_given": best_given[2],
            "noise": best_free[2],
            "blend": best_free[3],
            "temperature": best_free[4],
            "cv": scores,
        }

    def _fold_error(self, weights: np.ndarray, means: np.ndarray, observed: np.ndarray, valid: np.ndarray) -> float:
        """Mean unobserved MSE of the weighted held-out predictions (after the continuity correction)."""
        idx = np.flatnonzero(valid.any(axis=1))
        truth = self.fitted_[np.flatnonzero(self.primitives_.assignment >= 0)][idx]
        seen = np.where(observed[idx, :, None], truth, 0.0)
        out, _ = self.mix(means[idx], weights[idx], truth.shape)
        out = continuity_correction(out, seen, observed[idx], valid[idx])
        errors = unobserved_mse(out, truth, observed[idx], valid[idx].sum(axis=1))
        errors = errors[np.isfinite(errors)]
        return float(errors.mean()) if errors.size else 0.0

    # -- online -----------------------------------------------------------------------------
    def stream(self, truth, lengths, labels, frames, steps, keep, data=None) -> PriorStream:
        """The priors filtered a step at a time (module docstring), with the ``r`` and ``T`` chosen for
        a prefix of ``keep`` steps before the first step arrives; equal after step ``t`` to ``forecast``
        of that prefix with the same ``r`` and ``T``. The result's ``codes`` are the top primitive's
        conditioned code after each step."""
        choice = self.choice(Observation.build(int(keep)))
        ids = self._given_ids(labels, len(truth))
        r, weight = self._setting(choice, ids is not None)
        return PriorStream(self, truth, lengths, ids, r, weight, choice["temperature"], int(steps[0]))

    def online_share(self) -> float | None:
        """The share of the decoded draws in the Gaussians of the one observation rule chosen so far
        (``1 - blend``; None when no rule or several were chosen)."""
        if len(self.choices_) != 1:
            return None
        choice = next(iter(self.choices_.values()))
        return 1.0 - self._setting(choice, self.told_primitive)[1]

    def describe(self, details: dict, labels=None) -> dict:
        """What ``result.json`` records of a forecast's ``details``: the prior's summary, the
        ``model_share`` (the weight of the decoded draws against the fitted demonstrations' own
        Gaussian, ``1 - blend``: 0 when the prediction does not use the run's decoder) and the
        ``primitive`` asked (None: none); with none asked (nor each motion's label), the ``posterior``
        (n, P) over ``primitives`` (their names), each sample's ``top_primitive`` and
        ``posterior_accuracy`` (:func:`~primspace.predict.primitives.top1_accuracy` against ``labels``).
        Online (no forecast's ``prior`` in ``details``): ``details`` with the summary and the primitive."""
        if "prior" not in details:
            summary = self.summary()
            return {**details, "prior": summary, "primitive": summary["primitive"], "model_share": self.online_share()}
        summary = details["prior"]
        out = {"prior": summary, "primitive": summary["primitive"], "model_share": details.get("model_share")}
        if summary["primitive"] is not None or self.given:
            return out
        names = list(summary["primitives"]["names"])
        posterior = np.asarray(details["posterior"], dtype=np.float64)
        return {
            **out,
            "primitives": names,
            "posterior": posterior.tolist(),
            "top_primitive": [names[k] for k in posterior.argmax(axis=1)],
            "posterior_accuracy": top1_accuracy(posterior, summary["primitives"]["labels"], labels),
        }
