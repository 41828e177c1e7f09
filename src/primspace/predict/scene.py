"""The scene only: see the block, name the primitive, do it (issue 25, item 4; docs/predict.md).

No step of the new motion is demonstrated. What is given: the first camera frame, the
initial joints (the first step), and the primitive to perform, named as a cluster of the
run's fitted codes. The paper finds primitives as affine subspaces of the codes (paper,
*Affine Subspace Clustering*; :class:`~primspace.cluster.LowRankSubspaceClustering`); here
the code of the new motion is searched inside the chosen cluster's affine subspace,

    z = μ_k + U_kᵀ a,

``μ_k`` the mean of cluster ``k``'s fitted codes and ``U_k`` (r x K·q) their top ``r``
principal directions (``r``: the fewest that explain at least 90 % of the cluster's
variance, or ``rank=``). θ is frozen and only ``a`` is optimised (start ``a = 0``: the
cluster mean), by the masked loss of inference (:func:`primspace.train.loss.batch_loss`)
on the observed entries: the first step's joints and the first frame. Row-wise Adam
(:class:`~primspace.model.latent.LatentTable`), the whole set in order, on the CPU, seeded by the
run's seed: the same call gives the same codes. The decoder's whole sequence is the
prediction (:class:`~primspace.predict.Prediction`), scored on the steps after the
first (:func:`primspace.predict.metrics.unobserved_mse`).

**Which cluster is which primitive.** Cluster ids are numbered by the order of their
first member among the run's fitted samples (the run's ``indices`` order): the cluster
of the first fitted demonstration is 0, the next new one 1, and so on, so the numbering
is stable for a run and seed. :func:`scene_clusters` lists, per cluster, its size, its
first member and, when the fitted data has labels, the majority label's name: for
display only, so a user can tell "cluster 2 is the pushes" before asking for it. The
number of clusters, when not given, is the number of distinct labels of the fitted
data: a count, the labels themselves are never used to cluster.

This module sits above ``train`` and ``cluster`` (the training layer knows nothing of
clustering, docs/architecture.md), beside the experiments, which use
:func:`run_scene_point`.
"""

from __future__ import annotations

import contextlib
import copy
from dataclasses import replace

import numpy as np
import torch

from primspace.data import MotionDataset
from primspace.data.steps import valid_steps
from primspace.utils.errors import UserError
from primspace.model.latent import LatentTable
from primspace.predict.api import Prediction
from primspace.predict.base import Forecast, Predictor, motions_as_dataset
from primspace.predict.scene_clusters import SCENE_VARIANCE, SceneClusters, affine_subspace, cluster_codes
from primspace.predict.gradient import DEFAULT_PREDICT_EPOCHS
from primspace.predict.metrics import frame_errors, unobserved_mse
from primspace.utils.progress import progress_bar
from primspace.train.api import as_run, reconstruct, uses_images
from primspace.train.checks import select
from primspace.train.config import lr_factor
from primspace.train.loss import DataTensors, code_step
from primspace.train.observe import FIRST, Observation, observation_masks
from primspace.train.starts import fitted_samples

__all__ = [
    "SCENE",
    "SCENE_VARIANCE",
    "SceneClusters",
    "ScenePredictor",
    "cluster_codes",
    "scene_clusters",
    "affine_subspace",
    "infer_in_subspace",
    "predict_scene",
    "run_scene_point",
]

#: ``Prediction.init`` and ``result.json``'s ``mode`` of a scene-only prediction.
SCENE = "scene"


def _observation() -> Observation:
    """What the scene mode observes: the first step's joints and the first frame."""
    return Observation.build(1, FIRST)


def scene_clusters(
    run, n_clusters: int | None = None, *, fitted_data: MotionDataset | None = None, r2_target=None
) -> SceneClusters:
    """The run's fitted codes clustered, ids numbered by first member (module docstring).

    ``n_clusters`` defaults to the number of distinct labels of the fitted data (``fitted_data``
    or the run's data file): a count, not the labels. The labels, when there are any, also
    name each cluster by its majority (display only). Seeded by the run's seed.
    """
    parent = as_run(run)
    fitted = None
    if fitted_data is not None or parent.data_path is not None:
        fitted = fitted_samples(parent, fitted_data)
    labels = None if fitted is None else fitted.labels
    if n_clusters is None:
        if labels is None:
            why = "has no data file" if fitted is None else "fitted data has no labels"
            raise UserError(
                f"the scene mode clusters the fitted codes and the run {why} to count primitives by: "
                "give the number of clusters (n_clusters, --primitives K)"
            )
        n_clusters = int(np.unique(labels[labels >= 0]).size)
    return cluster_codes(
        parent.latents,
        n_clusters,
        labels,
        None if fitted is None else fitted.label_names,
        r2_target=r2_target,
        random_state=int(parent.train_config.seed),
    )


