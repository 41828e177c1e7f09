"""An amortised encoder from the observed steps to the code, trained on the decoder's own samples.

:class:`~primspace.predict.prior.PriorPredictor` conditions each primitive's prior on the
observed steps at prediction time. :class:`EncoderPredictor` learns that map once instead
(amortised inference): a small network ``e(x_o, m[, k]) -> z`` from a masked prefix to the
code, trained on motions the decoder itself makes, θ frozen:

1. **Training set**: ``n_train`` codes drawn from the fitted priors (each primitive's
   :class:`~primspace.predict.code_prior.GaussianCode`, the primitives in proportion to
   the fitted codes they hold), decoded once (scaled units).
2. **Inputs**: each draw with a random observed prefix (a fresh one per minibatch, its
   number of steps uniform in ``1..T``): the motion with the unobserved steps zeroed
   (``T·J``), the observed-step mask (``T``), and, when the primitive is given, its
   one-hot (``P``); the motion plus, by default, the reconstruction residual ``x - d(θ, z)``
   of a fitted demonstration of its primitive (``residuals``), since observed motions are
   not the decoder's own. **Output**: the code (standardised per entry over the training codes).
3. **Network and training**: an MLP (two hidden layers of ``hidden`` units, SiLU), Adam
   with a cosine learning rate over ``steps`` minibatches, the squared error of the
   standardised code; on the CPU with ``threads`` threads, seeded: the same seed gives
   the same numbers.
4. **Prediction**: one forward pass; optionally ``refine`` MAP steps through the decoder
   under the primitive's prior (:func:`~primspace.predict.prior_map.map_refine`); the codes
   decoded, then the continuity correction
   (:func:`~primspace.predict.candidates.continuity_correction`).

With a squared error the encoder learns the posterior mean of the code given the prefix
under the priors (given the primitive, or under their mixture without it); a decoded mean
code is not the mean decoded motion, which the prior's Kalman update predicts, so the two
differ most where a prefix leaves the motion uncertain.

Online (:meth:`EncoderPredictor.predict_online`): an MLP over the whole masked prefix,
so each arriving step is one forward pass of the prefix seen so far and one decode; the
prediction after step ``t`` equals :meth:`~EncoderPredictor.forecast` of that prefix.
"""

from __future__ import annotations

import copy
import math
import time

import numpy as np
import torch
from torch import nn

from primspace.predict.base import Forecast, Predictor, observation_rule, observed_mask
from primspace.predict.candidates import continuity_correction
from primspace.predict.metrics import check_labels, check_lengths, check_motor, valid_mask
from primspace.predict.prior import PriorPredictor
from primspace.predict.prior_map import map_refine, prior_terms
from primspace.predict.stream import Stream
from primspace.train.api import reconstruct
from primspace.train.config import thread_limit
from primspace.train.observe import NOTHING, Observation
from primspace.utils.errors import UserError
from primspace.utils.progress import progress_bar, stage

__all__ = ["EncoderPredictor", "EncoderStream", "ENCODER", "MaskedEncoder"]

#: The name of the encoder predictor (the ``init`` of its :class:`OnlineResult`).
ENCODER = "encoder"


class MaskedEncoder(nn.Module):
    """The MLP ``(masked motion, mask[, one-hot]) -> standardised code``."""

    def __init__(self, inputs: int, hidden: int, outputs: int):
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(inputs, hidden),
            nn.SiLU(),
            nn.Linear(hidden, hidden),
            nn.SiLU(),
            nn.Linear(hidden, outputs),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class Residuals:
    """The fitted demonstrations' reconstruction residuals ``x - d(θ, z)`` (scaled units, zero on
    padding), drawn for the training motions from the fitted demonstrations of their primitive."""

    def __init__(self, residuals: np.ndarray, assignment: np.ndarray, count: int):
        keep = np.flatnonzero(assignment >= 0)
        self.values = torch.from_numpy(residuals[keep].astype(np.float32))
        groups = assignment[keep]
        self.order = np.argsort(groups, kind="stable")
        self.sizes = np.bincount(groups, minlength=count)
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)[:-1]])

    def draw(self, ids: np.ndarray, rng: np.random.Generator) -> torch.Tensor:
        """A residual (b, T, J) of a fitted demonstration of each primitive ``ids`` (b,)."""
        within = np.floor(rng.random(len(ids)) * np.maximum(self.sizes[ids], 1)).astype(np.int64)
        return self.values[self.order[np.minimum(self.offsets[ids] + within, len(self.order) - 1)]]


