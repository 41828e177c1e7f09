"""`LowRankSubspaceClustering`: the paper's affine low-rank subspace clustering as an estimator.

Paper, Background (Linear Subspace Clustering; Affine Subspace Clustering): the closed form
``Q* = V P(Lambda) V^T`` of the relaxed low-rank representation (Vidal & Favaro 2014), then
spectral clustering of ``Q*``. See :mod:`primspace.cluster.lrsc` for the algebra and the
definition of R^2, :mod:`primspace.cluster.spectral` for the spectral step and its implicit
route that scales to millions of points.
"""

from __future__ import annotations

import contextlib
import threading
from dataclasses import dataclass
from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator, ClusterMixin
from sklearn.utils import check_array, check_random_state
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import validate_data
from threadpoolctl import threadpool_limits

from primspace.cluster.auto import AUTO_CRITERIA, DEFAULT_AUTO_CRITERION, choose_tau
from primspace.cluster.lrsc import SelfRepresentationSVD, self_representation_svd
from primspace.cluster.select import SELECT, select_r2_target
from primspace.cluster.spectral import (
    choose_spectral_method,
    njw_labels,
    spectral_embedding,
    spectral_embedding_dense,
)
from primspace.utils.errors import UserError

__all__ = ["LowRankSubspaceClustering", "DEFAULT_R2_TARGET", "DEFAULT_TAU_CHOICE"]

#: The fixed R^2 target: the first candidate of the held-out selection (and its tie winner).
#: On LASA (26 shapes) any target in [0.97, 0.999] clusters with accuracy >= 0.95; 0.9999
#: over-fits the noise.
DEFAULT_R2_TARGET = 0.99

#: How tau is chosen when none of tau, tau_relative, r2_target is given: by held-out
#: evidence among the fixed targets and the label-free choice (:mod:`primspace.cluster.select`).
DEFAULT_TAU_CHOICE = SELECT


