"""The rules of the paper's central claims (primspace.results.claim_rules_central) can hold and fail."""

from primspace.results.claim_rules_central import generalisation_improved, separated_from_the_onset
from primspace.results.claim_verdicts import PARTLY
from primspace.results.layout import INITIAL_CODES, LEARNED_CODES


def _intra(**finals):
    return {
        "runs": [
            {"init": init, "latent_dim": 40, "seed": 0, "fit": [], "infer": [{"loss": 1.0}, {"loss": loss}]}
            for init, loss in finals.items()
        ]
    }


def test_substantial_improvement_over_zero_and_random():
    assert generalisation_improved(_intra(projection=1e-5, zero=1e-4, random=1e-2)).ok is True
    assert generalisation_improved(_intra(projection=1e-5, zero=1.5e-5, random=1e-2)).ok == PARTLY  # 1.5x only
    assert generalisation_improved(_intra(projection=1e-5, zero=5e-6)).ok is False  # zero ends lower
    assert generalisation_improved(_intra(projection=1e-5)).ok is None  # nothing to compare with
    assert "zero 10x" in generalisation_improved(_intra(projection=1e-5, zero=1e-4)).numbers


def _clustering(initial, trained):
    rows = [{"init": "projection", "codes": LEARNED_CODES, "accuracy": trained}]
    rows += [] if initial is None else [{"init": "projection", "codes": INITIAL_CODES, "accuracy": initial}]
    return {"latent_dim": 40, "latent": rows, "trajectory": {"data": {"k": 7}}}


def test_separated_from_the_onset_reads_the_untrained_codes():
    # chance 1/7; well separated from 1/7 + 0.5 (6/7) = 0.571
    assert separated_from_the_onset(_clustering(0.95, 0.5)).ok is True
    assert separated_from_the_onset(_clustering(0.4, 0.9)).ok == PARTLY  # separated only after training
    assert separated_from_the_onset(_clustering(0.4, 0.5)).ok is False
    assert separated_from_the_onset(_clustering(None, 0.9)).ok is None
