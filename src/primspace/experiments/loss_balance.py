"""How the loss's terms share the training signal (issue 42, item 3): :func:`loss_balance`.

The paper's loss (*Main Results*): "Denote the entire output of the model during first
$T$ timesteps as $d(\\theta, \\mathbf{z})$. Then loss function will be"

.. math::  L(\\theta, \\mathbf{z}_1, \\mathbf{z}_2, ..., \\mathbf{z}_n) = \\sum_{i=1}^n {\\| d(\\theta, \\mathbf{z}_i) - \\mathbf{o}_i\\|^2}

where ``o_i`` holds the joint angles and, with images, the camera frames. Read as a sum
over every entry (``TrainConfig.loss_reduction="sum"``), a 48x64x3 frame has 1024 times
as many entries as a 9-joint vector, so the frames carry most of the loss; under
primspace's default (``"mean"``) each term is a per-element mean and both weigh alike
(:mod:`primspace.train.loss`).

For a trained run (``fit`` or ``infer``) and its own samples, in the run's own reduction
and weights, :func:`loss_balance` measures

- the motor term ``w_m · motor`` and the vision term ``w_v · vision`` of the loss (and the
  code-smoothness term, when the run has one), which add up to :func:`batch_loss`'s total
  (under ``"precision"`` each term is ``½ (e^{-s_m} · w_m · MSE_m + s_m)`` and the learned
  ``s_m`` and weights ``e^{-s_m}`` are reported; the gradients are of these terms, the
  ``s_m`` held, not counted in θ);
- the norm of each term's gradient with respect to θ (the decoder's weights: all of them,
  the dynamics that both heads share, each head) and to the codes (each code on its own
  sample's loss, as training steps it), and the cosine between the two terms' gradients;
- the motor error per primitive and per joint: RMS in the data's joint units (the run's
  :class:`~primspace.data.JointScaler` undone) over each sample's valid steps;
- the terms, gradients and RMS per primitive.

The frames are scored at every step (a run trained on ``vision_frames`` drawn frames
estimated the same sum, scaled by ``T / K``). An inferred run with an observation rule
(``config.json`` ``observe``) has its terms on the observed entries, as it was trained;
the joint RMS is over every valid step. The work runs on the CPU in batches of one
primitive's samples, the model copied (the run's own is never changed).
"""

from __future__ import annotations

import contextlib
import copy
import math
from dataclasses import replace

import numpy as np
import torch

from primspace.data import MotionDataset
from primspace.data.indices import check_indices
from primspace.data.steps import valid_steps
from primspace.train.loss import DataTensors, batch_loss, code_variation
from primspace.train.observe import Observation
from primspace.train.rundata import load_fitted_data
from primspace.train.sessions import as_run, uses_images
from primspace.utils.errors import UserError

__all__ = ["loss_balance", "THETA_PARTS", "UNLABELLED"]

#: θ's parts: the dynamics that both heads read (``p``, ``g``, the MTRNN layers) and each head.
THETA_PARTS = ("dynamics", "motor_head", "image_head")
#: The group of samples whose label is -1.
UNLABELLED = "unlabelled"
_CPU = torch.device("cpu")


