"""MAP through the decoder under a code prior per primitive.

:class:`~primspace.predict.prior.PriorPredictor` conditions the decoded draws of each
primitive's prior linearly (the ensemble Kalman update): its conditioned code is the best
code of a linear-Gaussian stand-in for the decoder. :class:`PriorMapPredictor` starts from
that code and finds the code of largest posterior density through the decoder itself,
θ frozen: for each motion, with ``k`` its primitive (``N(μ_k, C_k)`` its prior over codes)
and ``r`` the prior predictor's observation noise per entry,

    ``J(z) = Σ_observed (d(θ, z) − x)² / (2 r) + ½ (z − μ_k)ᵀ C_k⁻¹ (z − μ_k)``

minimised by ``iterations`` steps of Adam on the code (:func:`map_refine`, a row-wise Adam,
:class:`~primspace.model.latent.LatentTable`: each code moves as if it had its own optimiser, so
the batch does not change any code's path). The prediction is the decoded MAP code, then
the continuity correction (:func:`~primspace.predict.candidates.continuity_correction`).

Given the primitive (``given=True``: each motion's label; ``primitive=``: one for all), the
prior is that primitive's and ``r`` the prior predictor's ``noise_given``. Without it only
the top primitive of the posterior over primitives is refined (its prior, the label-free
``noise``); the prediction is that primitive's MAP decode, not the posterior-weighted
mixture, and ``details["posterior"]`` keeps the weights.

:func:`map_refine` and :func:`map_objective` take codes, observed steps and a prior per
motion, so another predictor (an amortised encoder) refines its own codes the same way.
The decoder is causal: without a code window only the steps up to the last observed one are
decoded while optimising. On the CPU, float32 and one thread by default: the same inputs give
the same numbers.
"""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import torch
from sklearn.base import clone

from primspace.model.latent import LatentTable
from primspace.predict.base import Forecast, Predictor, observation_rule, observed_mask
from primspace.predict.candidates import continuity_correction
from primspace.predict.metrics import check_lengths, valid_mask
from primspace.predict.prior import PriorPredictor
from primspace.train.api import reconstruct
from primspace.train.config import resolve_device, thread_limit
from primspace.train.run import require_run
from primspace.utils.errors import UserError

__all__ = ["PriorMapPredictor", "PRIOR_MAP", "MAP_STARTS", "map_refine", "map_objective", "prior_terms", "best_members"]

#: The name of the MAP predictor among the predictors.
PRIOR_MAP = "prior_map"
#: Where the MAP starts: the prior predictor's conditioned code, or the decoded draw of the
#: primitive's prior with the smallest objective.
MAP_STARTS = ("conditioned", "best_member")


class _Objective:
    """``J(z)`` per motion for a batch (module docstring), on a frozen copy of the decoder."""

    def __init__(self, run, seen, mask, means, precisions, r, device: str = "cpu"):
        self.device = resolve_device(device)
        n, steps, _ = np.shape(seen)
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != (n, steps):
            raise UserError(f"mask must have shape ({n}, {steps}) like seen's first two axes, got {mask.shape}")
        model = copy.deepcopy(run.model).to(self.device).eval().requires_grad_(False)
        last = int(np.flatnonzero(mask.any(axis=0)).max(initial=-1)) + 1
        if model.config.code_window is None and 0 < last < model.config.length:
            model.config = replace(model.config, length=last)  # causal: the observed prefix only
        length = model.config.length
        self.model = model

        def tensor(a):
            return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).to(self.device)

        self.seen = tensor(np.asarray(seen)[:, :length])
        self.mask = tensor(mask[:, :length])
        self.means, self.precisions = tensor(means), tensor(precisions)
        self.weight = tensor(0.5 / np.broadcast_to(np.asarray(r, dtype=np.float64), (n,)))

    def __call__(self, z: torch.Tensor) -> torch.Tensor:
        """(n,) the objective of each code of ``z`` (n, q)."""
        motor = self.model(z, images=False).motor
        sse = ((motor - self.seen).pow(2).sum(dim=2) * self.mask).sum(dim=1)
        dev = z - self.means
        quad = torch.einsum("nq,nqp,np->n", dev, self.precisions, dev)
        return self.weight * sse + 0.5 * quad


def _check_r(r, n: int) -> None:
    values = np.broadcast_to(np.asarray(r, dtype=np.float64), (n,))
    if not (np.isfinite(values).all() and (values > 0).all()):
        raise UserError(f"the observation noise r must be finite and > 0, got {r!r}")


