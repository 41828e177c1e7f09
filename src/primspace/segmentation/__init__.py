"""Finding the primitives in long demonstrations: boundaries and labels, one module per method.

The paper's future work (shared/paper.tex, Summary and Discussion, verbatim): "There are some
challenges such as primitives might have different number of timesteps and not clear
borderline between primitives." The package's map:

* :mod:`~primspace.segmentation.result`: what every method returns
  (:class:`SegmentationResult`) and the labeller of segment codes (affine subspace
  clustering, :func:`label_segments`);
* :mod:`~primspace.segmentation.scores`: boundary F1 within a tolerance, per-step labelling
  accuracy, one :func:`segmentation_scores` for all;
* :mod:`~primspace.segmentation.windows`: change points of a sequence of window codes
  (``primspace segment --method windows``);
* :mod:`~primspace.segmentation.synthesis`: the partition a model of single primitives
  generates best (``--method synthesis``);
* :mod:`~primspace.segmentation.surprise`: where that model's prediction of the next steps
  fails (``--method surprise``);
* :mod:`~primspace.segmentation.peers`: the maintained libraries' segmenters (ruptures,
  hmmlearn) on the same demonstrations;
* :mod:`~primspace.segmentation.bounds`: upper bounds on the true segments (classifiers given
  the labels), which tell a hard data set from a weak method.

The names below are the windows method's and the shared ones, importable from the package,
and :data:`METHODS` with :data:`DEFAULT_METHOD`, the method ``primspace segment`` uses unless
told otherwise.
"""

from primspace.segmentation.result import SEGMENT_R2_TARGET, SegmentationResult, label_segments
from primspace.segmentation.scores import (
    boundaries_from_segments,
    boundary_f1,
    segmentation_scores,
    step_labelling_accuracy,
)
from primspace.segmentation.windows import (
    AUTO_PENALTY_FACTOR,
    DEFAULT_MIN_SIZE,
    auto_penalty,
    change_points,
    noise_variances,
    segment_sequences,
)

#: The segmentation methods by name (``primspace segment --method``).
METHODS = ("synthesis", "surprise", "windows")
#: The default method: synthesis found the boundaries with F1 0.76 where the window codes got
#: 0.18 on the same long demonstrations, and needs no run trained with a code window.
DEFAULT_METHOD = "synthesis"

__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "AUTO_PENALTY_FACTOR",
    "DEFAULT_MIN_SIZE",
    "SEGMENT_R2_TARGET",
    "SegmentationResult",
    "auto_penalty",
    "boundaries_from_segments",
    "boundary_f1",
    "change_points",
    "noise_variances",
    "segment_sequences",
    "step_labelling_accuracy",
    "label_segments",
    "segmentation_scores",
]