def loss_balance(run, dataset: MotionDataset, *, indices=None, batch_size: int = 8, gradients: bool = True) -> dict:
    """The loss's terms, their gradients and the motor error per primitive and joint of ``run``.

    Parameters
    ----------
    run : TrainedRun or path-like
        A ``fit`` or ``infer`` run (:func:`primspace.train.load_run`).
    dataset : MotionDataset
        The run's data file (or any data set holding its samples, with ``labels``):
        :func:`primspace.train.rundata.load_fitted_data` finds the run's samples in it.
    indices : array-like of int, optional
        Rows of the run (``0 .. len(run.latents) - 1``) to measure; default every row.
    batch_size : int
        Samples per forward/backward pass (each batch holds one primitive's samples); it
        bounds memory, not the numbers.
    gradients : bool
        False: only the terms and the errors, without gradients (faster).

    Returns
    -------
    dict (JSON-ready)
        ``run``, ``kind``, ``epoch``, ``loss_reduction``, ``motor_weight``, ``vision_weight``,
        ``images``, ``n_samples``, ``primitives``, ``joints``; ``precision``: the learned
        log-variance ``s_m`` and weight ``e^{-s_m}`` of each modality
        (:meth:`~primspace.model.precision.ModalityPrecision.summary`; None when the decoder
        has none);
        ``terms``: ``motor``, ``vision`` (and ``smoothness``), ``total``, ``vision_share``
        (the vision term over the total; under ``"precision"`` the vision share of the
        weighed errors ``e^{-s_m} · w_m · MSE_m``); ``mse``: per-element ``motor`` (scaled units) and
        ``vision`` (pixels in [0, 1]) as metrics.jsonl logs them;
        ``gradients`` (with ``gradients``): ``theta`` (per term, the norm of the gradient of
        the mean loss over the samples, per part of :data:`THETA_PARTS` and ``all``;
        ``cosine`` motor-vision over ``all`` and ``dynamics``; ``vision_over_motor`` norm
        ratios) and ``codes`` (the mean over samples of ``‖∂ℓ_i/∂z_i‖`` per term, the
        median ratio vision/motor and the mean cosine);
        ``per_primitive``: the same per primitive (``n``, ``terms``, ``vision_share``,
        ``mse``, ``motor_rms`` over all joints in data units, ``gradients``);
        ``joint_rms``: ``values`` (primitives x joints) and ``all`` (joints) in the data's
        joint units; ``joint_rms_scaled``: the same in the model's [-1, 1] units.

    Raises
    ------
    UserError
        A data set without labels or without the run's samples, bad ``indices`` or ``batch_size``.
    """
    run = as_run(run)
    if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
        raise UserError(f"batch_size must be a whole number >= 1, got {batch_size!r}")
    data = load_fitted_data(run, dataset)
    if data.labels is None:
        where = str(dataset.path) if dataset.path is not None else "the data set"
        raise UserError(f"{where}: has no labels (field 'labels'): loss balance reports per primitive")
    rows = np.arange(len(data)) if indices is None else check_indices(indices, len(data))
    tc = run.train_config
    setup = {
        "data": data,
        "use_images": uses_images(run.model_config, data, tc),
        "observation": _observation(run),
        "model": copy.deepcopy(run.model).to(_CPU).float().eval().requires_grad_(gradients),
        "tc": tc,
        "scaler": run.scaler,
    }
    names = _group_names(data)
    totals = _Totals(len(names), data.n_joints, _theta_parts(setup["model"]) if gradients else None)
    codes = torch.from_numpy(np.ascontiguousarray(run.latents, dtype=np.float32))
    for group, batch in _batches(np.asarray(data.labels)[rows], rows, batch_size, len(names)):
        _measure(setup, codes[torch.from_numpy(batch)], batch, group, totals, gradients)
    return _summary(run, setup, totals, names, data.joint_names)


def _observation(run) -> Observation | None:
    """The observation rule an inferred run was trained under (None: every entry)."""
    rule = run.config.get("observe")
    return None if not rule else Observation.build(rule["motor"], rule["frames"])


def _group_names(data: MotionDataset) -> list[str]:
    """The primitives' names, then :data:`UNLABELLED` (samples labelled -1 fall there)."""
    return list(data.label_names) + [UNLABELLED]


def _batches(labels: np.ndarray, rows: np.ndarray, batch_size: int, n_groups: int):
    """``(group, rows)`` batches, each of one primitive's rows (label -1: the last group)."""
    groups = np.where(labels < 0, n_groups - 1, labels)
    for group in range(n_groups):
        mine = rows[groups == group]
        for start in range(0, len(mine), batch_size):
            yield group, mine[start : start + batch_size]


def _theta_parts(model) -> dict[str, list]:
    """θ's parameters by part (:data:`THETA_PARTS`); the learned precisions (``precision.*``), the
    loss's own weights, are not among them."""
    parts = {name: [] for name in THETA_PARTS}
    for name, param in model.named_parameters():
        head = name.split(".")[0]
        if head != "precision":
            parts[head if head in parts else "dynamics"].append(param)
    return parts


def _terms(model, z: torch.Tensor, tensors: DataTensors, tc) -> tuple[dict, dict]:
    """The batch's loss terms (each as :func:`batch_loss` weighs and reduces it) and their per-element MSEs."""
    idx = torch.arange(z.shape[0])
    plain = replace(tc, code_smoothness=0.0)
    motor_only = replace(tensors, images=None, streamed=False, frame_mask=None)
    loss, values = batch_loss(model, z, idx, motor_only, plain, contextlib.nullcontext())
    terms, mse = {"motor": loss}, {"motor": float(values[1])}
    if tensors.use_images:  # the motor head runs again at weight 0: it adds nothing to the loss or its gradient
        loss, values = batch_loss(model, z, idx, tensors, replace(plain, motor_weight=0.0), contextlib.nullcontext())
        terms["vision"], mse["vision"] = loss, float(values[2])
    if tc.code_smoothness > 0 and model.config.code_window is not None:
        terms["smoothness"] = tc.code_smoothness * code_variation(z, model.config, tensors.mask)
    return terms, mse