def infer_in_subspace(
    run,
    data: MotionDataset,
    mean: np.ndarray,
    basis: np.ndarray,
    *,
    epochs: int,
    progress: bool | None = None,
    **overrides,
) -> np.ndarray:
    """Codes (n, K·q) float32 ``mean + a @ basis`` with ``a`` fitted (θ frozen, start ``a = 0``) to
    the scene's observed entries (first joints, first frame) by the masked inference loss."""
    parent = as_run(run)
    try:
        tc = replace(
            parent.train_config, epochs=epochs, device="cpu", amp=False, vision_frames=None, **overrides
        ).validate()
    except TypeError as exc:
        raise UserError(f"unknown train config override ({exc})") from None
    if not uses_images(parent.model_config, data, tc):
        raise UserError(
            "the scene mode reads the first camera frame, and this run does not use frames (vision_weight 0)"
        )
    tensors = DataTensors.build(data, parent.scaler, True, "cpu", _observation())
    model = copy.deepcopy(parent.model).cpu().eval().requires_grad_(False)
    mu = torch.from_numpy(np.asarray(mean, dtype=np.float32))
    u = torch.from_numpy(np.ascontiguousarray(basis, dtype=np.float32))
    n, r = len(data), u.shape[0]
    table = LatentTable(torch.zeros(n, r), tc.latent_lr)
    with torch.random.fork_rng(devices=[]), progress_bar(tc.epochs if r else 0, "scene", enabled=progress) as advance:
        torch.manual_seed(tc.seed)
        for epoch in range(tc.epochs if r else 0):
            table.lr = tc.latent_lr * lr_factor(epoch, tc.epochs, tc.final_lr_fraction)
            for start in range(0, n, tc.batch_size):  # each code on its own sample's gradient
                idx = torch.arange(start, min(n, start + tc.batch_size))
                code_step(model, table, idx, tensors, tc, contextlib.nullcontext(), to_code=lambda a: mu + a @ u)
            advance()
    return (np.asarray(mean, dtype=np.float64) + table.numpy().astype(np.float64) @ np.asarray(basis)).astype(
        np.float32
    )


def _check_scene(parent, data: MotionDataset) -> None:
    if not isinstance(data, MotionDataset):
        raise UserError(f"expected a MotionDataset, got {type(data).__name__}")
    if not parent.model_config.has_images:
        raise UserError(
            "the scene mode reads the first camera frame and needs a run with an image head; "
            "this run was fitted on joints only"
        )
    if not data.has_images:
        where = str(data.path) if data.path is not None else "the data set"
        raise UserError(f"the scene mode reads the first camera frame, and {where} has no frames")


