"""The mixture over the fitted codes as a predictor, offline and online.

:class:`MixturePredictor` predicts the rest of a motion without a gradient step: the
posterior over decoded candidates built from the run's fitted codes
(:class:`~primspace.predict.candidates.CodeMixture`, whose docstring gives the maths),
its posterior mean or its ensemble conditioned on the observed entries, whichever the
leave-one-out prediction of the fitted demonstrations prefers, then the continuity
correction (:func:`~primspace.predict.candidates.continuity_correction`).

**Online** (:meth:`MixturePredictor.predict_online`, the one loop of :mod:`~primspace.predict.stream`): after step ``t`` the prediction is a
function of the prefix ``1..t`` alone, so following a motion online gives exactly the
offline prediction of the same prefix *without the ensemble conditioning*
(``condition=False``; tested), and an arriving step costs one update of the squared
distances to the decoded candidates (``c x J`` numbers per motion), the posterior weights
and the weighted mean. Predictive coding in the paper's words, "Predicted information is
compared with the real one and internal state is corrected based on the error" (paper,
*Background*): the internal state is the posterior over the candidates, corrected by each
step's error. The conditioning is left out online because its leave-one-out choice costs
seconds per prefix length; the offline default conditions, so online and offline differ
by that choice (docs/predict.md, *Online*).

What does not depend on the new motion is prepared in :meth:`MixturePredictor.fit` and on
first use of a rule, from the fitted demonstrations only: the candidates (decoded once)
and ``σ²`` (and ``r``) per observation rule or prefix length.
"""

from __future__ import annotations

import numpy as np

from primspace.predict.base import Forecast, Predictor, observation_rule, observed_mask
from primspace.predict.candidates import CONDITION_GRID, CodeMixture, continuity_correction
from primspace.predict.metrics import check_lengths, check_motor, valid_mask
from primspace.predict.primitives import primitives_from_labels
from primspace.predict.stream import Stream
from primspace.train.api import reconstruct
from primspace.train.observe import NOTHING, Observation
from primspace.train.run import require_run
from primspace.utils.errors import UserError
from primspace.utils.progress import stage

__all__ = ["MixturePredictor", "MixtureStream", "MIXTURE"]

#: The name of the mixture among the starts of :func:`primspace.predict.predict`.
MIXTURE = "mixture"