def _measure(setup: dict, z: torch.Tensor, batch: np.ndarray, group: int, totals: _Totals, gradients: bool) -> None:
    """Add one batch (rows ``batch`` of one primitive, codes ``z``) to ``totals``."""
    model, part = setup["model"], setup["data"].subset(batch)
    tensors = DataTensors.build(part, setup["scaler"], setup["use_images"], _CPU, observation=setup["observation"])
    z = z.clone().requires_grad_(gradients)
    with torch.set_grad_enabled(gradients):
        terms, mse = _terms(model, z, tensors, setup["tc"])
    totals.add_terms(group, len(batch), {k: float(v.detach()) for k, v in terms.items()}, mse)
    if gradients:
        params = [p for ps in totals.parts.values() for p in ps]
        for name, value in terms.items():
            found = torch.autograd.grad(value, [*params, z], allow_unused=True)
            flat = [torch.zeros_like(p) if g is None else g for p, g in zip(params, found[:-1])]
            per_code = torch.zeros_like(z) if found[-1] is None else found[-1] * len(batch)  # own sample's loss
            totals.add_gradients(group, name, len(batch), torch.cat([g.reshape(-1) for g in flat]), per_code)
    with torch.no_grad():
        motor = model(z.detach(), images=False).motor.double().numpy()
    scaler = setup["scaler"]
    error = motor * scaler.half_range_ + scaler.center_ - part.motor.astype(np.float64)  # data units
    valid = valid_steps(part.valid_lengths, part.length)
    totals.add_errors(group, (error**2 * valid[..., None]).sum(axis=(0, 1)), int(valid.sum()))


class _Totals:
    """Sums over samples, per group (primitive): terms, θ gradients, code gradients, squared errors."""

    def __init__(self, n_groups: int, n_joints: int, parts: dict | None) -> None:
        self.n = np.zeros(n_groups, dtype=np.int64)
        self.terms = [{} for _ in range(n_groups)]  # name -> Σ_batches B · term
        self.mse = [{} for _ in range(n_groups)]
        self.parts = parts or {}
        sizes = [sum(p.numel() for p in ps) for ps in self.parts.values()]
        edges = np.cumsum([0, *sizes])
        self.slices = {name: slice(int(a), int(b)) for name, a, b in zip(self.parts, edges[:-1], edges[1:])}
        self.theta = [{} for _ in range(n_groups)]  # name -> Σ_batches B · ∇θ term (float64)
        self.codes = [{} for _ in range(n_groups)]  # name -> list of per-sample code gradients
        self.sq_error = np.zeros((n_groups, n_joints))
        self.steps = np.zeros(n_groups, dtype=np.int64)

    def add_terms(self, group: int, b: int, terms: dict, mse: dict) -> None:
        self.n[group] += b
        for name, value in terms.items():
            self.terms[group][name] = self.terms[group].get(name, 0.0) + b * value
        for name, value in mse.items():
            self.mse[group][name] = self.mse[group].get(name, 0.0) + b * value

    def add_gradients(self, group: int, name: str, b: int, theta: torch.Tensor, per_code: torch.Tensor) -> None:
        grad = theta.detach().double() * b
        have = self.theta[group].get(name)
        self.theta[group][name] = grad if have is None else have + grad
        self.codes[group].setdefault(name, []).append(per_code.detach().double())

    def add_errors(self, group: int, sq_error: np.ndarray, steps: int) -> None:
        self.sq_error[group] += sq_error
        self.steps[group] += steps


def _norms(vector: torch.Tensor, slices: dict) -> dict:
    out = {name: float(vector[s].norm()) for name, s in slices.items() if s.stop > s.start}
    out["all"] = float(vector.norm())
    return out


def _cosine(a: torch.Tensor, b: torch.Tensor) -> float | None:
    den = float(a.norm() * b.norm())
    return None if den == 0 else float(a @ b) / den


def _ratio(a: float, b: float) -> float | None:
    return None if b == 0 else a / b