class LowRankSubspaceClustering(ClusterMixin, BaseEstimator):
    """Affine (or linear) low-rank subspace clustering with an NJW spectral step.

    Rows of ``X`` are the points (scikit-learn convention); the paper's data matrix ``Z`` has
    them as columns, ``Z = X^T``. The estimator computes the closed-form self-representation
    ``Q* = V P(Lambda) V^T`` of ``Z~ = [Z; ones_weight 1^T]`` (affine) or ``Z`` (linear),
    ``P(x) = 1 - 1/(tau x^2)`` for ``x > 1/sqrt(tau)`` else 0 (paper, eq. ``self_expression``),
    and clusters its affinity ``Q* o Q*`` (or ``|Q*|``) with Ng-Jordan-Weiss spectral
    clustering: normalised affinity ``D^-1/2 W D^-1/2``, its top k eigenvectors, rows scaled
    to unit length, k-means with ``n_init`` restarts.

    Parameters
    ----------
    n_clusters : int
        K, the number of subspaces (>= 1).
    affine : bool, default True
        Affine subspaces (append the ones row, paper: Affine Subspace Clustering); False:
        linear subspaces through the origin.
    tau : float, optional
        The paper's tau (> 0), absolute: it depends on the data's scale.
    tau_relative : float, optional
        Scale-free tau: ``tau = tau_relative / sigma_1^2`` (``sigma_1`` the top singular value
        of ``Z~``). ``P`` depends on ``tau sigma^2`` only, so a component is kept iff
        ``sigma_k / sigma_1 > 1 / sqrt(tau_relative)``. In the affine case scaling the data by
        c keeps the result only if ``ones_weight`` is scaled by c too.
    r2_target : float, "auto" or "select", optional
        Choose tau as the smallest one whose R^2 of ``Z ~ Z Q*`` reaches this value, in (0, 1)
        (how the paper chose tau). R^2 = 1 - ||Z - Z Q*||_F^2 / ||Z - mean||_F^2 over the data
        rows (the ones row does not count); see :mod:`primspace.cluster.lrsc`. ``"auto"``:
        choose the target of :data:`~primspace.cluster.auto.AUTO_R2_GRID` that scores best by
        ``auto_criterion``, without labels (:mod:`primspace.cluster.auto`). ``"select"``:
        compare the fixed targets (0.99, 0.7) and the ``"auto"`` choice by their held-out
        stability and keep the best, without labels (:mod:`primspace.cluster.select`). Give at
        most one of tau, tau_relative, r2_target; with none, ``r2_target = "select"``.
    auto_criterion : {"relative_eigengap", "eigengap", "stability"}, default "relative_eigengap"
        The label-free criterion of ``r2_target="auto"`` and of the ``"auto"`` candidate of
        ``"select"`` (ignored otherwise): the eigengap at
        k of the normalised affinity relative to ``1 - lambda_{k+1}``, the plain eigengap
        ``lambda_k - lambda_{k+1}``, or the stability of the labels across subsamples
        (:mod:`primspace.cluster.auto`).
    affinity : {"squared", "abs"}, default "squared"
        ``W = Q* o Q*`` (low rank: scales to millions of points) or ``|Q*|`` (dense only).
    ones_weight : float, default 1.0
        Value of the appended ones row (affine only); the paper's homogeneous coordinates use
        1. Larger values enforce the affine constraint more strongly relative to the data.
    spectral : {"auto", "dense", "implicit"}, default "auto"
        "dense" forms ``Q*`` and ``W`` (n x n, at most 10 000 points; ``Q*`` is then kept in
        ``self_representation_``). "implicit" never forms an n x n matrix (affinity "squared"
        only): degrees and products come from the low-rank factor of ``Q*``. "auto" is dense
        up to 2000 points or for affinity "abs", implicit above.
    n_init : int, default 20
        k-means restarts.
    random_state : int, RandomState or None
        Seeds k-means (and ARPACK's start vector where ARPACK is used).

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,), int64
        Cluster of each point, in ``0..n_clusters-1``.
    singular_values_ : ndarray of shape (s,)
        Singular values of ``Z~`` (descending; rounding-level values are 0).
    tau_ : float
        The absolute tau used.
    tau_relative_ : float
        ``tau_ * singular_values_[0]^2``.
    rank_ : int
        Rank of ``Q*``: the number of singular values above ``1/sqrt(tau_)``.
    r2_ : float
        R^2 of ``Z ~ Z Q*`` (NaN if all points are identical).
    representation_factor_ : ndarray of shape (n_samples, rank_)
        ``F = V_r sqrt(P_r)`` with ``Q* = F F^T``: any block of ``Q*`` or of the affinity
        follows from it (:func:`primspace.cluster.affinity_from_factor`).
    self_representation_ : ndarray of shape (n_samples, n_samples) or None
        ``Q*`` when the dense route formed it, else None.
    eigenvalues_ : ndarray of shape (k,)
        Top eigenvalues of ``D^-1/2 W D^-1/2`` (k <= n_clusters; see
        :mod:`primspace.cluster.spectral`).
    spectral_method_ : str
        "dense", "gram" or "lobpcg" (the last two implicit: see :mod:`primspace.cluster.spectral`).
    auto_choice_ : AutoTauChoice or None
        With ``r2_target="auto"`` or ``"select"``: every grid target's tau, R^2, rank and
        label-free score, and the one the criterion chose
        (:class:`~primspace.cluster.auto.AutoTauChoice`); else None.
    auto_scores_ : ndarray of shape (n_candidates,) or None
        ``auto_choice_.scores``: the criterion's score per candidate (NaN: ``Q* = 0``).
    selection_ : TauSelection or None
        With ``r2_target="select"``: the candidates, their held-out scores and the one chosen
        (:class:`~primspace.cluster.select.TauSelection`); else None.
    n_features_in_ : int

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> lines = [c + t[:, None] * v for c, v, t in
    ...          [(rng.normal(size=3), rng.normal(size=3), rng.normal(size=20)) for _ in range(2)]]
    >>> X = np.vstack(lines)
    >>> model = LowRankSubspaceClustering(2, tau_relative=1e6, random_state=0).fit(X)
    >>> bool(np.all(model.labels_[:20] == model.labels_[0]) and model.labels_[0] != model.labels_[20])
    True

    References
    ----------
    Nikulin & Tani, *Initialization of Latent Space Coordinates via Random Linear Projections
    for Learning Robotic Sensory-Motor Sequences*, Background. Vidal & Favaro, *Low rank
    subspace clustering (LRSC)*, Pattern Recognition Letters 43, 2014. Ng, Jordan & Weiss,
    *On spectral clustering: analysis and an algorithm*, NIPS 2001.
    """

    _parameter_constraints: dict = {
        "n_clusters": [Interval(Integral, 1, None, closed="left")],
        "affine": ["boolean"],
        "tau": [Interval(Real, 0, None, closed="neither"), None],
        "tau_relative": [Interval(Real, 0, None, closed="neither"), None],
        "r2_target": [Interval(Real, 0, 1, closed="neither"), StrOptions({"auto", "select"}), None],
        "auto_criterion": [StrOptions(set(AUTO_CRITERIA))],
        "affinity": [StrOptions({"squared", "abs"})],
        "ones_weight": [Interval(Real, 0, None, closed="neither")],
        "spectral": [StrOptions({"auto", "dense", "implicit"})],
        "n_init": [Interval(Integral, 1, None, closed="left")],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        n_clusters,
        *,
        affine=True,
        tau=None,
        tau_relative=None,
        r2_target=None,
        auto_criterion=DEFAULT_AUTO_CRITERION,
        affinity="squared",
        ones_weight=1.0,
        spectral="auto",
        n_init=20,
        random_state=None,
    ):
        self.n_clusters = n_clusters
        self.affine = affine
        self.tau = tau
        self.tau_relative = tau_relative
        self.r2_target = r2_target
        self.auto_criterion = auto_criterion
        self.affinity = affinity
        self.ones_weight = ones_weight
        self.spectral = spectral
        self.n_init = n_init
        self.random_state = random_state

    def fit(self, X, y=None, *, svd=None):
        """Cluster the rows of ``X``.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)
            Points as rows; finite.
        y : ignored

        Other Parameters
        ----------------
        svd : SelfRepresentationSVD, optional
            The decomposition of ``Z~`` for this ``X``, from :meth:`decompose` (or
            :func:`~primspace.cluster.self_representation_svd` with this estimator's
            ``affine`` and ``ones_weight``). Fits that differ only in tau share one SVD this
            way, as :func:`~primspace.cluster.tau_sweep` does; the result is the same as
            without it. Only its size and settings are checked against ``X``.

        Returns
        -------
        self

        Raises
        ------
        ValueError
            Invalid parameters, NaN/inf, 1-D input, fewer than 2 points or fewer points than
            clusters, all points identical, values too large or too close for float64
            (:func:`check_scale`: scale the points), two tau options at once, a tau that
            keeps no component, or an ``svd`` of other points or other settings.
        """
        X, tau_option = self._check_fit_input(X, reset=True)
        with small_problem_threads(X.shape[0]):
            if svd is None:
                svd = self_representation_svd(X, affine=self.affine, ones_weight=self.ones_weight)
            else:
                self._check_svd(svd, X.shape[0])
            tau, choice, selection = self._choose_tau(X, svd, tau_option)
            del X
            result = cluster_at_tau(
                svd,
                tau,
                n_clusters=self.n_clusters,
                affinity=self.affinity,
                spectral=self.spectral,
                n_init=self.n_init,
                random_state=self.random_state,
            )
        self.labels_ = result.labels
        self.singular_values_ = svd.singular_values
        self.tau_ = result.tau
        self.tau_relative_ = result.tau * svd.top_singular_value**2
        self.rank_ = result.rank
        self.r2_ = result.r2
        self.representation_factor_ = result.factor
        self.self_representation_ = result.self_representation
        self.eigenvalues_ = result.eigenvalues
        self.spectral_method_ = result.method
        self.auto_choice_ = choice
        self.auto_scores_ = None if choice is None else choice.scores
        self.selection_ = selection
        return self

    def _choose_tau(self, X, svd, tau_option):
        """``(tau, auto choice or None, selection or None)`` for the fit's tau option."""
        if tau_option[1] not in (AUTO, SELECT):
            return resolve_tau(svd, *tau_option), None, None
        choice = choose_tau(
            svd,
            self.n_clusters,
            criterion=self.auto_criterion,
            affinity=self.affinity,
            spectral=self.spectral,
            n_init=self.n_init,
            random_state=self.random_state,
        )
        if tau_option[1] == AUTO:
            return choice.tau, choice, None
        selection = select_r2_target(
            X,
            self.n_clusters,
            choice.to_dict(),
            self._labels_alone,
            rank_of=lambda target: svd.rank(svd.tau_for_r2(target)),
            random_state=self.random_state,
        )
        return svd.tau_for_r2(selection.r2_target), choice, selection

    def _labels_alone(self, X, r2_target: float) -> np.ndarray:
        """The labels of a fit of these points alone at ``r2_target`` (held-out selection)."""
        check_scale(X, X.shape[1] + 1 if self.affine else X.shape[1])
        svd = self_representation_svd(X, affine=self.affine, ones_weight=self.ones_weight)
        return cluster_at_tau(
            svd,
            svd.tau_for_r2(r2_target),
            n_clusters=self.n_clusters,
            affinity=self.affinity,
            spectral=self.spectral,
            n_init=self.n_init,
            random_state=self.random_state,
        ).labels

    def decompose(self, X) -> SelfRepresentationSVD:
        """The SVD of ``Z~`` that :meth:`fit` would compute for ``X``, to share between fits.

        Everything tau-dependent follows from this one decomposition
        (:mod:`primspace.cluster.lrsc`), so fits of ``X`` that differ only in ``tau``,
        ``tau_relative`` or ``r2_target`` can pass it as ``fit(X, svd=...)`` and skip the
        SVD: how :func:`~primspace.cluster.tau_sweep` computes one SVD per sweep. Parameters
        and ``X`` are validated as :meth:`fit` validates them; the estimator is not fitted.

        Parameters
        ----------
        X : array-like of shape (n_samples, n_features)

        Returns
        -------
        SelfRepresentationSVD
        """
        X, _ = self._check_fit_input(X, reset=False)
        with small_problem_threads(X.shape[0]):
            return self_representation_svd(X, affine=self.affine, ones_weight=self.ones_weight)

    def _check_fit_input(self, X, *, reset: bool) -> tuple[np.ndarray, tuple[str, float]]:
        """Parameters, then ``X`` (float64, >= 2 rows, >= n_clusters rows), then the tau option.

        ``reset``: record ``n_features_in_`` (fit); else leave the estimator unfitted.
        """
        self._validate_params()
        if reset:
            X = validate_data(self, X, dtype=np.float64, ensure_min_samples=2)
        else:
            X = check_array(X, dtype=np.float64, ensure_min_samples=2, estimator=self)
        n_samples = X.shape[0]
        if n_samples < self.n_clusters:
            raise UserError(f"n_samples={n_samples} should be >= n_clusters={self.n_clusters}")
        check_scale(X, X.shape[1] + 1 if self.affine else X.shape[1])
        return X, tau_option_from(self.tau, self.tau_relative, self.r2_target)

    def _check_svd(self, svd, n_samples: int) -> None:
        if not isinstance(svd, SelfRepresentationSVD):
            raise UserError(f"svd must be a SelfRepresentationSVD (from decompose), got {type(svd).__name__}")
        settings = (bool(self.affine), float(self.ones_weight) if self.affine else None)
        if (svd.affine, svd.ones_weight if svd.affine else None) != settings or svd.n_samples != n_samples:
            raise UserError(
                f"svd is of {svd.n_samples} points with affine={svd.affine}, ones_weight={svd.ones_weight}; "
                f"this fit has {n_samples} points with affine={self.affine}, ones_weight={self.ones_weight}: "
                "use decompose(X) of this estimator"
            )