def predict_scene(
    run,
    data: MotionDataset,
    primitive: int | str,
    *,
    clusters: SceneClusters | None = None,
    n_clusters: int | None = None,
    rank: int | None = None,
    epochs: int = DEFAULT_PREDICT_EPOCHS,
    indices=None,
    fitted_data: MotionDataset | None = None,
    frames: bool = True,
    progress: bool | None = None,
    **overrides,
) -> Prediction:
    """Predict each sample's whole motion from its first frame and first joints, as primitive ``primitive``.

    Parameters
    ----------
    run : TrainedRun or path-like
        A fitted run with an image head (θ frozen; the run is not changed).
    data : MotionDataset
        The scenes (with frames); every step after the first is the answer the errors are measured against.
    primitive : int or str
        The primitive to perform: a label name of the fitted data (``"push"``: the cluster
        mostly of that label) or a cluster id (:func:`scene_clusters`: ids by first member).
    clusters : SceneClusters, optional
        The run's clusters, computed once (:func:`scene_clusters`); default: computed here.
    n_clusters : int, optional
        How many clusters (default: the number of distinct labels of the fitted data).
    rank : int, optional
        The subspace's dimension (default: 90 % of the cluster's variance).
    epochs : int
        Optimisation epochs of the subspace coordinates (0: the cluster mean).
    indices, fitted_data, frames, progress, **overrides
        As in :func:`primspace.predict.predict` (``latent_lr``, ``batch_size``, ``seed`` ...).

    Returns
    -------
    Prediction
        ``init`` ``"scene"``; ``details``: ``mode``, and ``scene`` (primitive, its name,
        rank, cluster sizes and names).
    """
    parent = as_run(run)
    _check_scene(parent, data)
    sub, idx = select(data, indices)
    if clusters is None:
        clusters = scene_clusters(parent, n_clusters, fitted_data=fitted_data)
    elif clusters.codes.shape != parent.latents.shape or not np.allclose(clusters.codes, parent.latents):
        raise UserError("clusters are not of this run's fitted codes: compute them with scene_clusters(run)")
    k = clusters.check(primitive)
    mean, basis = clusters.subspace(k, rank)
    codes = infer_in_subspace(parent, sub, mean, basis, epochs=epochs, progress=progress, **overrides)
    motor, predicted_frames = reconstruct(parent, codes, images=frames)
    motor_observed, frames_observed = observation_masks(_observation(), sub)
    lengths = sub.valid_lengths
    scaled, truth = parent.scaler.transform(motor), parent.scaler.transform(sub.motor)
    errors = {"motor_mse": unobserved_mse(scaled, truth, motor_observed, lengths)}
    if predicted_frames is not None:
        errors["vision_mse"], errors["psnr"] = frame_errors(
            predicted_frames, sub.load_images().images, frames_observed, valid_steps(lengths, sub.length)
        )
    details = {
        "mode": SCENE,
        "scene": {"primitive": k, "name": clusters.names[k], "rank": int(basis.shape[0]), **clusters.summary()},
    }
    return Prediction(
        codes=codes,
        motor=motor,
        frames=predicted_frames,
        motor_observed=motor_observed,
        frames_observed=frames_observed,
        indices=idx,
        errors=errors,
        observation=_observation().to_dict(),
        init=SCENE,
        epochs=int(epochs),
        details=details,
    )


class ScenePredictor(Predictor):
    """The scene mode as a predictor: each motion from its first frame and first joints, as the
    primitive asked for (``labels`` of :meth:`forecast`: a cluster id or a label name each).

    :meth:`fit` clusters the run's fitted codes (``motor`` is not read: the fitted codes are
    the run's; ``labels`` name the clusters by majority and count them when ``n_clusters`` is
    None); :meth:`forecast` searches each motion's code in its primitive's affine subspace
    (:func:`infer_in_subspace`). ``observed`` is not read: the scene mode observes the first
    step of the joints and the first frame, always.

    Parameters
    ----------
    run : TrainedRun or path-like
        A fitted run with an image head.
    n_clusters : int, optional
        Clusters of the fitted codes (default: the number of distinct fitted labels).
    label_names : list of str, optional
        The names of the fitted labels (so that a primitive may be asked for by name).
    rank : int, optional
        The subspace's dimension (default: 90 % of the cluster's variance).
    epochs : int
    overrides : dict, optional
        Train-config overrides of the search (``latent_lr``, ``batch_size``, ``seed`` ...).
    progress : bool, optional
    """

    needs_labels = True

    def __init__(
        self,
        run,
        n_clusters: int | None = None,
        label_names=None,
        rank: int | None = None,
        epochs: int = DEFAULT_PREDICT_EPOCHS,
        overrides: dict | None = None,
        progress: bool | None = False,
    ):
        self.run = run
        self.n_clusters = n_clusters
        self.label_names = label_names
        self.rank = rank
        self.epochs = epochs
        self.overrides = overrides
        self.progress = progress

    def fit(self, motor=None, labels=None, lengths=None, frames=None) -> "ScenePredictor":
        """Cluster the run's fitted codes (``labels``: the fitted demonstrations', in its order)."""
        self.run_ = as_run(self.run)
        n = self.n_clusters
        if n is None:
            if labels is None:
                raise UserError(
                    "the scene mode clusters the fitted codes and needs the number of clusters "
                    "(n_clusters) or the fitted labels to count them by"
                )
            labels = np.asarray(labels)
            n = int(np.unique(labels[labels >= 0]).size)
        self.clusters_ = cluster_codes(
            self.run_.latents, n, labels, self.label_names, random_state=int(self.run_.train_config.seed)
        )
        return self

    def forecast(self, motor, observed=None, labels=None, lengths=None, frames=None) -> Forecast:
        """Each motion (scaled units) as the primitive ``labels[i]`` asks for, and its code."""
        if labels is None or frames is None:
            raise UserError("the scene mode needs each motion's primitive (labels) and its frames")
        motor = np.asarray(motor, dtype=np.float64)
        wanted = [self.clusters_.check(k) for k in labels]
        physical = self.run_.scaler.inverse_transform(motor).astype(np.float32)
        data = motions_as_dataset(physical, lengths, frames)
        codes = np.empty((len(motor), self.run_.latents.shape[1]), dtype=np.float32)
        for k in sorted(set(wanted)):
            rows = np.flatnonzero(np.asarray(wanted) == k)
            mean, basis = self.clusters_.subspace(k, self.rank)
            codes[rows] = infer_in_subspace(
                self.run_,
                data.subset(rows),
                mean,
                basis,
                epochs=self.epochs,
                progress=self.progress,
                **(self.overrides or {}),
            )
        scaled = self.run_.scaler.transform(reconstruct(self.run_, codes, images=False)[0])
        return Forecast(scaled, codes, {"mode": SCENE, "primitives": [int(k) for k in wanted]})