class MixturePredictor(Predictor):
    """The posterior over the run's fitted codes (module docstring).

    Parameters
    ----------
    run : TrainedRun or path-like
        The trained run (θ frozen; not changed).
    condition : bool
        Let the leave-one-out choice take the ensemble conditioning
        (:meth:`~primspace.predict.candidates.CodeMixture.conditioned`); False: the
        posterior mean only.
    continuity : bool
        Apply the continuity correction to the prediction.
    candidates : CodeMixture, optional
        The run's decoded candidates, shared with other predictors of the same run (they
        are decoded once); default: built in :meth:`fit`.
    per_label : bool
        Given the primitive: only the candidates built from fitted codes of the sample's own
        label (``labels`` of :meth:`fit` and :meth:`predict`), their posterior mean with the
        noise the label-free posterior mean chose (``condition`` must be False).
    primitive : str or int, optional
        The primitive of every motion, a label of the fitted data (its name, or its place among
        the labels present as for the prior: ``0..P-1``): the mixture restricted to it, as
        ``per_label`` with that label for every motion (``condition`` must be False).
    label_names : list of str, optional
        Names of the fitted data's labels (set by :func:`~primspace.predict.registry.fit_predictor`).
    progress : bool, optional
        Show the decoding and the leave-one-out choices (a spinner in a terminal, a line per
        stage in a log; default: as :func:`primspace.utils.progress.stage`).
    """

    name = MIXTURE

    def __init__(
        self,
        run,
        condition: bool = True,
        continuity: bool = True,
        candidates: CodeMixture | None = None,
        per_label: bool = False,
        progress: bool | None = False,
        primitive=None,
        label_names=None,
    ):
        self.run = run
        self.condition = condition
        self.continuity = continuity
        self.candidates = candidates
        self.per_label = per_label
        self.progress = progress
        self.primitive = primitive
        self.label_names = label_names

    @property
    def needs_labels(self) -> bool:
        """Given each motion's primitive by its label: the samples' labels are read."""
        return bool(self.per_label) and self.primitive is None

    def fit(self, motor, labels=None, lengths=None, frames=None) -> MixturePredictor:
        """Decode the candidates (unless given) and keep the fitted demonstrations ``motor``
        (scaled, the run's fitted samples in its order) for the leave-one-out choices."""
        self.resolve_run()
        motor = check_motor(motor)
        if len(motor) != len(self.run_.latents):
            raise UserError(
                f"the mixture is fitted on the run's {len(self.run_.latents)} fitted demonstrations "
                f"(one per code), got {len(motor)}"
            )
        self.fitted_, self.fitted_lengths_ = motor, check_lengths(lengths, *motor.shape[:2])
        self.valid_ = valid_mask(self.fitted_lengths_, motor.shape[1])
        if self.candidates is not None:
            self.mixture_ = self.candidates
        else:
            with stage(f"mixture: decoding the candidates of {len(motor)} fitted codes", enabled=self.progress):
                self.mixture_ = code_mixture(self.run_)
        self.noises_: dict = {}  # σ² per prefix length, online
        self.primitive_label_ = self.primitive_name_ = None
        if self.per_label or self.primitive is not None:
            if labels is None or self.condition:
                raise UserError("a mixture given the primitive needs the fitted labels and condition=False")
            self.source_labels_ = np.asarray(labels)[self.mixture_.sources]  # (c, 2)
            if self.primitive is not None:
                found = primitives_from_labels(labels, self.label_names)
                k = found.resolve(self.primitive)
                self.primitive_label_, self.primitive_name_ = int(found.labels[k]), found.names[k]
        return self

    def choice(self, rule: Observation) -> dict:
        """The leave-one-out choice (``noise``, ``condition``, ``loo``) for ``rule``: made on first
        use and kept with the candidates, so predictors sharing them share the search."""
        key = (rule.key, bool(self.condition))
        choices = self.mixture_.choices
        if key not in choices:
            observed = rule.masks(self.fitted_lengths_, self.fitted_.shape[1])[0]
            with stage(
                f"mixture: choosing its noise by leave-one-out on {len(self.fitted_)} fitted demonstrations",
                enabled=self.progress,
            ):
                choices[key] = self.mixture_.choose_noise(
                    self.fitted_, observed, self.valid_, conditions=CONDITION_GRID if self.condition else (None,)
                )
        return choices[key]

    def forecast(self, motor, observed, labels=None, lengths=None, frames=None) -> Forecast:
        """Posterior (or conditioned) sequences, the posterior-mode codes and the choice."""
        motor = self.check_query(motor)
        rule = observation_rule(observed, lengths, motor.shape[:2])
        if rule.motor == NOTHING:
            raise UserError(
                "init 'mixture' weighs the fitted codes by the observed joints, and observe='none' "
                "observes none: start by 'zero' or 'random'"
            )
        mask = observed_mask(observed, lengths, motor.shape[:2])
        choice = self.choice(rule)
        seen = np.where(mask[..., None], motor, 0.0)
        if self.primitive_label_ is not None:
            labels = np.full(len(motor), self.primitive_label_)
        if self.per_label or self.primitive_label_ is not None:
            scaled, codes = self._given_labels(seen, mask, labels, choice["noise"])
        else:
            scaled, codes = self.mixture_.predict(seen, mask, noise=choice["noise"], condition=choice["condition"])
        if self.continuity:
            valid = valid_mask(check_lengths(lengths, *motor.shape[:2]), motor.shape[1])
            scaled = continuity_correction(scaled, seen, mask, valid)
        details = {"mixture": {"candidates": int(len(self.mixture_.candidates)), **choice}}
        if self.primitive_name_ is not None:
            details["primitive"] = self.primitive_name_
        return Forecast(scaled, codes.astype(np.float32), details)

    def _given_labels(self, seen: np.ndarray, mask: np.ndarray, labels, noise: float) -> tuple:
        """The posterior mean over the candidates built from the sample's own label only, and its mode."""
        if labels is None or len(labels) != len(seen):
            raise UserError("a mixture given the primitive needs each sample's label")
        labels = np.asarray(labels)[:, None]
        other = ~((self.source_labels_[None, :, 0] == labels) & (self.source_labels_[None, :, 1] == labels))
        w = self.mixture_.weights(seen, mask, noise, exclude=other)
        return np.einsum("nc,ctj->ntj", w, self.mixture_.decoded), self.mixture_.candidates[np.argmax(w, axis=1)]

    def online_noise(self, t: int) -> float:
        """``σ²`` of the posterior mean for a prefix of ``t`` steps (leave-one-out, kept)."""
        if t not in self.noises_:
            observed = Observation.build(int(t)).masks(self.fitted_lengths_, self.fitted_.shape[1])[0]
            self.noises_[t] = self.mixture_.choose_noise(self.fitted_, observed, self.valid_, conditions=(None,))[
                "noise"
            ]
        return self.noises_[t]

    def stream(self, truth, lengths, labels, frames, steps, keep, data=None) -> MixtureStream:
        """The posterior followed a step at a time (module docstring): equal, after step ``t``, to
        ``forecast(motor, Observation.build(t))`` of a predictor with ``condition=False`` (tested).
        ``σ²`` for every prefix length is chosen before the first step arrives; the result's
        ``codes`` are the posterior mode after each step."""
        with stage(f"mixture: choosing its noise for {len(steps)} prefix lengths", enabled=self.progress):
            noises = {int(t): self.online_noise(int(t)) for t in steps}
        return MixtureStream(self, truth, valid_mask(lengths, truth.shape[1]), noises, int(steps[0]))


