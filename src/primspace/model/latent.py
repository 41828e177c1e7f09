"""Latent codes: how they start (initialisation strategies) and how they are optimised.

Paper, *Initialization of Latent Vectors*. Each demonstration ``i`` has its own code
``z_i ∈ R^q``, a trainable parameter of the auto-decoder. The paper compares

* ``zero``: ``z_i = 0``;
* ``random``: ``z_i ~ N(0, I)``;
* ``projection`` (proposed): ``z_i = P m_{1:T}``, with ``m_{1:T}`` the scaled motor
  sequence flattened into one vector of length ``T·J`` and ``P_jk ~ N(0, 1/q)``
  (q x T·J). By the corollary of Whitney's embedding theorem (Sauer et al. 1991) almost
  every such map is one-to-one on a union of low-dimensional primitives when q > 2d,
  and by Appendix A it keeps scalar products on average, ``E[Pa·Pb] = a·b`` with
  ``Var[Pa·Pb] ≤ (3|a|²|b|² − (a·b)²)/q``;

and we add ``pca``, the data-dependent linear baseline: the centred sequence projected
on the top q principal directions of the training sequences.

**Sequences of codes** (``window = W``; the paper's *Summary and Discussion*: "extend
latent variable initialization algorithm by random linear projections to a sequence of
latent vectors. It can be done via one-dimensional convolution through time of a random
linear projection with long motor sequence."). The motor sequence is cut into K = ceil(T / W) windows of W
steps (the last one padded with the last step) and the same ``P`` (q x W·J,
``P_jk ~ N(0, 1/q)``) projects every window: ``z_k = P m_{kW+1:(k+1)W}``, a convolution
with kernel length and stride W. Appendix A then holds window by window:
``E[z_k(a)·z_k(b)] = a_k·b_k``. ``pca`` uses the principal directions of all training
windows pooled; ``zero`` and ``random`` fill the K codes alike.

:class:`LatentInitializer` holds the strategy and its fitted state (``P``, or the PCA
mean and components), which is saved with a run and reused for new data.
:class:`LatentTable` holds the codes of one data set together with their optimiser.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from primspace.utils.errors import UserError

__all__ = [
    "INIT_METHODS",
    "CALIBRATED",
    "CALIBRATABLE",
    "START_METHODS",
    "NEAREST",
    "INFER_STARTS",
    "LatentInitializer",
    "LatentTable",
    "appendix_a_check",
    "appendix_a_observed",
]

#: The initialisation strategies, in the order figures show them.
INIT_METHODS = ("zero", "random", "projection", "pca")

#: A start that needs a trained run: its initialiser's codes mapped by the run's
#: :class:`primspace.model.calibration.CodeCalibration` (runs fitted with projection or pca).
CALIBRATED = "calibrated"

#: The initialisers whose codes depend on the data, so a map from them to fitted codes means something.
CALIBRATABLE = ("projection", "pca")

#: Every way codes can start: the initialisers, the calibrated and the vision (train/vision_start.py) starts.
VISION_PROJECTION = "projection-vision"
START_METHODS = INIT_METHODS + (CALIBRATED, VISION_PROJECTION)

#: A start for inference only: the fitted code of the fitted demonstration whose (observed)
#: motor is nearest (:mod:`primspace.train.observe`); meaningful only with a fitted parent run.
NEAREST = "nearest"

#: The starts :func:`primspace.train.infer` accepts: every start, then ``nearest``.
INFER_STARTS = START_METHODS + (NEAREST,)


# ---------------------------------------------------------------------- initialiser


class LatentInitializer:
    """Initial latent codes ``z_i`` for motor sequences (scikit-learn style).

    Parameters
    ----------
    method : {"zero", "random", "projection", "pca"}
        ``zero``: all zeros. ``random``: i.i.d. N(0, 1). ``projection``: ``z = P m_{1:T}``
        with ``P_jk ~ N(0, 1/q)`` (the paper's proposal). ``pca``: ``z = V_q (m − mean)``
        with ``V_q`` the top q principal directions of the training sequences.
    latent_dim : int
        q.
    random_state : int
        Seed of ``P`` (projection) and of the draws (random).
    window : int, optional
        W: one code per window of W steps (codes ``(n, K·q)``, window-major); None: one
        code per sequence.

    Attributes
    ----------
    n_features_ : int
        T·J, the length of a flattened sequence, or W·J with a window (set by :meth:`fit`).
    projection_ : ndarray of shape (q, T·J)
        ``P`` (method ``projection``) or the principal directions as rows (``pca``; rows
        past the data's rank are zero).
    mean_ : ndarray of shape (T·J,)
        The training mean (``pca`` only; zeros otherwise).

    Notes
    -----
    Inputs are scaled motor sequences ``(n, T, J)`` (joints in [-1, 1],
    :class:`primspace.data.JointScaler`), flattened time-major: ``[m_1, m_2, ..., m_T]``.
    ``P`` depends on the seed and the shape only, never on the data.

    Examples
    --------
    >>> init = LatentInitializer("projection", latent_dim=4, random_state=0)
    >>> init.fit_transform(np.zeros((3, 5, 2))).shape
    (3, 4)
    """

    def __init__(
        self, method: str = "projection", latent_dim: int = 20, random_state: int = 0, window: int | None = None
    ) -> None:
        self.method = method
        self.latent_dim = latent_dim
        self.random_state = random_state
        self.window = window

    def _validate_params(self) -> None:
        if self.method not in INIT_METHODS:
            raise UserError(f"unknown latent init '{self.method}'; choose one of {', '.join(INIT_METHODS)}")
        if not isinstance(self.latent_dim, (int, np.integer)) or self.latent_dim < 1:
            raise UserError(f"latent size (latent_dim, --latent-dim) must be at least 1, got {self.latent_dim}")
        if self.window is not None and (not isinstance(self.window, (int, np.integer)) or self.window < 1):
            raise UserError(f"code window (window, --code-window) must be at least 1 step, got {self.window}")

    def get_params(self, deep: bool = True) -> dict:
        return {
            "method": self.method,
            "latent_dim": self.latent_dim,
            "random_state": self.random_state,
            "window": self.window,
        }

    # --------------------------------------------------------------------------- fit
    def fit(self, scaled_motor) -> LatentInitializer:
        """Draw ``P`` (projection) or find the principal directions (pca).

        Parameters
        ----------
        scaled_motor : array-like of shape (n, T, J)
            Training sequences, joints scaled to [-1, 1].
        """
        self._validate_params()
        x = self._rows(scaled_motor)
        q, k = int(self.latent_dim), x.shape[1]
        self.n_features_ = k
        self.mean_ = np.zeros(k)
        if self.method == "projection":
            rng = np.random.default_rng(self.random_state)
            self.projection_ = rng.normal(0.0, 1.0 / math.sqrt(q), size=(q, k))
        elif self.method == "pca":
            self.mean_ = x.mean(axis=0)
            _, _, vt = np.linalg.svd(x - self.mean_, full_matrices=False)
            vt = _fix_signs(vt)
            components = np.zeros((q, k))
            rank = min(q, vt.shape[0])
            components[:rank] = vt[:rank]
            self.projection_ = components
        else:
            self.projection_ = None
        return self

    def transform(self, scaled_motor, *, random_state: int | None = None, observed=None) -> np.ndarray:
        """Initial codes ``(n, q)`` (float32) for sequences ``(n, T, J)``.

        Parameters
        ----------
        scaled_motor : array-like of shape (n, T, J)
        random_state : int, optional
            Seed of the draws of method ``random`` (default: this initialiser's seed).
            Give a different one for a new data set so its codes are fresh draws.
        observed : array-like of bool, shape (n, T), optional
            The observed steps (inference from a prefix, :mod:`primspace.train.observe`):
            the codes of the observed part, ``P (M ⊙ (m − mean))`` with the unobserved
            steps set to zero after centring (``mean`` is 0 for ``projection``: ``P``
            applied to the zero-filled sequence, for which Appendix A holds,
            :func:`appendix_a_observed`). With a window the padded last steps copy the
            last step's mask as they copy its values. None: every step.
        """
        self._check_fitted()
        x = self._rows(scaled_motor)
        if x.shape[1] != self.n_features_:
            what = "W*J" if self.window is not None else "T*J"
            raise UserError(
                f"motor sequences have {what} = {x.shape[1]} values, the latent initialiser was fitted on {self.n_features_}"
            )
        n = len(scaled_motor)
        q = int(self.latent_dim) * (len(x) // n)  # a code per window (rows of x per sample), or one
        if self.method == "zero":
            z = np.zeros((n, q))
        elif self.method == "random":
            seed = self.random_state if random_state is None else random_state
            z = np.random.default_rng(seed).standard_normal((n, q))
        else:  # with a window: each window's code, window-major per sample
            centred = x - self.mean_
            if observed is not None:
                mask = np.broadcast_to(np.asarray(observed, dtype=np.float64)[..., None], np.shape(scaled_motor))
                centred = centred * self._rows(mask)
            z = (centred @ self.projection_.T).reshape(n, q)
        return z.astype(np.float32)

    def _rows(self, scaled_motor) -> np.ndarray:
        """What ``P`` multiplies: flattened sequences (n, T·J), or windows (n·K, W·J)."""
        x = np.asarray(scaled_motor, dtype=np.float64)
        if self.window is None or x.ndim != 3:
            return _flatten(x)
        w = int(self.window)
        k = -(-x.shape[1] // w)
        padded = np.concatenate([x, np.repeat(x[:, -1:], k * w - x.shape[1], axis=1)], axis=1)
        return padded.reshape(x.shape[0] * k, w * x.shape[2])

    def fit_transform(self, scaled_motor, *, random_state: int | None = None) -> np.ndarray:
        return self.fit(scaled_motor).transform(scaled_motor, random_state=random_state)

    def _check_fitted(self) -> None:
        if not hasattr(self, "n_features_"):
            raise UserError("LatentInitializer is not fitted; call fit first")

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict:
        """Everything needed to rebuild the fitted initialiser (``P`` included)."""
        self._check_fitted()
        return {
            "method": self.method,
            "latent_dim": int(self.latent_dim),
            "random_state": int(self.random_state),
            "window": None if self.window is None else int(self.window),
            "n_features": int(self.n_features_),
            "projection": None
            if self.projection_ is None
            else torch.from_numpy(np.ascontiguousarray(self.projection_)),
            "mean": torch.from_numpy(np.ascontiguousarray(self.mean_)),
        }

    @classmethod
    def from_state_dict(cls, state: dict) -> LatentInitializer:
        try:
            window = state.get("window")  # runs saved before code windows have none
            init = cls(
                state["method"],
                int(state["latent_dim"]),
                int(state["random_state"]),
                None if window is None else int(window),
            )
            init._validate_params()
            init.n_features_ = int(state["n_features"])
            proj = state["projection"]
            init.projection_ = None if proj is None else np.asarray(proj, dtype=np.float64)
            init.mean_ = np.asarray(state["mean"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"not a LatentInitializer state ({exc})") from None
        return init

    def __repr__(self) -> str:
        window = "" if self.window is None else f", window={self.window}"
        return f"LatentInitializer(method={self.method!r}, latent_dim={self.latent_dim}, random_state={self.random_state}{window})"


def _flatten(scaled_motor) -> np.ndarray:
    x = np.asarray(scaled_motor, dtype=np.float64)
    if x.ndim != 3:
        raise UserError(f"motor sequences must have shape (n, T, J), got {x.shape}")
    return x.reshape(x.shape[0], -1)


def _fix_signs(vt: np.ndarray) -> np.ndarray:
    """Make each principal direction's largest-magnitude entry positive (deterministic signs)."""
    idx = np.argmax(np.abs(vt), axis=1)
    signs = np.sign(vt[np.arange(vt.shape[0]), idx])
    signs[signs == 0] = 1.0
    return vt * signs[:, None]


# -------------------------------------------------------------------- the code table


class LatentTable:
    """The codes ``Z`` (N, q) of one data set and their optimiser (row-wise Adam).

    Each code is an independent parameter, as in an auto-decoder (DeepSDF). A
    mini-batch step updates only the codes of the samples in the batch, with Adam
    moments and bias correction kept per row: a code moves exactly as if it had its own
    ``torch.optim.Adam`` stepped each time its sample is drawn. (A dense Adam over the
    whole table would keep moving absent codes with stale momentum.) This is the
    paper's setting "every gradient step updates the entire θ, but only a fraction of
    {z_i}" (Initialization of Latent Vectors).

    Parameters
    ----------
    codes : Tensor (N, q)
        Initial codes (the table takes a float32 copy on their device).
    lr : float
        Learning rate of the codes.
    betas, eps : Adam's constants.
    optimizer : {"adam", "sgd"}
        ``"sgd"``: plain gradient descent, ``z_i ← z_i − lr ∇ℓ_i`` (``TrainConfig.optimizer``).
    """

    def __init__(
        self,
        codes: torch.Tensor,
        lr: float,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
        optimizer: str = "adam",
    ) -> None:
        self.codes = codes.detach().to(torch.float32).clone()
        self.exp_avg = torch.zeros_like(self.codes)
        self.exp_avg_sq = torch.zeros_like(self.codes)
        self.steps = torch.zeros(self.codes.shape[0], dtype=torch.float32, device=self.codes.device)
        self.lr = float(lr)
        self.betas = (float(betas[0]), float(betas[1]))
        self.eps = float(eps)
        if optimizer not in ("adam", "sgd"):
            raise ValueError(f"optimizer must be 'adam' or 'sgd', got {optimizer!r}")
        self.optimizer = optimizer

    def __len__(self) -> int:
        return self.codes.shape[0]

    def batch(self, idx: torch.Tensor) -> torch.Tensor:
        """The codes of rows ``idx`` as a fresh leaf tensor that collects gradients."""
        return self.codes.index_select(0, idx).requires_grad_(True)

    @torch.no_grad()
    def step(
        self, idx: torch.Tensor, grad: torch.Tensor, active: torch.Tensor | None = None, lr: torch.Tensor | None = None
    ) -> None:
        """One step (Adam, or SGD) on rows ``idx`` (unique) with their gradient ``grad`` (B, q);
        ``active`` (B,) bool: only those rows step (a padded batch, :mod:`primspace.train.captured`);
        ``lr``: a rate in a tensor (read when the step runs, as a CUDA graph needs) instead of :attr:`lr`."""
        lr = self.lr if lr is None else lr
        if self.optimizer == "sgd":
            self._descend(idx, grad, active, lr)
            return
        b1, b2 = self.betas
        m = self.exp_avg.index_select(0, idx).mul_(b1).add_(grad, alpha=1 - b1)
        v = self.exp_avg_sq.index_select(0, idx).mul_(b2).addcmul_(grad, grad, value=1 - b2)
        before = self.steps.index_select(0, idx)
        s = before + 1
        bias1 = 1 - torch.pow(b1, s)
        bias2_sqrt = torch.sqrt(1 - torch.pow(b2, s))
        denom = (v.sqrt() / bias2_sqrt.unsqueeze(1)).add_(self.eps)
        update = (m / denom).mul_((lr / bias1).unsqueeze(1))
        if active is not None:
            rows = active.unsqueeze(1)
            m = torch.where(rows, m, self.exp_avg.index_select(0, idx))
            v = torch.where(rows, v, self.exp_avg_sq.index_select(0, idx))
            s = torch.where(active, s, before)
            update = torch.where(rows, update, torch.zeros_like(update))
        self.exp_avg.index_copy_(0, idx, m)
        self.exp_avg_sq.index_copy_(0, idx, v)
        self.steps.index_copy_(0, idx, s)
        self.codes.index_add_(0, idx, update, alpha=-1.0)

    def _descend(self, idx: torch.Tensor, grad: torch.Tensor, active: torch.Tensor | None, lr) -> None:
        """Plain gradient descent of rows ``idx`` (``steps`` still counts each row's steps)."""
        update = grad * lr
        steps = self.steps.index_select(0, idx) + 1
        if active is not None:
            update = torch.where(active.unsqueeze(1), update, torch.zeros_like(update))
            steps = torch.where(active, steps, steps - 1)
        self.steps.index_copy_(0, idx, steps)
        self.codes.index_add_(0, idx, update, alpha=-1.0)

    def numpy(self) -> np.ndarray:
        """The codes as a float32 array (N, q) on the host."""
        return self.codes.detach().cpu().numpy().astype(np.float32, copy=True)

    def state_dict(self) -> dict:
        return {
            "codes": self.codes.cpu(),
            "exp_avg": self.exp_avg.cpu(),
            "exp_avg_sq": self.exp_avg_sq.cpu(),
            "steps": self.steps.cpu(),
            "lr": self.lr,
            "betas": list(self.betas),
            "eps": self.eps,
            "optimizer": self.optimizer,
        }

    @classmethod
    def from_state_dict(cls, state: dict, device: torch.device | str = "cpu") -> LatentTable:
        optimizer = state.get("optimizer", "adam")  # tables saved before primspace 0.9: Adam
        table = cls(state["codes"].to(device), state["lr"], tuple(state["betas"]), state["eps"], optimizer)
        table.exp_avg = state["exp_avg"].to(device, torch.float32).clone()
        table.exp_avg_sq = state["exp_avg_sq"].to(device, torch.float32).clone()
        table.steps = state["steps"].to(device, torch.float32).clone()
        return table


# ----------------------------------------------------------------------- Appendix A


def appendix_a_check(a, b, latent_dim: int, *, n_draws: int = 4000, random_state: int = 0, block: int = 250) -> dict:
    """Check the paper's Appendix A numerically for one pair of vectors.

    Draws ``n_draws`` matrices ``P`` (q x k) with ``P_ij ~ N(0, 1/q)`` and returns the
    sample mean and variance of ``Pa·Pb`` against the paper's claims

    * ``E[Pa·Pb] = a·b`` (eq. ``exp_prod``), and
    * ``Var[Pa·Pb] ≤ (3|a|²|b|² − (a·b)²)/q`` (eq. ``var_prod``),

    and against the exact variance for Gaussian ``P``, ``(|a|²|b|² + (a·b)²)/q`` (each of
    the q terms ``(Pa)_j (Pb)_j`` is a product of jointly normal variables with variances
    ``|a|²/q``, ``|b|²/q`` and covariance ``a·b/q``). The bound is tight when ``a ∥ b``.

    Parameters
    ----------
    a, b : array-like of shape (k,)
    latent_dim : int
        q.
    n_draws : int
        Number of independent ``P``.
    random_state : int
    block : int
        Draws generated at once (memory: ``block · q · k`` floats).

    Returns
    -------
    dict
        ``dot`` (a·b), ``mean``, ``mean_stderr`` (standard error of the mean), ``var``
        (sample variance), ``var_exact``, ``var_bound``, ``mean_z`` (deviation of the
        mean in standard errors), ``n_draws``, ``latent_dim``.
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1)
    b = np.asarray(b, dtype=np.float64).reshape(-1)
    if a.shape != b.shape:
        raise UserError(f"a and b must have the same length, got {a.size} and {b.size}")
    q = int(latent_dim)
    if q < 1 or n_draws < 2:
        raise UserError("latent_dim must be >= 1 and n_draws >= 2")
    rng = np.random.default_rng(random_state)
    ab = np.stack([a, b], axis=1)  # (k, 2)
    products = np.empty(n_draws)
    for start in range(0, n_draws, block):
        m = min(block, n_draws - start)
        P = rng.normal(0.0, 1.0 / math.sqrt(q), size=(m, q, a.size))
        proj = P @ ab  # (m, q, 2): Pa and Pb
        products[start : start + m] = np.einsum("mq,mq->m", proj[..., 0], proj[..., 1])
    dot, na2, nb2 = float(a @ b), float(a @ a), float(b @ b)
    mean, var = float(products.mean()), float(products.var(ddof=1))
    stderr = math.sqrt(var / n_draws)
    return {
        "dot": dot,
        "mean": mean,
        "mean_stderr": stderr,
        "mean_z": (mean - dot) / stderr if stderr > 0 else 0.0,
        "var": var,
        "var_exact": (na2 * nb2 + dot**2) / q,
        "var_bound": (3 * na2 * nb2 - dot**2) / q,
        "n_draws": int(n_draws),
        "latent_dim": q,
    }


def appendix_a_observed(a, b, observed, latent_dim: int, **kwargs) -> dict:
    """Appendix A for the observed part of two sequences (inference from a prefix).

    With ``M`` the observation mask, ``a_obs = M ⊙ a`` and ``b_obs = M ⊙ b`` are the
    sequences with their unobserved steps set to zero, and the start of inference from
    what was observed is ``P a_obs`` (:meth:`LatentInitializer.transform` with
    ``observed``). Appendix A holds for any pair of vectors, so for these:
    ``E[P a_obs · P b_obs] = a_obs · b_obs`` (eq. ``exp_prod``) and
    ``Var ≤ (3|a_obs|²|b_obs|² − (a_obs·b_obs)²)/q`` (eq. ``var_prod``). Scalar products
    of the observed parts, not of the whole motions, are what the start keeps.

    Parameters
    ----------
    a, b : array-like of shape (T, J) or (T,)
        Two sequences (time first).
    observed : array-like of bool, shape (T,)
        The observed steps.
    latent_dim : int
        q.
    **kwargs
        Passed to :func:`appendix_a_check` (``n_draws``, ``random_state``, ``block``).

    Returns
    -------
    dict
        :func:`appendix_a_check`'s, for ``a_obs`` and ``b_obs``.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    m = np.asarray(observed, dtype=np.float64)
    if a.shape != b.shape or m.shape != a.shape[:1]:
        raise UserError(f"a {a.shape}, b {b.shape} and observed {m.shape} must share their first axis (steps)")
    m = m.reshape(m.shape + (1,) * (a.ndim - 1))
    return appendix_a_check(a * m, b * m, latent_dim, **kwargs)
