"""The peers of :mod:`primspace.segmentation`: change points and a hidden Markov model on raw joints.

primspace segments a demonstration from its inferred window codes; its peers here see the
demonstration itself, the joints scaled as the experiment scales them, one ``(L, J)`` array
of valid steps per demonstration. Each returns boundaries (steps ``t > 0`` where a segment
starts) and a label per step, scored by the same functions as primspace
(:func:`~primspace.segmentation.boundary_f1`, :func:`~primspace.segmentation.step_labelling_accuracy`).

* **Change points** (``ruptures``, extra ``eval``; Truong, Oudre & Vayatis 2020): PELT
  (Killick et al. 2012), exact dynamic programming (``Dynp``) or binary segmentation, with
  the costs ``l2`` (piecewise-constant mean), ``rbf`` (kernel, median heuristic) and
  ``normal`` (Gaussian, mean and full covariance). Candidate change points at every step
  (``jump=1``); at least ``window`` steps per segment, and ``d + 1`` for ``normal`` (a
  full-rank covariance). How many change points (:data:`RULES`), never from labels except
  ``count``:

  - ``noise``: primspace's own penalty (:func:`~primspace.segmentation.auto_penalty` of
    :func:`~primspace.segmentation.noise_variances` pooled over all demonstrations, ``n`` the
    demonstration's steps), for ``l2``, whose cost (within sum of squares) is the one it was
    derived for. It assumes white noise about a piecewise-constant signal; smooth joints
    have almost none, so it cuts every few steps: the rule that works on codes fails here.
  - ``bic``: for ``normal``, whose cost ``n log det S`` is ``-2 log`` likelihood up to a
    constant: ``p log n`` with ``p = d + d (d + 1) / 2`` parameters per segment.
  - ``elbow``: for any cost, the least cost with ``k = 0..10`` change points along the
    binary-segmentation path, and ``k`` where the normalised curve lies farthest below the
    chord from its first to its last point (the knee). ``rbf`` has neither a noise level nor
    a likelihood in its feature space: this is its rule.
  - ``count``: the true number of boundaries of each demonstration (given, as an oracle).

  Segments are labelled as primspace labels its segments: each resampled to
  :data:`LABEL_STEPS` steps (linear interpolation), flattened, and clustered by the affine
  :class:`~primspace.cluster.LowRankSubspaceClustering` into as many clusters as primitives
  (:func:`~primspace.segmentation.label_segments`).
* **A Gaussian HMM** (``hmmlearn``, extra ``eval``): as many states as primitives, a full
  covariance per state, fitted by EM (100 iterations, the most likely of 3 starts) on all
  demonstrations at once and decoded by Viterbi; the state is the step's label, and runs shorter than ``window`` steps
  are merged into the run before them (into the one after for a first run) before the
  boundaries are read where the state changes.
"""

from __future__ import annotations

import contextlib
import logging
import time
import warnings
from dataclasses import dataclass

import numpy as np

from primspace.segmentation.result import label_segments
from primspace.segmentation.windows import auto_penalty, noise_variances
from primspace.utils.errors import UserError

__all__ = [
    "ChangePointPeer",
    "HMMPeer",
    "MissingPackage",
    "PeerResult",
    "PEERS",
    "PEERS_VERSION",
    "RULES",
    "LABEL_STEPS",
    "ELBOW_MAX",
    "resample_segment",
    "label_by_clustering",
    "merge_short_runs",
    "elbow",
    "run_peers",
    "peer_sequences",
]

#: Bumped when a peer's rule or setting changes (a stored result of another version is recomputed).
PEERS_VERSION = 2  # 2: scored within the transition too (0.8)
#: Steps a segment is resampled to before its segments are clustered.
LABEL_STEPS = 20
#: Most change points per demonstration the ``elbow`` rule considers.
ELBOW_MAX = 10
#: How a change-point peer chooses its number of change points (module docstring).
RULES = ("noise", "bic", "elbow", "count")

_MISSING = "the segmentation peers need {}: pip install 'primspace[eval]'"