class MixtureStream(Stream):
    """The squared distances to the decoded candidates, updated as each step arrives (``c x J``
    numbers per motion), the posterior weights and mean, the continuity correction."""

    init = MIXTURE

    def __init__(self, predictor: MixturePredictor, truth, valid, noises: dict, start_step: int):
        self.predictor, self.truth, self.valid, self.noises = predictor, truth, valid, noises
        self.scaler = predictor.run_.scaler
        mixture = predictor.mixture_
        self.by_step = np.ascontiguousarray(mixture.decoded.transpose(1, 0, 2))  # (T, c, J): a step's candidates
        self.squares = (self.by_step**2).sum(axis=2)  # (T, c)
        self.d2 = np.zeros((len(truth), self.by_step.shape[1]))
        for t in range(1, start_step):  # the steps before the first arrival
            self.d2 += self._distances(t)

    def _distances(self, t: int) -> np.ndarray:
        """(n, c): the squared distances of step ``t`` (1-based), valid samples only."""
        x = self.truth[:, t - 1]
        step = (x**2).sum(axis=1)[:, None] + self.squares[t - 1][None] - 2.0 * x @ self.by_step[t - 1].T
        return self.valid[:, t - 1, None] * np.maximum(step, 0.0)

    def arrive(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        self.d2 += self._distances(t)
        energy = self.d2 / (2.0 * self.noises[t])
        w = np.exp(-(energy - energy.min(axis=1, keepdims=True)))
        w /= w.sum(axis=1, keepdims=True)
        mixture = self.predictor.mixture_
        predicted = mixture.posterior_mean(w)
        if self.predictor.continuity:
            observed = (np.arange(self.truth.shape[1]) < t)[None, :] & self.valid
            predicted = continuity_correction(predicted, self.truth, observed, self.valid)
        return predicted, mixture.candidates[np.argmax(w, axis=1)]


def code_mixture(run) -> CodeMixture:
    """The run's :class:`~primspace.predict.candidates.CodeMixture`: its fitted codes' candidates,
    decoded once (scaled motor). Build it once and share it between predictors of one run."""
    parent = require_run(run)
    scaler = parent.scaler

    def decode(codes):
        return scaler.transform(reconstruct(parent, codes.astype(np.float32), images=False, batch_size=1024)[0])

    return CodeMixture(parent.latents, decode)
