"""Low-rank self-representation in closed form (paper, Background: Linear / Affine Subspace
Clustering).

Notation (paper): the columns of ``Z`` are the points. Here, as in scikit-learn, the *rows*
of ``X`` are the points, so ``Z = X^T``. In the affine case a row of ones, weighted by
``ones_weight``, is appended to ``Z`` (homogeneous coordinates), which turns the affine
constraint ``1^T C = 1^T`` into the linear one ``Z~ = Z~ C``.

With the skinny SVD ``Z~ = U Lambda V^T`` (``V`` is n x r: one row per point), the paper's
closed form (eq. ``self_expression``) is::

    Q* = V P(Lambda) V^T,   P(x) = 1 - 1/(tau x^2) for x > 1/sqrt(tau), else 0.

This ``P`` is the minimiser of ``||C||_* + (tau/2) ||Z - Z C||_F^2`` s.t. ``C = C^T`` (Vidal &
Favaro 2014; per singular direction ``|c| + (tau/2) lambda^2 (1 - c)^2`` is minimal at
``c = 1 - 1/(tau lambda^2)``). The paper's eq. ``relaxed_optim`` prints the weight as
``1/tau``, whose minimiser would be ``1 - tau/(2 lambda^2)``; we implement the closed form
the paper states and used (its tau values 0.05-0.2 refer to it), and test it as the
minimiser of the ``tau/2`` objective.

Everything that depends on ``tau`` follows from one SVD: the shrinkage ``P``, the rank, the
goodness of fit ``R^2`` of ``Z ~ Z Q*`` and the factor ``F = V_r sqrt(P_r)`` with
``Q* = F F^T``. :class:`SelfRepresentationSVD` holds that SVD; choosing ``tau`` for a target
``R^2`` is an exact, closed-form search over the singular values (:func:`tau_for_r2`).

Definition of R^2
-----------------
``R^2 = 1 - ||Z - Z Q*||_F^2 / ||Z - zbar 1^T||_F^2``, the coefficient of determination of
the reconstruction of every coordinate of the data over the n points (``zbar`` is the mean
point). Only the data rows count: in the affine case the appended ones row is a constraint,
not data, and its arbitrary weight would otherwise change R^2. The denominator is centred, as
the coefficient of determination is by definition (the paper chose tau by "coefficient of
determination R^2 for reconstruction of trajectories"); an uncentred denominator would be
dominated by the mean trajectory and put R^2 near 1 for any tau. Because
``Z~ - Z~ Q* = U Lambda (I - P) V^T``, the residual of the data rows is::

    ||Z - Z Q*||_F^2 = sum_k  w_k lambda_k^2 (1 - p_k)^2,   w_k = 1 - U[ones, k]^2

(``w_k = 1`` in the linear case), so R^2 costs O(d) per tau once the SVD is known. R^2 is
continuous and non-decreasing in tau, so "the smallest tau whose R^2 reaches a target" is
well defined; on each interval between consecutive thresholds ``1/lambda_k^2`` the residual
is ``A/tau^2 + B`` and the search is solved exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from primspace.utils.errors import UserError

__all__ = [
    "R2_GRID",
    "SelfRepresentationSVD",
    "self_representation_svd",
    "shrinkage",
    "r2_from_singular_values",
    "tau_for_r2",
]

# Above this many matrix entries, a tall Z~ (n >= 10 p) is decomposed through its p x p Gram
# matrix, without copying Z~: 0.75 s against 4.7 s for LAPACK's SVD at n = 1e6, p = 41.
#: The R^2 grid, the one place it is written: R^2 targets (scale-free, and how the paper
#: picked tau). ``primspace cluster --sweep`` and the clustering experiment sweep it
#: (:mod:`primspace.cluster.sweep`); ``r2_target="auto"`` chooses among it
#: (:mod:`primspace.cluster.auto`).
R2_GRID = (0.5, 0.7, 0.8, 0.85, 0.9, 0.95, 0.99, 0.995, 0.999, 0.9999)

_GRAM_SVD_MIN_ENTRIES = 2_000_000
_GRAM_SVD_ROW_BLOCK = 65_536


def shrinkage(singular_values, tau: float) -> np.ndarray:
    """The paper's ``P(x)``: ``1 - 1/(tau x^2)`` for ``x > 1/sqrt(tau)``, else 0.

    Parameters
    ----------
    singular_values : array-like of shape (s,)
        ``lambda_k >= 0``.
    tau : float
        The relaxation parameter of the paper's problem (``relaxed_optim``), ``> 0``.

    Returns
    -------
    p : ndarray of shape (s,)
        ``P(lambda_k)`` in ``[0, 1)``.
    """
    lam = np.asarray(singular_values, dtype=np.float64)
    if not (np.isfinite(tau) and tau > 0):
        raise UserError(f"tau must be a positive number, got {tau}")
    x2 = tau * lam * lam
    with np.errstate(divide="ignore"):
        return np.where(x2 > 1.0, 1.0 - 1.0 / np.where(x2 > 1.0, x2, 1.0), 0.0)


def _residual(lam, weights, tau) -> float:
    p = shrinkage(lam, tau)
    return float(np.sum(weights * (lam * (1.0 - p)) ** 2))


def _weights_total(lam, data_share, total_sum_squares):
    weights = np.ones_like(lam) if data_share is None else np.asarray(data_share, dtype=np.float64)
    total = float(np.sum(lam * lam)) if total_sum_squares is None else float(total_sum_squares)
    return weights, total


def r2_from_singular_values(singular_values, tau: float, data_share=None, total_sum_squares=None) -> float:
    """R^2 of ``Z ~ Z Q*`` from the SVD alone (see the module docstring).

    Parameters
    ----------
    singular_values : array-like of shape (s,)
        Singular values of the matrix that is self-represented.
    tau : float
        The paper's tau (absolute).
    data_share : array-like of shape (s,), optional
        ``w_k``, the share of singular vector k's energy in the data rows (``1 - U[ones, k]^2``
        in the affine case). Default 1 (every row is data).
    total_sum_squares : float, optional
        The denominator of R^2. Default ``sum lambda^2`` (R^2 relative to the squared norm of
        the matrix itself); :class:`SelfRepresentationSVD` passes the centred sum of squares.

    Returns
    -------
    float
    """
    lam = np.asarray(singular_values, dtype=np.float64)
    weights, total = _weights_total(lam, data_share, total_sum_squares)
    if total <= 0:
        return float("nan")
    return 1.0 - _residual(lam, weights, tau) / total


def tau_for_r2(singular_values, target: float, data_share=None, total_sum_squares=None) -> float:
    """The smallest tau whose R^2 of ``Z ~ Z Q*`` reaches ``target`` (exact, O(s)).

    R^2(tau) is continuous and non-decreasing. Between consecutive thresholds
    ``1/lambda_j^2 < tau <= 1/lambda_{j+1}^2`` the kept components are ``1..j`` and the residual
    is ``A_j / tau^2 + B_j`` with ``A_j = sum_{k<=j} w_k / lambda_k^2`` and
    ``B_j = sum_{k>j} w_k lambda_k^2``; the first interval whose right end reaches the target
    holds the answer ``tau = sqrt(A_j / (R - B_j))`` with ``R = (1 - target) * total``.

    Parameters
    ----------
    singular_values : array-like of shape (s,)
    target : float
        In (0, 1).
    data_share, total_sum_squares : optional
        As in :func:`r2_from_singular_values`.

    Returns
    -------
    float

    Raises
    ------
    UserError
        If ``target`` is outside (0, 1), or it is reached with no component kept (Q* = 0).
    """
    if not (0.0 < target < 1.0):
        raise UserError(f"the R^2 target must lie in (0, 1), got {target}")
    lam = np.asarray(singular_values, dtype=np.float64)
    weights, total = _weights_total(lam, data_share, total_sum_squares)
    if total <= 0:
        raise UserError("R^2 is undefined: the points do not vary (all identical, or too close for float64)")
    order = np.argsort(-lam, kind="stable")
    lam, weights = lam[order], weights[order]
    positive = lam > 0
    lam, weights = lam[positive], weights[positive]
    allowed = (1.0 - target) * total
    energy = weights * lam * lam
    dropped = float(energy.sum())  # B_0: nothing kept
    if dropped <= allowed:
        raise UserError(
            f"R^2 target {target} is reached with no component kept (R^2 = {1 - dropped / total:.4g} "
            "at Q* = 0); choose a higher target"
        )
    kept = 0.0  # A_j
    for j in range(lam.size):
        kept += weights[j] / lam[j] ** 2
        dropped -= energy[j]
        right = 1.0 / lam[j + 1] ** 2 if j + 1 < lam.size else np.inf
        if dropped < allowed:
            tau = float(np.sqrt(kept / (allowed - dropped))) if kept > 0 else 1.0 / lam[j] ** 2
            if tau <= right:
                tau = max(tau, 1.0 / lam[j] ** 2)
                for _ in range(16):  # rounding: make "reaches" hold in floating point
                    if _residual(lam, weights, tau) <= allowed:
                        break
                    tau = min(tau * (1.0 + 1e-12), right)
                return tau
    raise UserError(f"R^2 target {target} cannot be reached")  # unreachable for target < 1


@dataclass(frozen=True, eq=False)
class SelfRepresentationSVD:
    """The SVD of ``Z~`` from which ``Q*(tau)`` follows for every tau.

    Attributes
    ----------
    singular_values : ndarray of shape (s,)
        ``lambda_k``, descending; values below the numerical rank tolerance are exactly 0.
    right_vectors : ndarray of shape (n_samples, r)
        ``V``: the right singular vectors of ``Z~`` (one row per point) for the ``r`` nonzero
        singular values.
    data_share : ndarray of shape (s,)
        ``w_k = 1 - U[ones, k]^2`` (affine) or 1 (linear): see the module docstring.
    total_sum_squares : float
        ``||Z - zbar 1^T||_F^2``, the denominator of R^2.
    affine : bool
    ones_weight : float
    method : str
        ``"lapack"`` (LAPACK SVD of ``Z~``) or ``"gram"`` (eigendecomposition of the p x p
        Gram matrix, used for tall, large inputs).
    """

    singular_values: np.ndarray
    right_vectors: np.ndarray
    data_share: np.ndarray
    total_sum_squares: float
    affine: bool
    ones_weight: float
    method: str

    @property
    def n_samples(self) -> int:
        return self.right_vectors.shape[0]

    @property
    def top_singular_value(self) -> float:
        return float(self.singular_values[0]) if self.singular_values.size else 0.0

    def tau_from_relative(self, tau_relative: float) -> float:
        """``tau = tau_relative / lambda_1^2``: scale-free (``P`` depends on ``tau lambda^2``)."""
        if self.top_singular_value <= 0:
            raise UserError("the data matrix is zero: tau_relative is undefined")
        return float(tau_relative) / self.top_singular_value**2

    def shrinkage(self, tau: float) -> np.ndarray:
        """``P(lambda)`` for every singular value."""
        return shrinkage(self.singular_values, tau)

    def rank(self, tau: float) -> int:
        """The rank of ``Q*``: the number of ``lambda_k > 1/sqrt(tau)``."""
        return int(np.count_nonzero(self.shrinkage(tau)))

    def r2(self, tau: float) -> float:
        """R^2 of ``Z ~ Z Q*`` (module docstring); NaN if all points are identical."""
        return r2_from_singular_values(self.singular_values, tau, self.data_share, self.total_sum_squares)

    def tau_for_r2(self, target: float) -> float:
        """The smallest tau whose R^2 reaches ``target``."""
        return tau_for_r2(self.singular_values, target, self.data_share, self.total_sum_squares)

    def factor(self, tau: float) -> np.ndarray:
        """``F = V_r diag(sqrt(P_r))`` of shape (n, rank), so that ``Q* = F F^T``."""
        p = self.shrinkage(tau)[: self.right_vectors.shape[1]]
        keep = np.flatnonzero(p > 0)
        return self.right_vectors[:, keep] * np.sqrt(p[keep])

    def self_representation(self, tau: float) -> np.ndarray:
        """The dense ``Q* = V P(Lambda) V^T`` (n x n): only for small n."""
        f = self.factor(tau)
        return f @ f.T


def self_representation_svd(X, affine: bool = True, ones_weight: float = 1.0) -> SelfRepresentationSVD:
    """SVD of ``Z~ = [X^T; ones_weight 1^T]`` (affine) or ``Z = X^T`` (linear).

    Parameters
    ----------
    X : ndarray of shape (n_samples, n_features)
        Points as rows (the paper's ``Z`` has them as columns); finite float64.
    affine : bool
        Append the ones row (paper, Affine Subspace Clustering).
    ones_weight : float
        The value of the appended row; the paper's homogeneous coordinates use 1. It sets how
        strongly the affine constraint binds relative to the data's scale.

    Returns
    -------
    SelfRepresentationSVD

    Notes
    -----
    Singular values below the numerical rank tolerance, ``lambda_1 max(n, p) eps`` (LAPACK)
    or ``lambda_1 sqrt(p eps)`` (Gram route, which resolves squared values only), are set to
    0: they are rounding noise and their vectors are not determined.
    """
    X = np.asarray(X, dtype=np.float64)
    n, d = X.shape
    p = d + 1 if affine else d
    w = float(ones_weight)
    mean = X.mean(axis=0)
    total = 0.0
    for start in range(0, n, _GRAM_SVD_ROW_BLOCK):  # blockwise: no n x d temporary
        centred = X[start : start + _GRAM_SVD_ROW_BLOCK] - mean
        total += float(np.einsum("ij,ij->", centred, centred))
    if n >= 10 * p and n * p >= _GRAM_SVD_MIN_ENTRIES:
        lam, u, v = _svd_by_gram(X, affine, w)
        method = "gram"
    else:
        a = np.hstack([X, np.full((n, 1), w)]) if affine else X
        v, lam, ut = np.linalg.svd(a, full_matrices=False)
        u = ut.T
        tol = lam[0] * max(n, p) * np.finfo(np.float64).eps if lam.size else 0.0
        lam = np.where(lam > tol, lam, 0.0)
        r = int(np.count_nonzero(lam))
        v = np.ascontiguousarray(v[:, :r])
        method = "lapack"
    share = 1.0 - u[-1] ** 2 if affine else np.ones_like(lam)
    return SelfRepresentationSVD(
        singular_values=lam,
        right_vectors=v,
        data_share=np.clip(share, 0.0, 1.0),
        total_sum_squares=total,
        affine=bool(affine),
        ones_weight=w,
        method=method,
    )


def _svd_by_gram(X: np.ndarray, affine: bool, w: float):
    """Thin SVD of a tall ``A = [X, w 1]`` via ``A^T A = U Lambda^2 U^T``, ``V = A U Lambda^-1``.

    ``A`` is never formed (its Gram matrix is assembled from ``X^T X`` and the column sums).
    """
    n, d = X.shape
    gram_x = X.T @ X
    if affine:
        col = w * X.sum(axis=0)
        gram = np.empty((d + 1, d + 1))
        gram[:d, :d] = gram_x
        gram[:d, d] = gram[d, :d] = col
        gram[d, d] = n * w * w
    else:
        gram = gram_x
    mu, u = np.linalg.eigh(gram)
    mu, u = mu[::-1], u[:, ::-1]
    lam = np.sqrt(np.clip(mu, 0.0, None))
    tol = lam[0] * np.sqrt(gram.shape[0] * np.finfo(np.float64).eps) if lam.size else 0.0
    lam = np.where(lam > tol, lam, 0.0)
    r = int(np.count_nonzero(lam))
    scale = u[:d, :r] / lam[:r]
    v = np.empty((n, r))
    for start in range(0, n, _GRAM_SVD_ROW_BLOCK):
        stop = min(start + _GRAM_SVD_ROW_BLOCK, n)
        np.matmul(X[start:stop], scale, out=v[start:stop])
    if affine:
        v += w * u[d, :r] / lam[:r]
    return lam, u, v