class MissingPackage(UserError):
    """A peer's package (extra ``eval``) is not installed."""


@dataclass
class PeerResult:
    """What a peer found: per demonstration the boundaries and a label per valid step; its
    wall-clock seconds; and a note when the labels could not be clustered."""

    boundaries: list[np.ndarray]
    step_labels: list[np.ndarray]
    seconds: float = 0.0
    note: str | None = None


def peer_sequences(sequences) -> list[np.ndarray]:
    """Demonstrations as a list of finite ``(L, J)`` float64 arrays of one ``J`` (one clear line if not)."""
    seqs = [np.asarray(x, dtype=np.float64) for x in sequences]
    if not seqs or any(x.ndim != 2 or len(x) == 0 for x in seqs) or len({x.shape[1] for x in seqs}) > 1:
        shapes = [x.shape for x in seqs]
        raise UserError(f"sequences must be one or more non-empty (L, J) arrays of one J, got {shapes}")
    for i, x in enumerate(seqs):
        if not np.isfinite(x).all():
            raise UserError(f"sequence {i} is not finite")
    return seqs


def resample_segment(x: np.ndarray, n_steps: int = LABEL_STEPS) -> np.ndarray:
    """``(n_steps, J)``: the segment ``x`` (m, J) linearly interpolated at ``n_steps`` even
    points from its first to its last step (a one-step segment repeated)."""
    x = np.asarray(x, dtype=np.float64)
    if len(x) == 1:
        return np.repeat(x, n_steps, axis=0)
    t = np.linspace(0.0, len(x) - 1, n_steps)
    grid = np.arange(len(x))
    return np.stack([np.interp(t, grid, x[:, j]) for j in range(x.shape[1])], axis=1)


def label_by_clustering(sequences, boundaries, n_primitives: int, random_state: int = 0):
    """Per-step labels of found segments: each resampled (:data:`LABEL_STEPS`), flattened,
    all clustered together by :func:`~primspace.segmentation.label_segments`.

    Returns ``(step_labels, note)``: a list of int64 arrays, one per demonstration."""
    feats, spans = [], []
    for x, b in zip(sequences, boundaries):
        edges = np.concatenate([[0], np.asarray(b, dtype=np.int64), [len(x)]])
        spans.append(np.diff(edges))
        feats += [resample_segment(x[a:e]).ravel() for a, e in zip(edges[:-1], edges[1:])]
    labels, note = label_segments(np.asarray(feats), n_primitives, random_state=random_state)
    out, k = [], 0
    for lengths in spans:
        out.append(np.repeat(labels[k : k + len(lengths)], lengths).astype(np.int64))
        k += len(lengths)
    return out, note


def elbow(costs) -> int:
    """The knee of a decreasing cost curve ``costs[k]``, ``k = 0..K``: the ``k`` whose point,
    both axes scaled to [0, 1], lies farthest below the chord from the first point to the
    last (0 if the curve does not decrease)."""
    c = np.asarray(costs, dtype=np.float64)
    if len(c) < 3 or not c[0] > c[-1]:
        return 0
    x = np.arange(len(c)) / (len(c) - 1)
    y = (c - c[-1]) / (c[0] - c[-1])
    return int(np.argmax((1.0 - x) - y))


