"""The predictor chosen by held-out evidence: :class:`SelectedPredictor`, the registry's ``auto``.

No one predictor is the best on every data set and task (docs/predict.md): the prior wins
without labels on the paper preset, the mixture restricted to the primitive given it on LASA.
:class:`SelectedPredictor` chooses for the data it is fitted on and the task it is asked, by
one protocol for every candidate:

1. **Candidates** (:func:`candidates_for`): without a primitive, the mixture over the fitted
   codes, the prior weighted by its posterior over primitives, and the two tuned Gaussian peers
   (:class:`~primspace.predict.gaussian_peers.RawGaussianPeer`,
   :class:`~primspace.predict.gaussian_peers.TunedProMPPeer`: they read only the fitted
   demonstrations, never the run's decoder) one for all; given the primitive (one for every
   motion, or each motion's label), the prior given it, the mixture restricted to it and the
   peers fitted per label. The encoder joins where asked (``candidates=``; it trains a network per fold).
2. **K-fold prediction of the fitted demonstrations** (:data:`SELECTION_FOLDS` folds,
   :func:`~primspace.predict.code_prior.fold_split`, within each label when the fitted data has
   labels): each fold is held out, each candidate fitted on the rest (their codes only: the
   run's decoder is the one trained on all of them, for every candidate alike) and asked to
   predict the held-out demonstrations from the observation rule asked (given their own label
   when the task gives the primitive); a candidate's error is the mean unobserved MSE
   (:func:`~primspace.predict.metrics.unobserved_mse`, scaled units) over the held-out
   demonstrations. A candidate's own choices (the mixture's noise, the prior's noise,
   temperature and blend, the peers' settings by their own K-fold) are made inside each fold on
   that fold's training demonstrations.
3. **The lowest error wins**; it is fitted on every fitted demonstration and predicts.
   ``details["selection"]`` records ``chosen``, every candidate's ``errors`` and ``folds`` (those that
   held a demonstration out: fewer than asked when every label has fewer members, e.g. 2 with two each).

The choice is made once per observation rule and kept: in the predictor, and in the run
folder (:mod:`primspace.predict.selection_cache`, keyed by the fitted data, the task, the
settings and the code version) with the chosen predictor's own settings (and the prior's decoded
draws), so a later call with the same key fits the chosen predictor with those settings, decodes
nothing the first call decoded, and skips every K-fold search.

Online prediction (:meth:`SelectedPredictor.stream`) chooses among the candidates that predict
online: the peers do not.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from primspace.predict.base import Forecast, Predictor, observation_rule
from primspace.predict.code_prior import fold_split
from primspace.predict.encoder import ENCODER, EncoderPredictor
from primspace.predict.gaussian_peers import RawGaussianPeer, TunedProMPPeer
from primspace.predict.metrics import check_labels, check_lengths, check_motor, unobserved_mse
from primspace.predict.mixture import MIXTURE, MixturePredictor
from primspace.predict.primitives import primitives_from_labels
from primspace.predict.prior import PRIOR, PriorPredictor
from primspace.predict.selection_cache import SELECTION_DIR, choice_key, choice_path, load_choice, save_choice
from primspace.train.observe import NOTHING, Observation
from primspace.utils.errors import UserError
from primspace.utils.progress import stage

__all__ = [
    "SelectedPredictor",
    "AUTO",
    "SELECTION_FOLDS",
    "CANDIDATES",
    "DEFAULT_CANDIDATES",
    "RAW_GAUSSIAN",
    "PROMP_TUNED",
    "candidates_for",
]

#: The registry's name of the predictor chosen by held-out evidence.
AUTO = "auto"
#: Folds of the K-fold prediction that scores the candidates: three, so that a choice costs about
#: three fits of each candidate on two thirds of the fitted demonstrations (docs/predict.md).
SELECTION_FOLDS = 3
#: The registry's names of the tuned Gaussian peers (candidates that never read the run's decoder).
RAW_GAUSSIAN, PROMP_TUNED = RawGaussianPeer.name, TunedProMPPeer.name
#: The classes of the peer candidates, by name.
PEERS = {RAW_GAUSSIAN: RawGaussianPeer, PROMP_TUNED: TunedProMPPeer}
#: Every candidate the selection knows.
CANDIDATES = (MIXTURE, PRIOR, RAW_GAUSSIAN, PROMP_TUNED, ENCODER)
#: The candidates when none are asked: all but the encoder (it trains a network per fold).
DEFAULT_CANDIDATES = (MIXTURE, PRIOR, RAW_GAUSSIAN, PROMP_TUNED)


def candidates_for(told: bool, labelled: bool, primitives: str = "labels", asked=None) -> tuple[str, ...]:
    """The candidates of a task: ``told`` (the primitive given) or not, on fitted data that is
    ``labelled`` or not, with the prior's ``primitives`` (labels or clusters); ``asked``: the
    candidates wanted (default: :data:`DEFAULT_CANDIDATES`), those that do not apply left out: the
    peers and the mixture given the primitive need the fitted data's labels as the primitives."""
    asked = DEFAULT_CANDIDATES if asked is None else tuple(asked)
    unknown = [name for name in asked if name not in CANDIDATES]
    if unknown or not asked:
        raise UserError(f"candidates must be some of {', '.join(CANDIDATES)}, got {list(asked)!r}")
    prior = labelled or primitives == "clusters"
    by_label = not told or (labelled and primitives == "labels")
    applies = {
        MIXTURE: by_label,
        PRIOR: prior,
        RAW_GAUSSIAN: by_label,
        PROMP_TUNED: by_label,
        ENCODER: prior and (not told or primitives == "labels"),
    }
    chosen = tuple(name for name in asked if applies[name])
    if not chosen:
        raise UserError(f"none of the candidates {', '.join(asked)} applies to the fitted data and the task")
    return chosen