def run_scene_point(fit, fitted: MotionDataset, test: MotionDataset, epochs: int) -> dict:
    """The scene mode on an experiment's split, for the success-per-primitive table.

    Parameters
    ----------
    fit : TrainedRun
        The fitted run (image head).
    fitted : MotionDataset
        Its fitted samples, in its order (``data.subset(fit.indices)``), with labels.
    test : MotionDataset
        The scenes to act on, with frames and labels.
    epochs : int

    Returns
    -------
    dict
        ``scaled`` (n, T, J) the predicted motor in scaled units (NaN rows: no cluster
        holds the sample's label), ``motor`` the same in physical units, ``cluster`` (n,)
        the cluster asked for (−1: none), ``mse`` (n,) the unobserved motor MSE, and
        ``clusters`` (:meth:`SceneClusters.summary`) with ``ranks`` per cluster used.

    Notes
    -----
    The labels only pick which primitive to ask for, as a user names the primitive:
    each test sample asks for the cluster whose members' majority label is its label
    (of several, the one holding most fitted samples of that label; of none, the
    cluster holding most of them). The clustering itself sees codes only; its number of
    clusters is the number of distinct fitted labels.
    """
    if fitted.labels is None or test.labels is None:
        raise UserError("run_scene_point picks each sample's primitive by its label: both data sets need labels")
    n_clusters = int(np.unique(fitted.labels[fitted.labels >= 0]).size)
    clusters = cluster_codes(
        fit.latents, n_clusters, fitted.labels, fitted.label_names, random_state=int(fit.train_config.seed)
    )
    counts = np.array(
        [
            [np.sum((clusters.labels == k) & (fitted.labels == lab)) for k in range(n_clusters)]
            for lab in range(int(max(fitted.labels.max(), test.labels.max())) + 1)
        ]
    )
    chosen = np.full(len(test), -1, dtype=np.int64)
    for i, lab in enumerate(test.labels):
        if lab >= 0 and counts[lab].max() > 0:
            score = [(clusters.majority[k] == lab, counts[lab, k]) for k in range(n_clusters)]
            chosen[i] = max(range(n_clusters), key=lambda k: score[k])
    scaled = np.full(test.motor.shape, np.nan)
    mse, ranks = np.full(len(test), np.nan), {}
    for k in np.unique(chosen[chosen >= 0]):
        rows = np.flatnonzero(chosen == k)
        p = predict_scene(
            fit, test, int(k), clusters=clusters, epochs=epochs, indices=rows, frames=False, progress=False
        )
        scaled[rows], mse[rows] = fit.scaler.transform(p.motor), p.errors["motor_mse"]
        ranks[int(k)] = p.details["scene"]["rank"]
    motor = np.where(np.isnan(scaled), np.nan, fit.scaler.inverse_transform(np.nan_to_num(scaled)))
    return {
        "scaled": scaled,
        "motor": motor.astype(np.float32),
        "cluster": chosen,
        "mse": mse,
        "clusters": {**clusters.summary(), "ranks": ranks},
    }