def _gradient_summary(theta: dict, codes: dict, n: int, slices: dict) -> dict:
    """Norms and cosines of the θ gradients (``theta``: Σ B·∇, divided by ``n`` here) and the code gradients."""
    mean = {name: v / n for name, v in theta.items()}
    out = {"theta": {name: _norms(v, slices) for name, v in mean.items()}, "codes": {}}
    for name, parts in codes.items():
        out["codes"][name] = float(torch.cat(parts).norm(dim=1).mean())
    if "motor" in mean and "vision" in mean:
        m, v = mean["motor"], mean["vision"]
        shared = slices["dynamics"]
        out["theta"]["cosine"] = {"all": _cosine(m, v), "dynamics": _cosine(m[shared], v[shared])}
        out["theta"]["vision_over_motor"] = {
            part: _ratio(out["theta"]["vision"][part], out["theta"]["motor"][part]) for part in ("all", "dynamics")
        }
        cm, cv = torch.cat(codes["motor"]), torch.cat(codes["vision"])
        norms = cm.norm(dim=1) * cv.norm(dim=1)
        cos = (cm * cv).sum(dim=1) / norms.clamp_min(1e-300)
        out["codes"]["cosine"] = float(cos.mean())
        out["codes"]["vision_over_motor_median"] = float((cv.norm(dim=1) / cm.norm(dim=1).clamp_min(1e-300)).median())
    return out


def _terms_summary(terms: dict, mse: dict, n: int) -> dict:
    mean = {name: v / n for name, v in terms.items()}
    total = sum(mean.values())
    return {
        "terms": {**mean, "total": total},
        "vision_share": _ratio(mean.get("vision", 0.0), total),
        "mse": {name: v / n for name, v in mse.items()},
    }


def _group_summary(totals: _Totals, groups: list[int], half_range: np.ndarray) -> dict:
    """Terms, MSEs, motor RMS and gradients over the samples of ``groups``."""
    n = int(totals.n[groups].sum())
    terms, mse, theta, codes = {}, {}, {}, {}
    for g in groups:
        for name, value in totals.terms[g].items():
            terms[name] = terms.get(name, 0.0) + value
        for name, value in totals.mse[g].items():
            mse[name] = mse.get(name, 0.0) + value
        for name, value in totals.theta[g].items():
            theta[name] = value if name not in theta else theta[name] + value
        for name, value in totals.codes[g].items():
            codes.setdefault(name, []).extend(value)
    steps = int(totals.steps[groups].sum())
    sq = totals.sq_error[groups].sum(axis=0)
    out = {"n": n, **_terms_summary(terms, mse, n)}
    out["motor_rms"] = math.sqrt(sq.sum() / (steps * len(sq)))
    out["motor_rms_scaled"] = math.sqrt((sq / half_range**2).sum() / (steps * len(sq)))
    if theta:
        out["gradients"] = _gradient_summary(theta, codes, n, totals.slices)
    return out


def _summary(run, setup: dict, totals: _Totals, names: list[str], joints: list[str]) -> dict:
    """The JSON-ready result of :func:`loss_balance`."""
    tc, half = setup["tc"], setup["scaler"].half_range_
    present = [g for g in range(len(names)) if totals.n[g] > 0]
    overall = _group_summary(totals, present, half)
    rms = np.sqrt(totals.sq_error[present] / totals.steps[present][:, None])
    rms_all = np.sqrt(totals.sq_error[present].sum(axis=0) / totals.steps[present].sum())
    out = {
        "run": None if run.run_dir is None else str(run.run_dir),
        "kind": run.kind,
        "init": run.init,
        "epoch": run.epoch,
        "loss_reduction": tc.loss_reduction,
        "motor_weight": tc.motor_weight,
        "vision_weight": tc.vision_weight,
        "vision_frames_trained": tc.vision_frames,
        "precision": None if setup["model"].precision is None else setup["model"].precision.summary(),
        "observe": run.config.get("observe"),
        "images": bool(setup["use_images"]),
        "n_samples": overall.pop("n"),
        "primitives": [names[g] for g in present],
        "joints": list(joints),
        **overall,
        "per_primitive": {names[g]: _group_summary(totals, [g], half) for g in present},
        "joint_rms": {"values": rms.tolist(), "all": rms_all.tolist()},
        "joint_rms_scaled": {"values": (rms / half).tolist(), "all": (rms_all / half).tolist()},
    }
    if out["precision"] is not None:
        for part in (out, *out["per_primitive"].values()):
            part["vision_share"] = _weighed_share(part["mse"], out["precision"], tc)
    return out


def _weighed_share(mse: dict, precision: dict, tc) -> float | None:
    """Under ``"precision"``: the vision share of the weighed errors ``e^{-s_m} · w_m · MSE_m`` (the terms
    themselves hold ``½ s_m`` too, of either sign); None without vision."""
    if "vision" not in mse:
        return None
    motor = precision["motor"]["weight"] * tc.motor_weight * mse["motor"]
    vision = precision["vision"]["weight"] * tc.vision_weight * mse["vision"]
    return _ratio(vision, motor + vision)