def check_scale(X: np.ndarray, n_columns: int) -> None:
    """Refuse points the closed form cannot handle in float64, with the reason, in one line.

    All rows equal: nothing to cluster (R^2 is undefined). Values whose squares summed over
    the ``n_samples x n_columns`` matrix overflow float64 (about 1e154 / sqrt(entries)), or
    differences between points whose squares underflow (below about 1e-153): the SVD, R^2
    and tau would be inf, 0 or NaN, so scaling the points is the fix, named as such.
    """
    spread = float(np.max(X.max(axis=0) - X.min(axis=0))) if X.size else 0.0
    largest = float(np.max(np.abs(X))) if X.size else 0.0
    limit = float(np.sqrt(np.finfo(np.float64).max / max(1, X.shape[0] * n_columns))) / 16
    if not np.isfinite(spread) or largest > limit:
        raise UserError(
            f"point values up to {largest:.3g} are too large: their squares overflow float64 (keep them below "
            f"{limit:.3g} for {X.shape[0]} x {n_columns} values); scale the points down, e.g. divide by {largest:.0e}"
        )
    if spread == 0:
        raise UserError(f"all {X.shape[0]} points are identical: there is nothing to cluster")
    smallest = float(np.sqrt(np.finfo(np.float64).tiny)) * 16
    if spread < smallest:
        raise UserError(
            f"the points differ by at most {spread:.3g}: too small, their squares underflow float64 (need "
            f"differences above {smallest:.3g}); scale the points up, e.g. divide by {spread:.0e}"
        )