def map_objective(run, codes, seen, mask, means, precisions, r, *, device: str = "cpu", threads=1) -> np.ndarray:
    """(n,) float64: ``J(z)`` of each motion's code (module docstring).

    Parameters are those of :func:`map_refine`.
    """
    run = require_run(run)
    _check_r(r, len(codes))
    with thread_limit(threads), torch.no_grad():
        objective = _Objective(run, seen, mask, means, precisions, r, device)
        z = torch.from_numpy(np.ascontiguousarray(codes, dtype=np.float32)).to(objective.device)
        return objective(z).double().cpu().numpy()


def map_refine(
    run, codes, seen, mask, means, precisions, r, iterations: int, lr: float, *, device: str = "cpu", threads=1
) -> np.ndarray:
    """The MAP codes through the decoder, θ frozen: ``iterations`` Adam steps on ``J(z)``.

    Parameters
    ----------
    run : TrainedRun
    codes : ndarray (n, q)
        The start of each motion's code.
    seen : ndarray (n, T, J)
        The motions in the run's scaled units (read only where ``mask``).
    mask : ndarray (n, T) bool
        The observed steps of each motion.
    means : ndarray (n, q)
        Each motion's prior mean ``μ``.
    precisions : ndarray (n, q, q)
        Each motion's prior precision ``C⁻¹``.
    r : float or ndarray (n,)
        Observation noise per entry (scaled units²).
    iterations : int
        Adam steps (0: the start, as float32).
    lr : float
        Adam's learning rate (code units per step, at most about).
    device : str
    threads : int or None
        CPU threads while optimising (:func:`~primspace.train.config.thread_limit`; None: as they are).

    Returns
    -------
    ndarray (n, q) float32
    """
    run = require_run(run)
    codes = np.asarray(codes, dtype=np.float32)
    if codes.ndim != 2 or not np.isfinite(codes).all():
        raise UserError(f"codes must be a finite (n, q) array, got shape {codes.shape}")
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 0:
        raise UserError(f"iterations must be a whole number >= 0, got {iterations!r}")
    if not (isinstance(lr, (int, float, np.floating)) and np.isfinite(lr) and lr > 0):
        raise UserError(f"lr must be a finite number > 0, got {lr!r}")
    _check_r(r, len(codes))
    if iterations == 0 or len(codes) == 0:
        return codes.copy()
    with thread_limit(threads):
        objective = _Objective(run, seen, mask, means, precisions, r, device)
        table = LatentTable(torch.from_numpy(codes).to(objective.device), float(lr))
        idx = torch.arange(len(codes), device=objective.device)
        for _ in range(int(iterations)):
            rows = table.batch(idx)
            objective(rows).sum().backward()  # each row's gradient is its own motion's
            table.step(idx, rows.grad)
        return table.numpy()


def prior_terms(gaussians, ids) -> tuple[np.ndarray, np.ndarray]:
    """Each motion's prior mean (n, q) and precision (n, q, q) from the primitives' Gaussians
    (:class:`~primspace.predict.code_prior.GaussianCode`) and each motion's primitive ``ids``."""
    ids = np.asarray(ids, dtype=np.int64)
    means = np.stack([g.mean for g in gaussians])
    precisions = np.stack([np.linalg.inv(np.asarray(g.cov, dtype=np.float64)) for g in gaussians])
    precisions = 0.5 * (precisions + precisions.transpose(0, 2, 1))
    return means[ids], precisions[ids]


def best_members(ensembles, ids, seen, mask, means, precisions, r) -> np.ndarray:
    """(n, q): for each motion, the code of the decoded draw of its primitive's ensemble
    (:class:`~primspace.predict.code_prior.DecodedGaussian`) with the smallest ``J``."""
    n = len(ids)
    flat = np.asarray(seen, dtype=np.float64).reshape(n, -1)
    entries = np.repeat(np.asarray(mask, dtype=np.float64), np.shape(seen)[2], axis=1)
    r = np.broadcast_to(np.asarray(r, dtype=np.float64), (n,))
    out = np.empty((n, means.shape[1]), dtype=np.float32)
    for k in np.unique(ids):
        rows = np.flatnonzero(ids == k)
        ens = ensembles[k]
        members = ens.mean + ens.deviations * np.sqrt(len(ens.deviations) - 1)
        motion, code = members[:, : ens.n_motion], members[:, ens.n_motion :]
        x, m = flat[rows] * entries[rows], entries[rows]
        sse = m @ (motion**2).T - 2.0 * x @ motion.T + (x * flat[rows]).sum(axis=1, keepdims=True)  # (n_k, N)
        dev = code[None] - means[rows][:, None]  # (n_k, N, q)
        quad = np.einsum("inq,iqp,inp->in", dev, precisions[rows], dev)
        out[rows] = code[np.argmin(sse / (2.0 * r[rows, None]) + 0.5 * quad, axis=1)]
    return out