def encoder_inputs(seen: torch.Tensor, mask: torch.Tensor, onehot: torch.Tensor | None) -> torch.Tensor:
    """The encoder's input rows: ``seen`` (n, T, J) with the unobserved steps zeroed, ``mask``
    (n, T) float, and the primitive's one-hot (n, P) when given."""
    parts = [(seen * mask[..., None]).reshape(len(seen), -1), mask]
    if onehot is not None:
        parts.append(onehot)
    return torch.cat(parts, dim=1)


class EncoderPredictor(Predictor):
    """An encoder from the observed steps to the code, trained on decoded prior draws (module docstring).

    Parameters
    ----------
    run : TrainedRun or path-like
        The trained run (θ frozen; not changed).
    prior : PriorPredictor, optional
        The priors to draw the training codes from, fitted or not (a copy is fitted on
        :meth:`fit`'s arguments when not); default: ``PriorPredictor(run)`` fitted there.
    given : bool
        The encoder reads each motion's primitive (its label, ``labels`` of :meth:`predict`).
    n_train : int
        Codes drawn and decoded for training.
    steps : int
        Adam steps (minibatches).
    hidden : int
        Units of each of the two hidden layers.
    batch_size : int
    lr : float
        Adam's initial learning rate (cosine to zero over ``steps``).
    residuals : float
        Add to each training motion the reconstruction residual of a fitted demonstration of
        its primitive (drawn afresh per minibatch) times ``residuals``, so that the encoder
        reads motions as they are observed, not only as the decoder makes them (0: the
        decoder's samples as they are).
    refine : int
        MAP steps through the decoder after the encoder (0: none;
        :func:`~primspace.predict.prior_map.map_refine`): Adam on the code, under the prior of
        each motion's primitive (given, or the one whose prior gives the encoded code the largest
        density) with the prior predictor's noise ``r`` for the observation (chosen by its K-fold
        prediction on first use; a mask needs prefixes of one length).
    refine_lr : float
        Adam's learning rate of the refinement.
    continuity : bool
    label_names : list of str, optional
        Names of the labels, for the default prior.
    threads : int, optional
        CPU threads while training and encoding (None: as they are).
    random_state : int, optional
        Seed of the draws, the prefixes and the network (default: the run's seed).
    progress : bool, optional
    """

    name = ENCODER

    def __init__(
        self,
        run,
        prior=None,
        given: bool = False,
        n_train: int = 8192,
        steps: int = 3000,
        hidden: int = 256,
        batch_size: int = 256,
        lr: float = 1e-3,
        residuals: float = 1.0,
        refine: int = 0,
        refine_lr: float = 0.01,
        continuity: bool = True,
        label_names=None,
        threads: int | None = 1,
        random_state: int | None = None,
        progress: bool | None = False,
    ):
        self.run = run
        self.prior = prior
        self.given = given
        self.n_train = n_train
        self.steps = steps
        self.hidden = hidden
        self.batch_size = batch_size
        self.lr = lr
        self.residuals = residuals
        self.refine = refine
        self.refine_lr = refine_lr
        self.continuity = continuity
        self.label_names = label_names
        self.threads = threads
        self.random_state = random_state
        self.progress = progress

    @property
    def needs_labels(self) -> bool:
        """Given each motion's primitive by its label."""
        return bool(self.given)

    # -- fit ------------------------------------------------------------------------------
    def fit(self, motor, labels=None, lengths=None, frames=None) -> EncoderPredictor:
        """Fit the prior (unless fitted), draw and decode its training set, train the encoder."""
        run = self.resolve_run()
        self._check_params()
        self.seed_ = int(run.train_config.seed) if self.random_state is None else int(self.random_state)
        self.prior_ = self._fitted_prior(motor, labels, lengths)
        self.primitives_ = self.prior_.primitives_
        self.shape_ = (int(run.model_config.length), int(run.model_config.n_joints))
        start = time.perf_counter()
        with thread_limit(self.threads):
            with stage(f"encoder: drawing and decoding {self.n_train} codes", enabled=self.progress):
                scaled, ids, codes = self._training_set()
                self.residuals_ = self._residuals(motor, lengths) if self.residuals > 0 else None
            self.code_mean_ = codes.mean(axis=0)
            self.code_scale_ = codes.std(axis=0) + 1e-6
            self.network_, self.losses_ = self._train(scaled, ids, (codes - self.code_mean_) / self.code_scale_)
        self.fit_seconds_ = time.perf_counter() - start
        return self

    def _check_params(self) -> None:
        for name, least in (("n_train", 2), ("steps", 1), ("hidden", 1), ("batch_size", 1), ("refine", 0)):
            value = getattr(self, name)
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < least:
                raise UserError(f"{name} must be a whole number >= {least}, got {value!r}")
        for name in ("lr", "refine_lr"):
            lr = getattr(self, name)
            if isinstance(lr, bool) or not isinstance(lr, (int, float)) or not math.isfinite(lr) or lr <= 0:
                raise UserError(f"{name} must be a finite number > 0, got {lr!r}")
        res = self.residuals
        if isinstance(res, bool) or not isinstance(res, (int, float)) or not math.isfinite(res) or res < 0:
            raise UserError(f"residuals must be a finite number >= 0, got {res!r}")
        if self.prior is not None and not isinstance(self.prior, PriorPredictor):
            raise UserError(f"prior must be a PriorPredictor or None, got {type(self.prior).__name__}")

    def _fitted_prior(self, motor, labels, lengths) -> PriorPredictor:
        """The prior given (fitted, or a copy fitted here) or a default one, on this run."""
        if self.prior is None:
            prior = PriorPredictor(self.run_, label_names=self.label_names, random_state=self.random_state)
            return prior.fit(motor, labels, lengths)
        if hasattr(self.prior, "gaussians_"):
            prior = self.prior
        else:
            prior = copy.copy(self.prior).fit(motor, labels, lengths)
        if prior.gaussians_[0].mean.shape[0] != self.run_.model_config.code_size:
            raise UserError(
                f"the prior's codes have {prior.gaussians_[0].mean.shape[0]} entries, "
                f"the run's {self.run_.model_config.code_size}: fit the prior on the same run"
            )
        return prior

    def _training_set(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``n_train`` codes drawn from the priors (primitives in proportion), decoded:
        scaled motions (N, T, J) float32, primitive ids (N,), codes (N, q) float64."""
        rng = np.random.default_rng([self.seed_, 39, 5])
        shares = np.asarray(self.prior_.shares_, dtype=np.float64)
        counts = np.bincount(
            rng.choice(len(shares), size=int(self.n_train), p=shares / shares.sum()), minlength=len(shares)
        )
        ids = np.repeat(np.arange(len(shares)), counts)
        codes = np.concatenate([g.sample(c, rng) for g, c in zip(self.prior_.gaussians_, counts)])
        scaled = self._decode(codes.astype(np.float32)).astype(np.float32)
        return scaled, ids, codes

    def _decode(self, codes: np.ndarray) -> np.ndarray:
        """Codes (n, q) decoded, scaled units (n, T, J) float64."""
        decoded = reconstruct(self.run_, codes.astype(np.float32), images=False, batch_size=1024)[0]
        return self.run_.scaler.transform(decoded).astype(np.float64)

    def _residuals(self, motor, lengths) -> Residuals:
        """The fitted demonstrations' residuals (their codes, the run's, decoded)."""
        motor = check_motor(motor)
        valid = valid_mask(check_lengths(lengths, *motor.shape[:2]), motor.shape[1])
        rest = (motor - self._decode(np.asarray(self.run_.latents, dtype=np.float32))) * valid[..., None]
        rest *= float(self.residuals)
        return Residuals(rest, self.primitives_.assignment, self.primitives_.count)

    def _onehot(self, ids) -> torch.Tensor | None:
        if not self.given:
            return None
        return torch.from_numpy(np.eye(self.primitives_.count, dtype=np.float32)[np.asarray(ids)])

    def _train(self, scaled: np.ndarray, ids: np.ndarray, targets: np.ndarray) -> tuple[MaskedEncoder, np.ndarray]:
        """Adam on the squared error of the standardised code, a fresh random prefix per draw and
        minibatch; returns the network (eval mode) and the loss of each step."""
        length, joints = self.shape_
        inputs = length * joints + length + (self.primitives_.count if self.given else 0)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(self.seed_)
            network = MaskedEncoder(inputs, int(self.hidden), targets.shape[1])
        rng = np.random.default_rng([self.seed_, 39, 6])
        motions, codes = torch.from_numpy(scaled), torch.from_numpy(targets.astype(np.float32))
        onehot = self._onehot(ids)
        optimiser = torch.optim.Adam(network.parameters(), lr=float(self.lr))
        total = int(self.steps)
        schedule = torch.optim.lr_scheduler.LambdaLR(optimiser, lambda s: 0.5 * (1.0 + math.cos(math.pi * s / total)))
        arange = torch.arange(length)
        losses = np.empty(total)
        network.train()
        with progress_bar(total, "encoder", enabled=self.progress) as advance:
            for s in range(total):
                take = torch.from_numpy(rng.integers(0, len(motions), int(self.batch_size)))
                seen = torch.from_numpy(rng.integers(1, length + 1, int(self.batch_size)))
                mask = (arange[None, :] < seen[:, None]).float()
                seen = motions[take]
                if self.residuals_ is not None:
                    seen = seen + self.residuals_.draw(ids[take.numpy()], rng)
                x = encoder_inputs(seen, mask, None if onehot is None else onehot[take])
                loss = torch.mean((network(x) - codes[take]) ** 2)
                optimiser.zero_grad(set_to_none=True)
                loss.backward()
                optimiser.step()
                schedule.step()
                losses[s] = float(loss.detach())
                advance()
        return network.eval().requires_grad_(False), losses

    # -- prediction -----------------------------------------------------------------------
    def encode(self, motor, observed, labels=None, lengths=None) -> np.ndarray:
        """The codes (n, q) float32 the encoder reads from the observed prefix of each motion."""
        motor, mask, ids = self._arguments(motor, observed, labels, lengths)
        return self._encode(motor, mask, ids)

    def _encode(self, motor: np.ndarray, mask: np.ndarray, ids) -> np.ndarray:
        with thread_limit(self.threads), torch.no_grad():
            x = encoder_inputs(
                torch.from_numpy(motor.astype(np.float32)),
                torch.from_numpy(mask.astype(np.float32)),
                None if ids is None else self._onehot(ids),
            )
            out = self.network_(x).numpy().astype(np.float64)
        return (out * self.code_scale_ + self.code_mean_).astype(np.float32)

    def _arguments(self, motor, observed, labels, lengths):
        """``motor`` checked against the run's T and J, the observed mask (a prefix of each
        sample's valid steps), and each motion's primitive when given (None otherwise)."""
        motor = check_motor(motor)
        n, steps, joints = motor.shape
        if (steps, joints) != self.shape_:
            raise UserError(f"motor must have the run's (T, J) = {self.shape_}, got {(steps, joints)}")
        if isinstance(observed, Observation) and observed.motor == NOTHING:
            raise UserError("the encoder reads the observed joints, and observe='none' observes none")
        mask = observed_mask(observed, lengths, (n, steps))
        if not np.array_equal(mask, np.arange(steps)[None, :] < mask.sum(axis=1, keepdims=True)):
            raise UserError("observed must be a prefix of each sample's steps")
        return motor, mask, self._given_ids(labels, n)

    def _given_ids(self, labels, n: int):
        if not self.given:
            return None
        labels = check_labels(labels, n)
        if labels is None:
            raise UserError("an encoder given the primitive reads each motion's label: pass labels")
        return self.primitives_.for_labels(labels)

    def predict_prefix(self, motor, mask, ids, valid, rule) -> tuple[np.ndarray, np.ndarray]:
        """Encode (and refine), decode and correct: motions (n, T, J) scaled and their codes;
        ``rule`` the observation whose noise ``r`` the refinement reads (None: no refinement)."""
        codes = self._encode(motor, mask, ids)
        if self.refine > 0:
            codes = self._refined(codes, motor, mask, ids, rule)
        with thread_limit(self.threads):
            out = self._decode(codes)
        if self.continuity:
            out = continuity_correction(out, np.where(mask[..., None], motor, 0.0), mask, valid)
        return out, codes

    def _refined(self, codes, motor, mask, ids, rule) -> np.ndarray:
        """``refine`` MAP steps through the decoder (:func:`~primspace.predict.prior_map.map_refine`)
        under the prior of each motion's primitive: the one given, else the primitive whose prior
        gives the encoder's code the largest density; ``r`` the prior predictor's for ``rule``."""
        if ids is None:
            density = np.stack([g.log_likelihood(codes.astype(np.float64)) for g in self.prior_.gaussians_], axis=1)
            ids = density.argmax(axis=1)
        choice = self.prior_.choice(rule)
        r = choice["noise_given"] if self.given else choice["noise"]
        means, precisions = prior_terms(self.prior_.gaussians_, ids)
        seen = np.where(mask[..., None], motor, 0.0)
        return map_refine(
            self.run_,
            codes,
            seen,
            mask,
            means,
            precisions,
            r,
            int(self.refine),
            float(self.refine_lr),
            threads=self.threads,
        )

    def forecast(self, motor, observed, labels=None, lengths=None, frames=None) -> Forecast:
        """The decoded codes of the encoder, corrected (module docstring), and ``details["encoder"]``."""
        motor, mask, ids = self._arguments(motor, observed, labels, lengths)
        n, steps = mask.shape
        rule = None
        if self.refine > 0:
            rule = observed if isinstance(observed, Observation) else observation_rule(observed, lengths, (n, steps))
        out, codes = self.predict_prefix(motor, mask, ids, valid_mask(check_lengths(lengths, n, steps), steps), rule)
        details = {"encoder": self.summary()}
        if ids is not None:
            details["posterior"] = np.eye(self.primitives_.count)[ids].tolist()
        return Forecast(out, codes, details)

    def summary(self) -> dict:
        """What ``result.json`` records of the encoder and its training."""
        return {
            "given": bool(self.given),
            "n_train": int(self.n_train),
            "steps": int(self.steps),
            "hidden": int(self.hidden),
            "residuals": float(self.residuals),
            "refine": int(self.refine),
            "final_loss": float(self.losses_[-max(1, len(self.losses_) // 20) :].mean()),
            "fit_seconds": float(self.fit_seconds_),
            "primitives": self.primitives_.summary(),
        }

    # -- online -----------------------------------------------------------------------------
    def stream(self, truth, lengths, labels, frames, steps, keep, data=None) -> EncoderStream:
        """One forward pass of the prefix seen so far, one decode and the correction per arriving step;
        equal after step ``t`` to :meth:`forecast` of that prefix. The refinement's ``r`` (for a prefix
        of ``keep`` steps) is chosen before the first step arrives."""
        if tuple(truth.shape[1:]) != self.shape_:
            raise UserError(f"motor must have the run's (T, J) = {self.shape_}, got {tuple(truth.shape[1:])}")
        rule = Observation.build(int(keep))
        if self.refine > 0:
            self.prior_.choice(rule)  # chosen before the first step arrives, not in the latency
        return EncoderStream(self, truth, lengths, self._given_ids(labels, len(truth)), rule)


class EncoderStream(Stream):
    """The encoder read again on each longer prefix."""

    init = ENCODER

    def __init__(self, predictor: EncoderPredictor, truth, lengths, ids, rule: Observation):
        self.predictor, self.truth, self.lengths, self.ids, self.rule = predictor, truth, lengths, ids, rule
        self.scaler = predictor.run_.scaler
        self.valid = valid_mask(lengths, truth.shape[1])

    def arrive(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        mask = np.arange(self.truth.shape[1])[None, :] < np.minimum(self.lengths, t)[:, None]
        return self.predictor.predict_prefix(self.truth, mask, self.ids, self.valid, self.rule)