# ------------------------------------------------------- shared with tau_sweep()

#: Up to this many points the fit runs on one BLAS/OpenMP thread: threads cost more than they
#: give on small problems, and far more on a busy machine (measured on 2 cores under load:
#: 182 LASA points took 1.2-3.2 s with 2 threads, 0.17 s with 1).
SINGLE_THREAD_MAX_SAMPLES = 20_000


_single_thread = threading.local()  # inside small_problem_threads' limit, in this thread


@contextlib.contextmanager
def small_problem_threads(n_samples: int):
    """A context that limits BLAS and OpenMP to one thread for small problems (else no-op).

    Nested uses inside an active limit are no-ops: entering ``threadpool_limits`` costs about
    1 ms (it inspects the loaded libraries), once per fit of a tau sweep otherwise.
    """
    if n_samples > SINGLE_THREAD_MAX_SAMPLES or getattr(_single_thread, "active", False):
        yield
        return
    with threadpool_limits(limits=1):
        _single_thread.active = True
        try:
            yield
        finally:
            _single_thread.active = False


#: The ``r2_target`` that chooses tau without labels (:mod:`primspace.cluster.auto`).
AUTO = "auto"


def tau_option_from(tau, tau_relative, r2_target) -> tuple[str, float | str]:
    """The one tau option given, as ``(kind, value)``; ``("r2_target", "select")`` if none,
    ``("r2_target", "auto")`` for the label-free choice."""
    given = [
        (k, v) for k, v in (("tau", tau), ("tau_relative", tau_relative), ("r2_target", r2_target)) if v is not None
    ]
    if len(given) > 1:
        raise UserError(f"give at most one of tau, tau_relative, r2_target; got {', '.join(k for k, _ in given)}")
    kind, value = given[0] if given else ("r2_target", DEFAULT_TAU_CHOICE)
    if kind == "r2_target" and isinstance(value, str):
        if value not in (AUTO, SELECT):
            raise UserError(f"r2_target must be a number in (0, 1), {AUTO!r} or {SELECT!r}, got {value!r}")
        return kind, value
    if kind == "r2_target":
        if not 0 < value < 1:
            raise UserError(f"r2_target must lie in (0, 1), got {value}")
    elif not (np.isfinite(value) and value > 0):
        raise UserError(f"{kind} must be a positive number, got {value}")
    return kind, float(value)