@dataclass(frozen=True)
class ChangePointPeer:
    """A ``ruptures`` change-point detector with a rule for how many change points.

    Parameters
    ----------
    algorithm : {"pelt", "dynp", "binseg"}
    cost : {"l2", "rbf", "normal"}
    rule : one of :data:`RULES`
        ``noise`` and ``bic`` go with ``pelt``, ``elbow`` with ``binseg`` (its path of
        ``k = 0..10`` change points); ``count`` (any algorithm) needs the true counts.
    """

    algorithm: str
    cost: str
    rule: str

    def __post_init__(self):
        if self.algorithm not in ("pelt", "dynp", "binseg") or self.cost not in ("l2", "rbf", "normal"):
            raise UserError(f"unknown change-point peer {self.algorithm}/{self.cost}")
        wanted = {"noise": "pelt", "bic": "pelt", "elbow": "binseg"}.get(self.rule, self.algorithm)
        if self.rule not in RULES or self.algorithm != wanted:
            raise UserError(f"rule {self.rule!r} does not go with {self.algorithm} (rules: {', '.join(RULES)})")

    def min_size(self, n_joints: int, window: int) -> int:
        """Fewest steps per segment: ``window``; for ``normal`` at least ``J + 1``."""
        return max(int(window), n_joints + 1) if self.cost == "normal" else int(window)

    def boundaries(self, sequences, window: int, true_counts=None) -> list[np.ndarray]:
        """Boundary steps of each demonstration (``true_counts``: its true number of boundaries, for ``count``)."""
        seqs = peer_sequences(sequences)
        if self.rule == "count" and (true_counts is None or len(true_counts) != len(seqs)):
            raise UserError("the 'count' rule needs the true number of boundaries of every demonstration")
        variances = noise_variances(seqs) if self.rule == "noise" else None
        counts = true_counts if self.rule == "count" else [None] * len(seqs)
        return [self._detect(x, window, variances, k) for x, k in zip(seqs, counts)]

    def _detect(self, x: np.ndarray, window: int, variances, count) -> np.ndarray:
        rpt = _ruptures()
        size = self.min_size(x.shape[1], window)
        most = len(x) // size - 1  # change points that fit
        if most < 1:
            return np.zeros(0, dtype=np.int64)
        make = {"pelt": rpt.Pelt, "dynp": rpt.Dynp, "binseg": rpt.Binseg}
        with warnings.catch_warnings():  # ruptures announces its covariance bias (v1.1.5) on every normal cost
            warnings.simplefilter("ignore", UserWarning)
            algo = make[self.algorithm](model=self.cost, min_size=size, jump=1).fit(x)
        if self.rule == "count":
            k = min(int(count), most)
            bkps = algo.predict(n_bkps=k) if k > 0 else [len(x)]
        elif self.rule == "elbow":
            path = [[len(x)]] + [algo.predict(n_bkps=k) for k in range(1, min(ELBOW_MAX, most) + 1)]
            bkps = path[elbow([algo.cost.sum_of_costs(b) for b in path])]
        else:
            bkps = algo.predict(pen=self.penalty(x, variances))
        return np.asarray(bkps[:-1], dtype=np.int64)

    def penalty(self, x: np.ndarray, variances=None) -> float:
        """The ``noise`` or ``bic`` penalty for the demonstration ``x`` (module docstring)."""
        n, d = x.shape
        if self.rule == "bic":
            return float((d + d * (d + 1) / 2) * np.log(max(n, 2)))
        v = noise_variances(x) if variances is None else variances
        spread = float(np.sum((x - x.mean(axis=0)) ** 2))
        return max(auto_penalty(v, n), 1e-9 * spread)

    def run(self, sequences, n_primitives: int, window: int, true_counts=None, random_state: int = 0) -> PeerResult:
        """Boundaries, and labels by :func:`label_by_clustering`."""
        from threadpoolctl import threadpool_limits

        start = time.perf_counter()
        seqs = peer_sequences(sequences)
        with threadpool_limits(1):  # small matrices: BLAS threads only contend
            found = self.boundaries(seqs, window, true_counts)
            labels, note = label_by_clustering(seqs, found, n_primitives, random_state)
        return PeerResult(found, labels, round(time.perf_counter() - start, 2), note)


def merge_short_runs(states, min_duration: int) -> np.ndarray:
    """``states`` with every run shorter than ``min_duration`` steps given to the run before
    it (the one after, for a first run), shortest first, until none is left (or one run)."""
    s = np.asarray(states).copy()
    while True:
        change = np.flatnonzero(s[1:] != s[:-1]) + 1
        starts, stops = np.concatenate([[0], change]), np.concatenate([change, [len(s)]])
        short = np.flatnonzero(stops - starts < min_duration)
        if len(starts) < 2 or not len(short):
            return s
        j = short[np.argmin((stops - starts)[short])]
        s[starts[j] : stops[j]] = s[starts[j] - 1] if j > 0 else s[stops[j]]


