"""The Ng-Jordan-Weiss spectral step on ``Q* = F F^T``, dense or without any n x n matrix.

NJW (Ng, Jordan & Weiss, 2001), as used after the paper's closed form (Background, Linear
Subspace Clustering: "spectral clustering ... on Q*"):

1. affinity ``W = Q* o Q*`` (``"squared"``, elementwise) or ``|Q*|`` (``"abs"``), self-loops
   included (``W_ii = Q*_ii^2``: the affinity is exactly the closed form's, which keeps it
   low-rank);
2. ``M = D^-1/2 W D^-1/2`` with degrees ``d = W 1`` (a point of degree 0 gets a zero row);
3. the eigenvectors of the k largest eigenvalues of ``M``; eigenvalues ``<= 1e-9 lambda_max``
   (rounding level, or negative with ``"abs"``) are dropped, so with fewer than k positive
   ones the embedding has fewer columns and the null-space vectors, which are arbitrary, never
   enter k-means;
4. each row scaled to unit length;
5. k-means with ``n_init`` restarts on the rows.

Implicit route (affinity "squared")
-----------------------------------
With ``Q* = F F^T`` (``F = V_r sqrt(P_r)``, n x r), ``W_ij = (f_i . f_j)^2 = <phi_i, phi_j>``
with ``phi_i = vech(f_i f_i^T)`` (the ``m = r(r+1)/2`` products ``f_ia f_ib``, ``a <= b``, the
off-diagonal ones times sqrt 2). Hence ``W = Phi Phi^T`` has rank <= m and::

    d_i = f_i^T (F^T F) f_i,                                  (degrees, O(n r^2))
    (W x)_i = f_i^T (sum_j x_j f_j f_j^T) f_i = rowsum((F (F^T diag(x) F)) o F)_i,

so the normalised operator ``M = Psi Psi^T`` with ``Psi = D^-1/2 Phi`` is applied in
O(n r^2) per vector without forming an n x n matrix (:class:`NormalizedAffinityOperator`,
which evaluates ``Psi (Psi^T X)`` over row blocks of ``Psi`` rebuilt from ``F``: the same
numbers as the rowsum formula, half the flops, all BLAS-3). Two eigensolvers use it, both in
float64:

``"gram"`` (exact)
    ``M`` and the m x m matrix ``G = Psi^T Psi`` share their nonzero eigenvalues; with
    ``G = E S E^T`` the top eigenvectors of ``M`` are ``Psi E_k S_k^-1/2``. ``G`` is
    accumulated over row blocks of ``Psi`` (one BLAS syrk each), O(n m^2): no iteration, no
    tolerance, and a repeated top eigenvalue (perfectly separated clusters) is no problem.
    Chosen while ``r <= GRAM_MAX_RANK`` (48, m <= 1176).
``"lobpcg"`` (iterative)
    :func:`scipy.sparse.linalg.lobpcg` on the operator with a block of k random vectors,
    tolerance 1e-8: O(n r^2 k) per iteration, cheaper than ``"gram"`` for large r (whose
    cost grows as r^4). A block method, because single-vector Lanczos (ARPACK) misses copies
    of a repeated top eigenvalue (measured: 5 of 7 found for 7 separated subspaces).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.sparse.linalg import LinearOperator, eigsh, lobpcg
from sklearn.cluster import KMeans
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils import check_random_state

from primspace.utils.errors import UserError

__all__ = [
    "SpectralEmbedding",
    "NormalizedAffinityOperator",
    "affinity_from_factor",
    "degrees_from_factor",
    "choose_spectral_method",
    "spectral_embedding",
    "spectral_embedding_dense",
    "njw_labels",
    "DENSE_MAX_SAMPLES",
    "AUTO_DENSE_MAX_SAMPLES",
    "GRAM_MAX_RANK",
]

AFFINITIES = ("squared", "abs")
# "auto" forms the n x n matrices up to this many points (they are cheap there and the
# self-representation matrix is then kept); "dense" refuses more than DENSE_MAX_SAMPLES
# (Q* and W take 1.6 GB at 1e4 points).
AUTO_DENSE_MAX_SAMPLES = 2_000
DENSE_MAX_SAMPLES = 10_000
# Above this size the dense eigenproblem goes to ARPACK instead of a full LAPACK eigh.
_DENSE_EIGH_MAX_SAMPLES = 3_000
# The gram route costs ~n r^4 / 4, lobpcg ~(iterations) * 3 k n r^2: measured at n = 5e4,
# k = 7: gram 0.8 s / lobpcg 1.3 s at r = 41, 3.7 s / 1.7 s at r = 60, 34 s / 2.3 s at r = 80.
GRAM_MAX_RANK = 48
_PSI_BLOCK_ENTRIES = 1 << 22  # entries of one block of Psi^T (32 MB)
_OPERATOR_BLOCK_ROWS = 65_536
_LANCZOS_TOL = 1e-10  # ARPACK, dense matrices above _DENSE_EIGH_MAX_SAMPLES
_LOBPCG_TOL = 1e-8
_LOBPCG_MAXITER = 1_000
_LOBPCG_WARN_RESIDUAL = 1e-5
_EIGENVALUE_RTOL = 1e-9


@dataclass(frozen=True, eq=False)
class SpectralEmbedding:
    """The top eigenvectors of ``M = D^-1/2 W D^-1/2``.

    Attributes
    ----------
    vectors : ndarray of shape (n_samples, k)
        Orthonormal eigenvectors, largest eigenvalue first (``k <= n_components``: rounding-
        level eigenvalues are dropped).
    eigenvalues : ndarray of shape (k,)
    method : str
        ``"dense"``, ``"gram"`` or ``"lobpcg"``.
    """

    vectors: np.ndarray
    eigenvalues: np.ndarray
    method: str


def _inverse_sqrt(degrees: np.ndarray) -> np.ndarray:
    out = np.zeros_like(degrees)
    positive = degrees > 0
    out[positive] = 1.0 / np.sqrt(degrees[positive])
    return out


def affinity_from_factor(factor, affinity: str = "squared", rows=None, cols=None) -> np.ndarray:
    """A dense block of ``W``: ``(F_rows F_cols^T)^2`` or ``|F_rows F_cols^T|``.

    Parameters
    ----------
    factor : ndarray of shape (n, r)
        ``F`` with ``Q* = F F^T``.
    affinity : {"squared", "abs"}
    rows, cols : index arrays, optional
        Which points (default all); ``cols`` defaults to ``rows``.
    """
    _check_affinity(affinity)
    f = np.asarray(factor, dtype=np.float64)
    fr = f if rows is None else f[rows]
    fc = fr if cols is None else f[cols]
    q = fr @ fc.T
    return np.square(q, out=q) if affinity == "squared" else np.abs(q, out=q)


def degrees_from_factor(factor) -> np.ndarray:
    """Degrees of ``W = (F F^T) o (F F^T)``: ``d_i = f_i^T (F^T F) f_i``, O(n r^2)."""
    f = np.asarray(factor, dtype=np.float64)
    gram = f.T @ f
    d = np.empty(f.shape[0])
    for start in range(0, f.shape[0], _OPERATOR_BLOCK_ROWS):
        fb = f[start : start + _OPERATOR_BLOCK_ROWS]
        d[start : start + fb.shape[0]] = np.einsum("ij,ij->i", fb @ gram, fb)
    return d


class NormalizedAffinityOperator(LinearOperator):
    """``M = D^-1/2 W D^-1/2`` for ``W = (F F^T) o (F F^T)``, never formed (module docstring).

    ``M X = Psi (Psi^T X)``, accumulated over row blocks of ``Psi`` (rebuilt from ``F`` per
    block): O(n r^2) per column, memory O(block x r^2).

    Parameters
    ----------
    factor : ndarray of shape (n, r)
        ``F`` with ``Q* = F F^T``.

    Attributes
    ----------
    degrees : ndarray of shape (n,)
        ``d = W 1``.
    inv_sqrt_degrees : ndarray of shape (n,)
        ``d^-1/2`` (0 where ``d = 0``).
    """

    def __init__(self, factor) -> None:
        self.factor = np.ascontiguousarray(factor, dtype=np.float64)
        self.degrees = degrees_from_factor(self.factor)
        self.inv_sqrt_degrees = _inverse_sqrt(self.degrees)
        n = self.factor.shape[0]
        super().__init__(dtype=np.dtype(np.float64), shape=(n, n))

    def _matvec(self, x):
        return self._matmat(np.asarray(x, dtype=np.float64).reshape(-1, 1)).reshape(-1)

    def _rmatvec(self, x):
        return self._matvec(x)

    def _matmat(self, x):
        x = np.asarray(x, dtype=np.float64)
        inner = 0.0
        for start, stop, psi_t in _psi_blocks(self.factor, self.inv_sqrt_degrees):
            inner = inner + psi_t @ x[start:stop]  # Psi^T X, (m, b)
        out = np.empty((self.shape[0], x.shape[1]))
        for start, stop, psi_t in _psi_blocks(self.factor, self.inv_sqrt_degrees):
            np.matmul(psi_t.T, inner, out=out[start:stop])
        return out

    def _adjoint(self):
        return self


def choose_spectral_method(n_samples: int, rank: int, affinity: str, spectral: str) -> str:
    """Map the estimator's ``spectral`` option to ``"dense"``, ``"gram"`` or ``"lobpcg"``.

    ``"auto"``: dense up to :data:`AUTO_DENSE_MAX_SAMPLES` points or for ``affinity="abs"``
    (``|Q*|`` has no low-rank factorisation); implicit otherwise. ``"implicit"``: ``"gram"``
    for ``rank <= GRAM_MAX_RANK``, ``"lobpcg"`` above.

    Raises
    ------
    UserError
        ``"implicit"`` with ``affinity="abs"``, or a dense route beyond
        :data:`DENSE_MAX_SAMPLES` points.
    """
    _check_affinity(affinity)
    if spectral == "auto":
        spectral = "dense" if (n_samples <= AUTO_DENSE_MAX_SAMPLES or affinity == "abs") else "implicit"
    if spectral == "implicit":
        if affinity != "squared":
            raise UserError(
                "spectral='implicit' needs affinity='squared' (|Q*| has no low-rank factorisation); "
                "use spectral='dense'"
            )
        return "gram" if rank <= GRAM_MAX_RANK else "lobpcg"
    if spectral != "dense":
        raise UserError(f"spectral must be 'auto', 'dense' or 'implicit', got {spectral!r}")
    if n_samples > DENSE_MAX_SAMPLES:
        hint = "use affinity='squared' with spectral='implicit'" if affinity == "abs" else "use spectral='implicit'"
        gb = 2 * 8 * n_samples**2 / 1e9
        raise UserError(
            f"the dense spectral step needs two {n_samples} x {n_samples} matrices ({gb:.0f} GB) and is "
            f"limited to {DENSE_MAX_SAMPLES} points; {hint}"
        )
    return "dense"


def spectral_embedding(
    factor, n_components: int, *, affinity: str = "squared", method: str = "gram", random_state=None
) -> SpectralEmbedding:
    """Top ``n_components`` eigenvectors of the normalised affinity of ``Q* = F F^T``.

    Parameters
    ----------
    factor : ndarray of shape (n, r)
    n_components : int
        k, the number of clusters.
    affinity : {"squared", "abs"}
    method : {"dense", "gram", "lobpcg"}
        See the module docstring; :func:`choose_spectral_method` picks one.
    random_state : int, RandomState or None
        Seeds ARPACK's starting vector (``"lobpcg"`` and large dense problems).
    """
    f = np.ascontiguousarray(factor, dtype=np.float64)
    if method == "dense":
        return spectral_embedding_dense(affinity_from_factor(f, affinity), n_components, random_state=random_state)
    if affinity != "squared":
        raise UserError(f"method {method!r} needs affinity='squared'")
    if method == "gram":
        return _gram_embedding(f, n_components)
    if method == "lobpcg":
        return _lobpcg_embedding(f, n_components, random_state)
    raise UserError(f"unknown spectral method {method!r}")


def spectral_embedding_dense(affinity_matrix, n_components: int, *, random_state=None) -> SpectralEmbedding:
    """Top eigenvectors of ``D^-1/2 W D^-1/2`` for a dense symmetric ``W`` (overwritten)."""
    w = np.asarray(affinity_matrix, dtype=np.float64)
    n = w.shape[0]
    s = _inverse_sqrt(w.sum(axis=1))
    w *= s[:, None]
    w *= s[None, :]
    k = min(n_components, n)
    if n <= _DENSE_EIGH_MAX_SAMPLES or k >= n - 1:
        values, vectors = scipy.linalg.eigh(w, subset_by_index=[n - k, n - 1], overwrite_a=True)
    else:
        values, vectors = eigsh(w, k=k, which="LA", v0=_start_vector(n, random_state), tol=_LANCZOS_TOL)
    return _top(values, vectors, "dense")


def _top(values: np.ndarray, vectors: np.ndarray, method: str, n_components: int | None = None) -> SpectralEmbedding:
    order = np.argsort(-values, kind="stable")[:n_components]
    values, vectors = values[order], vectors[:, order]
    keep = values > _EIGENVALUE_RTOL * max(float(values[0]), 0.0) if values.size else values > 0
    return SpectralEmbedding(np.ascontiguousarray(vectors[:, keep]), values[keep], method)


def _start_vector(n: int, random_state) -> np.ndarray:
    # random, not sqrt(d): that is an exact eigenvector when clusters are perfectly separated
    return check_random_state(random_state).uniform(-1.0, 1.0, n)


def _psi_blocks(f: np.ndarray, inv_sqrt_degrees: np.ndarray):
    """Yield ``(start, stop, Psi[start:stop]^T)``: (m, b) blocks with rows
    ``d_i^-1/2 f_ia f_ib`` (a <= b, off-diagonal ones times sqrt 2), ~32 MB each."""
    n, r = f.shape
    m = r * (r + 1) // 2
    block = max(256, _PSI_BLOCK_ENTRIES // m)
    root2 = np.sqrt(2.0)
    for start in range(0, n, block):
        stop = min(start + block, n)
        ft = (f[start:stop] * np.sqrt(inv_sqrt_degrees[start:stop])[:, None]).T.copy()  # (r, b)
        out = np.empty((m, stop - start))
        offset = 0
        for a in range(r):
            rows = out[offset : offset + r - a]
            np.multiply(ft[a:], ft[a], out=rows)
            rows[1:] *= root2
            offset += r - a
        yield start, stop, out


def _gram_embedding(f: np.ndarray, n_components: int) -> SpectralEmbedding:
    n, r = f.shape
    s = _inverse_sqrt(degrees_from_factor(f))
    m = r * (r + 1) // 2
    gram = np.zeros((m, m))
    for _, _, psi_t in _psi_blocks(f, s):
        gram += psi_t @ psi_t.T  # numpy dispatches A @ A.T to BLAS syrk
    values, vectors = np.linalg.eigh(gram)
    top = _top(values, vectors, "gram", n_components)
    projection = top.vectors / np.sqrt(top.eigenvalues)
    out = np.empty((n, projection.shape[1]))
    for start, stop, psi_t in _psi_blocks(f, s):
        np.matmul(psi_t.T, projection, out=out[start:stop])
    return SpectralEmbedding(out, top.eigenvalues, "gram")


def _lobpcg_embedding(f: np.ndarray, n_components: int, random_state) -> SpectralEmbedding:
    # For n < 5 k scipy's lobpcg applies the operator to the identity and solves densely
    # (at most 25 k^2 entries): the only case in which this route holds an n x n matrix.
    op = NormalizedAffinityOperator(f)
    n = op.shape[0]
    k = min(n_components, n)
    # A random block start (never sqrt(d), an exact eigenvector for separated clusters); the
    # block of k vectors resolves a top eigenvalue repeated up to k times, which ARPACK's
    # single-vector Lanczos does not (measured: it finds 5 of 7 copies).
    start = check_random_state(random_state).uniform(-1.0, 1.0, (n, k))
    with warnings.catch_warnings():  # lobpcg warns on stagnation; the residual is checked below
        warnings.simplefilter("ignore", UserWarning)
        values, vectors = lobpcg(op, start, largest=True, tol=_LOBPCG_TOL, maxiter=_LOBPCG_MAXITER)
    residual = np.linalg.norm(op.matmat(vectors) - vectors * values, axis=0).max()
    if residual > _LOBPCG_WARN_RESIDUAL:
        warnings.warn(
            f"lobpcg stopped with eigenvector residual {residual:.2g} (> {_LOBPCG_WARN_RESIDUAL:g}); "
            "the clustering may be inaccurate",
            ConvergenceWarning,
            stacklevel=3,
        )
    return _top(values, vectors, "lobpcg")


def njw_labels(embedding, n_clusters: int, *, n_init: int = 20, random_state=None) -> np.ndarray:
    """Rows scaled to unit length, then k-means with ``n_init`` restarts (NJW steps 4-5).

    Parameters
    ----------
    embedding : ndarray of shape (n, k)
    n_clusters : int
    n_init : int
    random_state : int, RandomState or None

    Returns
    -------
    labels : ndarray of shape (n,), int64
    """
    y = np.array(embedding, dtype=np.float64)
    norms = np.linalg.norm(y, axis=1)
    nonzero = norms > 0
    y[nonzero] /= norms[nonzero, None]
    km = KMeans(n_clusters=n_clusters, n_init=n_init, random_state=random_state)
    return km.fit(y).labels_.astype(np.int64)


def _check_affinity(affinity: str) -> None:
    if affinity not in AFFINITIES:
        raise UserError(f"affinity must be 'squared' or 'abs', got {affinity!r}")