class SelectedPredictor(Predictor):
    """The candidate with the lowest K-fold error on the fitted demonstrations (module docstring).

    Parameters
    ----------
    run : TrainedRun or path-like
    primitive : str or int, optional
        The primitive of every motion (as for the prior: a name or an id of its primitives).
    given : bool
        Each motion's primitive is its label (``labels`` of :meth:`predict`).
    primitives : {"labels", "clusters"}
        The prior's primitives.
    n_clusters : int, optional
    label_names : list of str, optional
        Names of the fitted data's labels (set by :func:`~primspace.predict.registry.fit_predictor`).
    candidates : tuple of str, optional
        Those to choose among (default: mixture, prior and the two tuned Gaussian peers; :func:`candidates_for`).
    folds : int
        Folds of the K-fold prediction (at least 2).
    prior_samples : int, optional
        Draws per primitive of the prior (default: the prior's).
    peer_settings : dict, optional
        Keywords of the peer candidates by name (e.g. ``{"promp_tuned": {"n_basis": 8}}``; default:
        their own, as the prediction grid runs them).
    condition : bool
        The mixture without a primitive may take its ensemble conditioning.
    continuity : bool
    random_state : int, optional
        Seed of the folds and the candidates (default: the run's seed).
    reuse : bool
        Keep the choice in the run folder and read it from there (:mod:`~primspace.predict.selection_cache`).
    progress : bool, optional
    """

    name = AUTO

    def __init__(
        self,
        run,
        primitive=None,
        given: bool = False,
        primitives: str = "labels",
        n_clusters: int | None = None,
        label_names=None,
        candidates=None,
        folds: int = SELECTION_FOLDS,
        prior_samples: int | None = None,
        peer_settings: dict | None = None,
        condition: bool = True,
        continuity: bool = True,
        random_state: int | None = None,
        reuse: bool = True,
        progress: bool | None = False,
    ):
        self.run = run
        self.primitive = primitive
        self.given = given
        self.primitives = primitives
        self.n_clusters = n_clusters
        self.label_names = label_names
        self.candidates = candidates
        self.folds = folds
        self.prior_samples = prior_samples
        self.peer_settings = peer_settings
        self.condition = condition
        self.continuity = continuity
        self.random_state = random_state
        self.reuse = reuse
        self.progress = progress

    @property
    def told(self) -> bool:
        """Whether the task gives the primitive (one for every motion, or each motion's label)."""
        return self.primitive is not None or bool(self.given)

    @property
    def needs_labels(self) -> bool:
        return bool(self.given) and self.primitive is None

    def fit(self, motor, labels=None, lengths=None, frames=None) -> SelectedPredictor:
        """Keep the fitted demonstrations (scaled, the run's order) and what applies to them; the
        candidates are scored and the chosen one fitted on first use of an observation rule."""
        run = self.resolve_run()
        if isinstance(self.folds, bool) or not isinstance(self.folds, (int, np.integer)) or self.folds < 2:
            raise UserError(f"folds must be a whole number >= 2, got {self.folds!r}")
        motor = check_motor(motor)
        if len(motor) != len(run.latents):
            raise UserError(f"the selection is fitted on the run's {len(run.latents)} fitted demonstrations")
        self.fitted_ = (motor, check_labels(labels, len(motor)), check_lengths(lengths, *motor.shape[:2]))
        fitted_labels = self.fitted_[1]
        labelled = fitted_labels is not None and bool((fitted_labels >= 0).any())
        self.candidates_ = candidates_for(self.told, labelled, self.primitives, self.candidates)
        unknown = sorted(set(self.peer_settings or {}) - set(PEERS))
        if unknown:
            raise UserError(f"peer_settings takes {', '.join(PEERS)}, got {', '.join(map(repr, unknown))}")
        if self.primitive is not None and self.primitives == "labels":  # a name the run lacks: one line, at once
            primitives_from_labels(fitted_labels, self.label_names).resolve(self.primitive)
        self.seed_ = int(run.train_config.seed) if self.random_state is None else int(self.random_state)
        self.selections_: dict = {}
        self.chosen_: dict = {}
        self.predictor_: Predictor | None = None
        self.online_selection_: dict | None = None  # the choice among the online candidates (``stream``)
        return self

    # -- the candidates ----------------------------------------------------------------------
    def build(self, name: str, run, scoring: bool = False) -> Predictor:
        """Candidate ``name`` on ``run`` for this task; ``scoring``: as the K-fold asks it (given
        each held-out demonstration's own label when the task gives the primitive)."""
        one = None if scoring else self.primitive
        by_label = self.told and one is None
        if name in PEERS:  # one per label when told (the primitive's label for every motion, or each one's)
            own = dict((self.peer_settings or {}).get(name, {}))
            return PEERS[name](**{"per_label": self.told, "random_state": self.seed_, **own})
        common = dict(continuity=self.continuity, progress=False)
        if name == MIXTURE:
            condition = self.condition and not self.told
            return MixturePredictor(
                run, condition=condition, per_label=by_label, primitive=one, label_names=self.label_names, **common
            )
        extra = {} if self.prior_samples is None else {"n_samples": int(self.prior_samples)}
        prior = dict(
            primitives=self.primitives, n_clusters=self.n_clusters, label_names=self.label_names, **extra, **common
        )
        if name == PRIOR:
            return PriorPredictor(run, primitive=one, given=by_label, random_state=self.random_state, **prior)
        return EncoderPredictor(
            run, prior=PriorPredictor(run, random_state=self.random_state, **prior), given=self.told, **common
        )

    def _labels_for(self, name: str, labels, n: int):
        """The labels a candidate reads for ``n`` motions: the primitive's label for every motion
        (the encoder and the peers, given one primitive for all), else ``labels``."""
        if name in (ENCODER, *PEERS) and self.primitive is not None:
            found = primitives_from_labels(self.fitted_[1], self.label_names)
            return np.full(n, int(found.labels[found.resolve(self.primitive)]))
        return labels

    # -- the K-fold score ----------------------------------------------------------------------
    def fold_of(self) -> np.ndarray:
        """The fold of each fitted demonstration (-1: never held out): within each label with two
        members or more when the fitted data has labels, else over all of them."""
        motor, labels, _ = self.fitted_
        if labels is None or not (labels >= 0).any():
            groups = [np.arange(len(motor))]
        else:
            groups = [np.flatnonzero(labels == v) for v in np.unique(labels[labels >= 0])]
            groups = [g for g in groups if len(g) > 1]
        return fold_split(groups, len(motor), [self.seed_, 53], int(self.folds))

    def score(self, name: str, rule: Observation) -> float:
        """The mean unobserved MSE of candidate ``name`` over the held-out fitted demonstrations
        (each predicted by the candidate fitted on the other folds; NaN when none is held out)."""
        motor, labels, lengths = self.fitted_
        fold_of = self.fold_of()
        errors = np.full(len(motor), np.nan)
        observed = rule.masks(lengths, motor.shape[1])[0]
        for f in range(int(self.folds)):
            held, keep = np.flatnonzero(fold_of == f), np.flatnonzero(fold_of != f)
            if not held.size:
                continue
            run = dataclasses.replace(
                self.run_,
                latents=self.run_.latents[keep],
                initial_latents=self.run_.initial_latents[keep],
                indices=self.run_.indices[keep],
            )
            candidate = self.build(name, run, scoring=True).fit(motor[keep], _rows(labels, keep), lengths[keep])
            asked = _rows(labels, held) if self.told else None
            predicted = candidate.predict(motor[held], rule, labels=asked, lengths=lengths[held])
            errors[held] = unobserved_mse(predicted, motor[held], observed[held], lengths[held])
        errors = errors[np.isfinite(errors)]
        return float(errors.mean()) if errors.size else float("nan")

    def task(self, rule: Observation) -> dict:
        """The task of ``rule`` as recorded and keyed."""
        return {
            "observe": rule.to_dict(),
            "primitive": None if self.primitive is None else str(self.primitive),
            "given": bool(self.given),
            "primitives": self.primitives,
            "n_clusters": self.n_clusters,
        }

    def settings(self) -> dict:
        """The settings a choice depends on, as recorded and keyed."""
        names = ("folds", "prior_samples", "peer_settings", "condition", "continuity")
        return {"candidates": list(self.candidates_), "seed": self.seed_, **{n: getattr(self, n) for n in names}}

    # -- the choice ------------------------------------------------------------------------------
    def select(self, rule: Observation) -> dict:
        """The selection for ``rule`` (``chosen``, ``errors``, ``folds``, ``reused``): read from the run
        folder when kept there with this key, else the candidates scored (and the choice kept)."""
        if rule.key in self.selections_:
            return self.selections_[rule.key]
        if rule.motor == NOTHING:
            raise UserError(
                "the predictor is chosen by the observed joints, and observe='none' observes none: "
                "give a start of gradient inference (init 'zero' or 'random')"
            )
        path, key, kept = self._kept(rule)
        if kept is not None:
            selection = {**kept["selection"], "reused": str(path)}
            self.chosen_[rule.key] = self._refit(selection["chosen"], rule, kept.get("settings") or {})
        else:
            selection = self._scored(rule)
            chosen = self._refit(selection["chosen"], rule, {})
            self.chosen_[rule.key] = chosen
            record = {"selection": selection, "settings": frozen_settings(chosen, rule), "task": self.task(rule)}
            kept_at = None if path is None or not save_choice(path, key, record) else str(path)
            selection = {**selection, "reused": None, "kept": kept_at}
        self.selections_[rule.key] = selection
        return selection

    def _kept(self, rule: Observation) -> tuple:
        """(the file of this choice, its key, the choice kept there or None); (None, None, None)
        when nothing is kept (``reuse`` off, or a run held in memory only)."""
        run_dir = getattr(self.run_, "run_dir", None)
        if not self.reuse or run_dir is None:
            return None, None, None
        key = choice_key(self.fitted_, self.run_.latents, self.task(rule), self.settings())
        path = choice_path(run_dir, key)
        return path, key, load_choice(path, key)

    def _scored(self, rule: Observation) -> dict:
        """Every candidate's K-fold error and the lowest (the first of them alone: no score)."""
        if len(self.candidates_) == 1:
            return {"chosen": self.candidates_[0], "errors": {self.candidates_[0]: None}, "folds": 0}
        errors = {}
        for name in self.candidates_:
            with stage(f"auto: {name}'s {self.folds}-fold error on the fitted demonstrations", enabled=self.progress):
                errors[name] = self.score(name, rule)
        finite = {name: e for name, e in errors.items() if np.isfinite(e)}
        chosen = min(finite, key=finite.get) if finite else self.candidates_[0]
        clean = {name: (float(e) if np.isfinite(e) else None) for name, e in errors.items()}
        fold_of = self.fold_of()
        used = int(np.unique(fold_of[fold_of >= 0]).size)  # fewer than asked when every label has fewer members
        return {"chosen": chosen, "errors": clean, "folds": used if finite else 0}

    def _refit(self, name: str, rule: Observation, settings: dict) -> Predictor:
        """Candidate ``name`` fitted on every fitted demonstration, with its kept ``settings``."""
        if name not in self.candidates_:
            raise UserError(f"the kept choice {name!r} is not a candidate of this task ({', '.join(self.candidates_)})")
        predictor = self.build(name, self.run_)
        if name == PRIOR and settings:
            predictor.set_params(**{k: settings[k] for k in ("family", "noise", "temperature", "blend")})
        if name in PEERS and settings:
            predictor.set_params(**settings["setting"])
        run_dir = getattr(self.run_, "run_dir", None)
        if "draws_dir" in predictor.get_params() and self.reuse and run_dir is not None:  # kept with the choice
            predictor.set_params(draws_dir=Path(run_dir) / SELECTION_DIR)
        predictor.fit(*self.fitted_)
        if name == MIXTURE and settings:
            predictor.mixture_.choices[(rule.key, bool(predictor.condition))] = dict(settings["choice"])
        return predictor

    # -- predicting ------------------------------------------------------------------------------
    def chosen(self, rule: Observation) -> Predictor:
        """The fitted predictor chosen for ``rule`` (chosen on first use)."""
        self.select(rule)
        return self.chosen_[rule.key]

    def forecast(self, motor, observed, labels=None, lengths=None, frames=None, **options) -> Forecast:
        """The chosen predictor's forecast, ``details["selection"]`` added."""
        motor = self.check_query(motor)
        rule = observation_rule(observed, lengths, motor.shape[:2])
        predictor = self.chosen(rule)
        self.predictor_ = predictor
        asked = self._labels_for(predictor.name, labels, len(motor))
        forecast = predictor.forecast(motor, observed, asked, lengths, frames, **options)
        forecast.details = {**forecast.details, "selection": self.selections_[rule.key]}
        return forecast

    def stream(self, truth, lengths, labels, frames, steps, keep, data=None):
        """The chosen predictor's stream, chosen for a prefix of ``keep`` steps among the candidates that
        predict online (the peers do not)."""
        online = [name for name in self.candidates_ if name not in PEERS]
        if not online:
            raise UserError(f"none of the candidates {', '.join(self.candidates_)} predicts online")
        selector = self
        if len(online) < len(self.candidates_):
            params = {**self.get_params(deep=False), "candidates": tuple(online)}
            selector = SelectedPredictor(**params).fit(*self.fitted_)
        rule = Observation.build(int(keep))
        predictor = selector.chosen(rule)
        self.online_selection_ = selector.selections_[rule.key]
        self.predictor_ = predictor
        asked = self._labels_for(predictor.name, labels, len(truth))
        return predictor.stream(truth, lengths, asked, frames, steps, keep, data=data)

    def online_forecast(self, result, truth, observed, lengths, seen: int) -> Forecast:
        return self.predictor_.online_forecast(result, truth, observed, lengths, seen)

    def describe(self, details: dict, labels=None) -> dict:
        """The chosen predictor's record, with ``selection``."""
        selection = details.get("selection")
        out = self.predictor_.describe({k: v for k, v in details.items() if k != "selection"}, labels)
        if self.primitive is not None and self.predictor_.name in PEERS:  # as the mixture and the prior record it
            found = primitives_from_labels(self.fitted_[1], self.label_names)
            out = {**out, "primitive": found.names[found.resolve(self.primitive)]}
        if selection is None and self.online_selection_ is not None:
            selection = self.online_selection_
        elif selection is None and len(self.selections_) == 1:
            selection = next(iter(self.selections_.values()))
        return {**out, "selection": selection}


def _rows(values, rows):
    """``values[rows]``, or None for None."""
    return None if values is None else values[rows]


def frozen_settings(predictor: Predictor, rule: Observation) -> dict:
    """What the fitted ``predictor`` chose for ``rule`` that a refit with the same data would choose
    again (kept with the choice, read by the refit instead of searching): the mixture's noise
    choice; the prior's family, noise, temperature and blend; a peer's setting; nothing for the encoder."""
    if predictor.name == MIXTURE:
        return {"choice": predictor.choice(rule)}
    if predictor.name == PRIOR:
        choice = predictor.choice(rule)
        told = predictor.told_primitive
        noise, blend = (choice["noise_given"], choice["blend_given"]) if told else (choice["noise"], choice["blend"])
        family = predictor.prior_choice_["family"]
        return {
            "family": [family[0], family[1].item() if isinstance(family[1], np.generic) else family[1]],
            "noise": float(noise),
            "temperature": float(choice["temperature"]),
            "blend": float(blend),
        }
    if predictor.name in PEERS:
        return {"setting": dict(predictor.choice(rule))}
    return {}