@dataclass(frozen=True)
class HMMPeer:
    """``hmmlearn``'s GaussianHMM, a state per primitive (module docstring).

    Parameters
    ----------
    covariance : {"full", "diag"}
    n_iter : int
        EM iterations.
    n_init : int
        EM runs from different starts (k-means of a seed each); the most likely is kept.
    """

    covariance: str = "full"
    n_iter: int = 100
    n_init: int = 3

    def run(self, sequences, n_primitives: int, window: int, true_counts=None, random_state: int = 0) -> PeerResult:
        """Fit on all demonstrations, decode each, merge runs shorter than ``window``."""
        start = time.perf_counter()
        seqs = peer_sequences(sequences)
        try:
            from hmmlearn.hmm import GaussianHMM
        except ImportError as exc:
            raise MissingPackage(_MISSING.format("hmmlearn")) from exc
        from threadpoolctl import threadpool_limits

        X, lengths, best = np.concatenate(seqs), [len(x) for x in seqs], None
        # small matrices: BLAS threads only contend (70x slower on a busy 2-core machine)
        with _quiet("hmmlearn"), threadpool_limits(1):
            for k in range(self.n_init):
                model = GaussianHMM(
                    n_components=int(n_primitives),
                    covariance_type=self.covariance,
                    n_iter=self.n_iter,
                    random_state=int(random_state) * 100 + k,
                ).fit(X, lengths)
                score = model.score(X, lengths)
                best = (score, model) if best is None or score > best[0] else best
            states = [merge_short_runs(best[1].predict(x), int(window)).astype(np.int64) for x in seqs]
        found = [np.flatnonzero(s[1:] != s[:-1]).astype(np.int64) + 1 for s in states]
        return PeerResult(found, states, round(time.perf_counter() - start, 2))


#: The peers in the order of the tables: name -> peer.
PEERS = {
    "pelt-l2-noise": ChangePointPeer("pelt", "l2", "noise"),
    "pelt-normal-bic": ChangePointPeer("pelt", "normal", "bic"),
    "binseg-l2-elbow": ChangePointPeer("binseg", "l2", "elbow"),
    "binseg-rbf-elbow": ChangePointPeer("binseg", "rbf", "elbow"),
    "binseg-normal-elbow": ChangePointPeer("binseg", "normal", "elbow"),
    "dynp-l2-count": ChangePointPeer("dynp", "l2", "count"),
    "dynp-rbf-count": ChangePointPeer("dynp", "rbf", "count"),
    "dynp-normal-count": ChangePointPeer("dynp", "normal", "count"),
    "hmm-full": HMMPeer("full"),
}


def run_peers(sequences, n_primitives: int, window: int, true_counts=None, names=None, random_state: int = 0):
    """Run the named :data:`PEERS` (default all) on the same demonstrations.

    Returns ``(results, missing)``: ``{name: PeerResult}`` of those that ran, and
    ``{name: reason}`` of those that could not (a package not installed; ``count`` peers
    without ``true_counts``)."""
    results, missing = {}, {}
    for name in names or PEERS:
        peer = PEERS[name]
        if getattr(peer, "rule", None) == "count" and true_counts is None:
            missing[name] = "needs the true number of boundaries"
            continue
        try:
            results[name] = peer.run(sequences, n_primitives, window, true_counts, random_state)
        except MissingPackage as exc:
            missing[name] = str(exc)
    return results, missing


def _ruptures():
    try:
        import ruptures
    except ImportError as exc:
        raise MissingPackage(_MISSING.format("ruptures")) from exc
    return ruptures


@contextlib.contextmanager
def _quiet(logger: str):
    """Silence a library's convergence chatter (logged as warnings) for a while."""
    log = logging.getLogger(logger)
    level = log.level
    log.setLevel(logging.ERROR)
    try:
        yield
    finally:
        log.setLevel(level)