def resolve_tau(svd: SelfRepresentationSVD, kind: str, value: float) -> float:
    """Absolute tau from ``("tau" | "tau_relative" | "r2_target", value)``."""
    if kind == "tau":
        return value
    if kind == "tau_relative":
        return svd.tau_from_relative(value)
    return svd.tau_for_r2(value)


@dataclass(frozen=True, eq=False)
class TauClustering:
    """What one tau gives: labels, rank, R^2, the factor of Q*, and the spectral details."""

    tau: float
    rank: int
    r2: float
    factor: np.ndarray
    self_representation: np.ndarray | None
    eigenvalues: np.ndarray
    method: str
    labels: np.ndarray


def cluster_at_tau(
    svd: SelfRepresentationSVD,
    tau: float,
    *,
    n_clusters: int,
    affinity: str = "squared",
    spectral: str = "auto",
    n_init: int = 20,
    random_state=None,
) -> TauClustering:
    """Closed form at ``tau``, then the NJW spectral step.

    Raises
    ------
    UserError
        If tau keeps no component (``Q* = 0``).
    """
    rank = svd.rank(tau)
    if rank == 0:
        top = svd.top_singular_value
        need = f"tau > 1/sigma_1^2 = {1 / top**2:.4g}" if top > 0 else "nonzero data"
        raise UserError(f"tau={tau:.4g} keeps no component of Q* (every singular value <= 1/sqrt(tau)); need {need}")
    rng = check_random_state(random_state)
    kmeans_seed, arpack_seed = (int(s) for s in rng.randint(np.iinfo(np.int32).max, size=2))
    factor = svd.factor(tau)
    n = factor.shape[0]
    method = choose_spectral_method(n, rank, affinity, spectral)
    q = None
    if method == "dense":
        q = factor @ factor.T
        w = np.square(q) if affinity == "squared" else np.abs(q)
        embedding = spectral_embedding_dense(w, n_clusters, random_state=arpack_seed)
        del w
    else:
        embedding = spectral_embedding(factor, n_clusters, affinity=affinity, method=method, random_state=arpack_seed)
    labels = njw_labels(embedding.vectors, n_clusters, n_init=n_init, random_state=kmeans_seed)
    return TauClustering(
        tau=float(tau),
        rank=rank,
        r2=svd.r2(tau),
        factor=factor,
        self_representation=q,
        eigenvalues=embedding.eigenvalues,
        method=embedding.method,
        labels=labels,
    )