class PriorMapPredictor(Predictor):
    """MAP of each motion's code through the decoder under its primitive's prior (module docstring).

    Without the primitive only the top primitive of the posterior is refined, and the
    prediction is its MAP decode (the posterior is kept in ``details["posterior"]``).

    Parameters
    ----------
    run : TrainedRun or path-like
        The trained run (θ frozen; not changed).
    prior : PriorPredictor, optional
        The priors, noise and posterior: fitted already (used as it is, shared) or not (a
        clone is fitted); default: a ``PriorPredictor(run)`` with ``label_names`` and ``random_state``.
    primitive, given
        As :class:`~primspace.predict.prior.PriorPredictor`; when set they override the prior's
        (:meth:`~primspace.predict.prior.PriorPredictor.asked`).
    label_names : list of str, optional
        Names of the labels (for the default prior).
    iterations : int
        Adam steps of the MAP (0: the start decoded).
    lr : float
        Adam's learning rate on the codes.
    start : {"conditioned", "best_member"}
        The prior predictor's conditioned code, or the decoded draw with the smallest objective.
    continuity : bool
    random_state : int, optional
        Seed of the default prior (default: the run's).
    threads : int or None
        CPU threads of the MAP.
    """

    def __init__(
        self,
        run,
        prior: PriorPredictor | None = None,
        primitive=None,
        given: bool = False,
        label_names=None,
        iterations: int = 200,
        lr: float = 0.01,
        start: str = "conditioned",
        continuity: bool = True,
        random_state: int | None = None,
        threads: int | None = 1,
    ):
        self.run = run
        self.prior = prior
        self.primitive = primitive
        self.given = given
        self.label_names = label_names
        self.iterations = iterations
        self.lr = lr
        self.start = start
        self.continuity = continuity
        self.random_state = random_state
        self.threads = threads

    @property
    def needs_labels(self) -> bool:
        """Given each motion's primitive by its label."""
        if self.given or self.primitive is not None:
            return bool(self.given) and self.primitive is None
        return self.prior is not None and self.prior.needs_labels

    def fit(self, motor, labels=None, lengths=None, frames=None) -> PriorMapPredictor:
        """Fit the inner prior predictor (unless it is fitted already)."""
        self.resolve_run()
        if self.start not in MAP_STARTS:
            raise UserError(f"start must be one of {', '.join(MAP_STARTS)}, got {self.start!r}")
        prior = self.prior
        if prior is None:
            prior = PriorPredictor(self.run_, label_names=self.label_names, random_state=self.random_state)
        elif not hasattr(prior, "gaussians_"):
            prior = clone(prior)
        if not hasattr(prior, "gaussians_"):
            prior.fit(motor, labels, lengths, frames)
        if self.given or self.primitive is not None:
            prior = prior.asked(self.primitive, self.given)
        self.prior_ = prior
        return self

    def forecast(self, motor, observed, labels=None, lengths=None, frames=None) -> Forecast:
        """The decoded MAP codes (continuity-corrected), the codes, and the prior's details with ``map``."""
        motor = self.check_query(motor)
        n, steps, _ = motor.shape
        inner = self.prior_.forecast(motor, observed, labels, lengths, frames)
        rule = observation_rule(observed, lengths, (n, steps))
        mask = observed_mask(observed, lengths, (n, steps))
        seen = np.where(mask[..., None], motor, 0.0)
        choice = self.prior_.choice(rule)
        r = choice["noise_given"] if self.prior_.told_primitive else choice["noise"]
        ids = np.asarray(inner.details["posterior"]).argmax(axis=1)
        means, precisions = prior_terms(self.prior_.gaussians_, ids)
        terms = (seen, mask, means, precisions, r)
        start = inner.codes
        if self.start == "best_member":
            start = best_members(self.prior_.ensembles_, ids, *terms)
        codes = map_refine(self.run_, start, *terms, self.iterations, self.lr, threads=self.threads)
        before = map_objective(self.run_, start, *terms, threads=self.threads)
        after = map_objective(self.run_, codes, *terms, threads=self.threads)
        out = self.run_.scaler.transform(reconstruct(self.run_, codes, images=False, batch_size=1024)[0])
        out = out.astype(np.float64)
        if self.continuity:
            out = continuity_correction(out, seen, mask, valid_mask(check_lengths(lengths, n, steps), steps))
        details = dict(inner.details, model_share=1.0)  # the prediction is the MAP code decoded
        details["map"] = {
            "iterations": int(self.iterations),
            "lr": float(self.lr),
            "start": self.start,
            "objective_start": float(before.mean()),
            "objective_end": float(after.mean()),
        }
        return Forecast(out, codes, details)
