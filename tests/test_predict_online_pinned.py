"""The online numbers of the prior and the encoder, and the peers' predictions, pinned on a small case.

The prediction grid (``test_predict_pinned.py``) pins the online gradient start and the online
mixture; this file pins the two other online predictors (their remaining error after every
step and the prediction kept) and the peers' predictions as arrays, so that moving their loops
into one cannot change a number.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import cpu_class, pinned_for_this_cpu
from test_train import primitives, small_run

PINNED = Path(__file__).with_suffix(".json")


def make_case():
    """The small run, its fitted demonstrations and the test motions."""
    train, test = primitives(6, seed=0, T=20), primitives(2, seed=100, T=20)
    return small_run(train, epochs=10, final_lr_fraction=1.0), train, test


@pytest.fixture(scope="module")
def case():
    return make_case()


def numbers(run, train, test) -> dict:
    """The pinned numbers: means of the online errors and predictions, and of the peers' predictions."""
    from primspace.predict import EncoderPredictor, MeanMotionPeer, NearestPeer, PriorPredictor, ProMPPeer

    scaled, fitted = run.scaler.transform(test.motor), run.scaler.transform(train.motor)
    prior = PriorPredictor(run, given=True, n_samples=100, noise=1e-3, temperature=10.0, blend=0.5)
    prior.fit(fitted, train.labels, train.valid_lengths)
    encoder = EncoderPredictor(run, prior=prior.asked(), n_train=128, steps=10, hidden=8, batch_size=32)
    encoder.fit(fitted, train.labels, train.valid_lengths)
    out = {}
    for name, predictor in (("prior", prior), ("posterior", prior.asked()), ("encoder", encoder)):
        result = predictor.predict_online(scaled, test.valid_lengths, test.labels, start_step=3, prediction_after=8)
        out[name] = {
            "errors": [float(e) for e in np.nan_to_num(result.errors).sum(axis=0)],
            "prediction": float(np.abs(result.prediction).sum()),
            "codes": float(np.abs(result.codes).sum()),
        }
    observed = np.arange(test.length)[None, :] < 6
    observed = np.repeat(observed, len(test), axis=0)
    for name, peer in (
        ("promp", ProMPPeer(per_label=True)),
        ("promp one", ProMPPeer(per_label=False)),
        ("nearest", NearestPeer()),
        ("mean", MeanMotionPeer()),
    ):
        peer.fit(fitted, train.labels, train.valid_lengths)
        out[name] = float(np.abs(peer.predict(scaled, observed, test.labels, test.valid_lengths)).sum())
    return out


def test_the_online_priors_and_the_peers_keep_their_numbers(case):
    pinned = pinned_for_this_cpu(json.loads(PINNED.read_text()), "online and peer numbers", vendor=True)
    got = numbers(*case)
    assert set(got) == set(pinned)
    for name, value in pinned.items():
        cells = value if isinstance(value, dict) else {"": value}
        for key, v in cells.items():
            number = got[name][key] if isinstance(value, dict) else got[name]
            np.testing.assert_allclose(number, v, rtol=1e-6, atol=1e-12, err_msg=f"{name} {key}")


if __name__ == "__main__":  # records the pins of this CPU class
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    table = json.loads(PINNED.read_text()) if PINNED.exists() else {}
    table[cpu_class(vendor=True)] = numbers(*make_case())
    PINNED.write_text(json.dumps(table, indent=1) + "\n")
