"""The predictor chosen by held-out evidence (``auto``, :mod:`primspace.predict.selection`): the lowest
K-fold error wins, the choice is recorded in ``result.json``, it is the default of ``predict`` and of
``primspace predict``, and it is kept in the run folder and read back on a later call with the same key."""

import dataclasses
import json

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.data import MotionDataset
from primspace.predict import AUTO, DEFAULT_PREDICTOR, MIXTURE, PRIOR, PredictRequest, SelectedPredictor, predict
from primspace.predict.peers import MeanMotionPeer
from primspace.predict.selection import DEFAULT_CANDIDATES, PROMP_TUNED, RAW_GAUSSIAN, candidates_for
from primspace.predict.selection_cache import SELECTION_MARK
from primspace.train import TrainConfig, fit
from primspace.train.observe import Observation
from primspace.utils.errors import UserError
from test_train import SMALL, primitives

NAMES = ["reach", "push", "lift"]
#: Draws per primitive of the prior, and of each fold of its own K-fold choice: small and fast.
SAMPLES, CV_SAMPLES = 50, 20
#: The tuned ProMP's basis counts tried (its default grid goes past the 16 steps of these motions: slow EM).
BASIS = (6, 10)


@pytest.fixture(scope="module", autouse=True)
def fewer_fold_draws():
    """Fewer draws in the prior's own K-fold and fewer basis counts in the tuned ProMP's."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("primspace.predict.prior.CV_SAMPLES", CV_SAMPLES)
        mp.setattr("primspace.predict.gaussian_peers.BASIS_GRID", BASIS)
        yield


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A short run fitted on named primitives (a folder on disk: the choice is kept there), new motions."""
    root = tmp_path_factory.mktemp("selection")
    dataclasses.replace(primitives(4, seed=0, T=16), label_names=NAMES).save(root / "train.h5")
    fit(
        MotionDataset.load(root / "train.h5"),
        root / "run",
        model_config=SMALL,
        train_config=TrainConfig(epochs=5, batch_size=12, threads=1),
        init="projection",
        progress=False,
    )
    dataclasses.replace(primitives(2, seed=100, T=16), label_names=NAMES).save(root / "data.h5")
    return root


def _predict(files, **kw):
    data = MotionDataset.load(files / "data.h5")
    return predict(files / "run", data, **{"observe": 0.5, "frames": False, "prior_samples": SAMPLES, **kw})


class _Zero(MeanMotionPeer):
    """A candidate that predicts zeros where nothing was observed (far from the fitted motions)."""

    def predict(self, motor, observed, labels=None, lengths=None, frames=None):
        mask = np.asarray(observed)[..., None] if not isinstance(observed, Observation) else None
        if mask is None:
            mask = observed.masks(np.full(len(motor), motor.shape[1]), motor.shape[1])[0][..., None]
        return np.where(mask, motor, 0.0)


@pytest.fixture
def peers(files, monkeypatch):
    """The run, fitted motions all alike, and the selection's candidates replaced by two peers: the mean
    motion (it predicts the held-out motions exactly) as the prior, zeros as the mixture."""
    from primspace.train import load_run

    run = load_run(files / "run")
    one = np.linspace(-0.5, 0.5, 16)[:, None] * np.ones((1, run.model_config.n_joints))
    motor = np.repeat(one[None], len(run.latents), axis=0)
    built = {MIXTURE: lambda: _Zero(per_label=False), PRIOR: lambda: MeanMotionPeer(per_label=False)}
    monkeypatch.setattr(SelectedPredictor, "build", lambda self, name, run, scoring=False: built[name]())
    return run, motor, np.arange(len(run.latents)) % 3


def test_the_candidate_with_the_lowest_kfold_error_is_chosen(peers):
    run, motor, labels = peers
    chosen = SelectedPredictor(run, candidates=(MIXTURE, PRIOR), reuse=False)
    selection = chosen.fit(motor, labels).select(Observation.build(0.25))
    assert selection["chosen"] == PRIOR and selection["folds"] == 3
    assert selection["errors"][PRIOR] == pytest.approx(0.0, abs=1e-12)
    # every fitted demonstration is held out once: the K-fold error of zeros is their error on every one
    observed = Observation.build(0.25).masks(np.full(len(motor), 16), 16)[0]
    assert selection["errors"][MIXTURE] == pytest.approx(float((motor[~observed] ** 2).mean()))
    assert selection["errors"][MIXTURE] > 0.01


def test_a_stale_or_foreign_file_is_never_read(peers):
    run, motor, labels = peers
    rule = Observation.build(0.2)

    def select():
        return SelectedPredictor(run, candidates=(MIXTURE, PRIOR)).fit(motor, labels).select(rule)

    path = select()["kept"]
    record = json.loads(open(path).read())
    assert record["writer"] == SELECTION_MARK and select()["reused"] == path
    with open(path, "w") as f:  # a stale key: ignored, scored again and written again
        json.dump({**record, "key": "0" * 64}, f)
    again = select()
    assert again["reused"] is None and again["kept"] == path and json.loads(open(path).read())["key"] == record["key"]
    with open(path, "w") as f:  # a file the command did not write: neither read nor replaced
        f.write('{"note": "mine"}')
    third = select()
    assert third["reused"] is None and third["kept"] is None and json.loads(open(path).read()) == {"note": "mine"}


def test_the_candidates_of_each_task():
    peers = (RAW_GAUSSIAN, PROMP_TUNED)
    assert DEFAULT_CANDIDATES == (MIXTURE, PRIOR, *peers)
    assert candidates_for(False, True) == (MIXTURE, PRIOR, *peers)
    assert candidates_for(True, True) == (MIXTURE, PRIOR, *peers)  # restricted to the label, the prior given it
    assert candidates_for(False, False) == (MIXTURE, *peers)  # no labels, no clusters asked: the prior has none
    assert candidates_for(True, False, "clusters") == (PRIOR,)  # the peers' primitives are the labels
    assert candidates_for(True, True, asked=(PRIOR,)) == (PRIOR,)
    with pytest.raises(UserError, match="candidates must be some of"):
        candidates_for(False, True, asked=("promp",))


def test_auto_is_the_default_and_its_choice_is_recorded(files):
    assert DEFAULT_PREDICTOR == AUTO and PredictRequest().init == AUTO
    p = _predict(files)
    selection = p.details["selection"]
    assert p.init == AUTO and selection["folds"] == 3 and tuple(selection["errors"]) == DEFAULT_CANDIDATES
    assert selection["chosen"] == min(selection["errors"], key=selection["errors"].get)
    assert selection["kept"] is not None and selection["reused"] is None
    kept = json.loads(open(selection["kept"]).read())
    assert kept["writer"] == SELECTION_MARK and kept["selection"]["chosen"] == selection["chosen"]


def test_a_second_call_reads_the_choice_and_fits_no_candidate_by_kfold(files, monkeypatch):
    first = _predict(files, primitive="push")
    assert first.details["selection"]["reused"] is None

    def refuse(*args, **kwargs):
        raise AssertionError("scored again")

    monkeypatch.setattr(SelectedPredictor, "score", refuse)
    second = _predict(files, primitive="push")
    assert second.details["selection"]["reused"] == first.details["selection"]["kept"]
    assert second.details["selection"]["chosen"] == first.details["selection"]["chosen"]
    np.testing.assert_array_equal(second.motor, first.motor)  # the kept settings: the same numbers
    with pytest.raises(AssertionError, match="scored again"):  # another task: another key, scored
        _predict(files, primitive="lift")


@pytest.mark.slow
def test_the_command_chooses_by_default_records_and_reuses(files, run_cli, tmp_path):
    base = ("predict", files / "run", files / "data.h5", "--observe", "0.4", "--primitive", "push", "--no-judge")
    res = run_cli(*base, "--prior-samples", SAMPLES, "--out", tmp_path / "a")
    assert res.code == 0, res.err
    result = json.loads((tmp_path / "a" / "result.json").read_text())
    assert result["init"] == AUTO and result["command"]["init"] == AUTO
    assert tuple(result["selection"]["errors"]) == DEFAULT_CANDIDATES and result["selection"]["folds"] == 3
    assert f"init auto ({result['selection']['chosen']}, the lowest 3-fold error" in res.out
    res = run_cli(*base, "--prior-samples", SAMPLES, "--out", tmp_path / "b")
    assert res.code == 0, res.err
    assert res.out.startswith("reused the predictor chosen earlier") and len(res.out.strip().splitlines()) == 2
    res = run_cli(*base, "--predictor", MIXTURE, "--out", tmp_path / "c")  # the alias overrides
    assert res.code == 0 and json.loads((tmp_path / "c" / "result.json").read_text())["init"] == MIXTURE


def test_fit_predictor_prints_the_table_and_keeps_the_choice(files, run_cli):
    res = run_cli("fit-predictor", files / "run", "--observe", "0.3", "--primitive", "lift", "--prior-samples", SAMPLES)
    assert res.code == 0, res.err
    lines = res.out.splitlines()
    n = len(DEFAULT_CANDIDATES)
    assert lines[0].split() == ["candidate", "3-fold", "MSE"]
    assert tuple(line.split()[0] for line in lines[1 : n + 1]) == DEFAULT_CANDIDATES
    assert sum("<- chosen" in line for line in lines) == 1 and "kept in" in lines[n + 1]
    res = run_cli("fit-predictor", files / "run", "--observe", "0.3", "--primitive", "lift", "--prior-samples", SAMPLES)
    assert "reused the choice kept earlier" in res.out


@pytest.mark.parametrize(
    "flags, fragment",
    [
        (["--init", "bogus"], "unknown start 'bogus'"),
        (["--predictor", "zero", "--primitive", "push"], "--init zero takes no --primitive"),
        (["--primitive", "jump"], "unknown primitive 'jump'"),
    ],
)
def test_a_bad_predictor_or_primitive_is_one_line(files, run_cli, tmp_path, flags, fragment):
    assert_user_error(run_cli("predict", files / "run", files / "data.h5", "--out", tmp_path / "o", *flags), fragment)
    assert not (tmp_path / "o").exists()


def test_the_priors_decoded_draws_are_kept_and_read_back(files, tmp_path):
    from primspace.predict.selection_cache import decoded_draws
    from primspace.train import load_run

    run, codes, calls = load_run(files / "run"), np.random.default_rng(0).normal(size=(5, 18)).astype(np.float32), []

    def decode(values):
        calls.append(len(values))
        return np.asarray(values, dtype=np.float32)[:, :4] * 2.0

    first = decoded_draws(tmp_path, run, codes, decode)
    again = decoded_draws(tmp_path, run, codes, decode)
    assert calls == [5] and np.array_equal(first, again)  # read back, not decoded again
    decoded_draws(tmp_path, run, codes[:3], decode)  # other codes: another key
    assert calls == [5, 3]
    (kept,) = [p for p in tmp_path.glob("draws-*.npz") if np.load(p)["decoded"].shape[0] == 5]
    kept.write_bytes(b"not ours")  # a file the command did not write: neither read nor replaced
    decoded_draws(tmp_path, run, codes, decode)
    assert calls == [5, 3, 5] and kept.read_bytes() == b"not ours"


@pytest.mark.parametrize(
    "candidate, given", [(MIXTURE, False), (MIXTURE, True), (PRIOR, False), (PROMP_TUNED, True), (RAW_GAUSSIAN, False)]
)
def test_a_kept_choice_predicts_the_same_numbers_without_searching(files, candidate, given, monkeypatch):
    """Each candidate refitted with its kept settings (and the prior with its kept draws) predicts as fitted afresh."""
    from primspace.predict import fit_predictor
    from primspace.train import load_run

    run, data = load_run(files / "run"), MotionDataset.load(files / "data.h5")
    scaled, rule = run.scaler.transform(data.motor), Observation.build(0.35)

    def forecast():
        chosen = SelectedPredictor(run, candidates=(candidate,), prior_samples=SAMPLES, given=given)
        return fit_predictor(chosen, run).forecast(scaled, rule, data.labels, data.valid_lengths)

    first = forecast()
    assert first.details["selection"]["reused"] is None and first.details["selection"]["folds"] == 0

    def refuse(*args, **kwargs):
        raise AssertionError("searched again")

    monkeypatch.setattr("primspace.predict.prior.PriorPredictor._cross_validate", refuse)
    monkeypatch.setattr("primspace.predict.candidates.CodeMixture.choose_noise", refuse)
    monkeypatch.setattr("primspace.predict.gaussian_peers.unobserved_mse", refuse)  # the peers' K-fold choice
    if candidate == PRIOR:
        monkeypatch.setattr("primspace.predict.prior.reconstruct", refuse)  # its draws are read back
    second = forecast()
    assert second.details["selection"]["reused"] == first.details["selection"]["kept"]
    np.testing.assert_array_equal(second.motor, first.motor)


@pytest.mark.slow
def test_the_grid_runs_auto_for_both_tasks(files):
    """The start ``auto`` in the prediction grid: a row without the primitive and one given it."""
    from primspace.predict.grid import AUTO_ROWS, GIVEN_ROWS, grid_predictions
    from primspace.train import load_run
    from test_predict_pinned import CHEAP_PEERS, CHEAP_PRIORS

    run = load_run(files / "run")
    train, test = MotionDataset.load(files / "train.h5"), MotionDataset.load(files / "data.h5")
    cheap = {**CHEAP_PRIORS, "prior": {"n_samples": SAMPLES}}
    kept = sorted((files / "run").rglob("*"))
    table = grid_predictions(
        run, train, test, (0.3,), starts=(AUTO,), epochs=1, prior_settings=cheap, peer_settings=CHEAP_PEERS
    )
    assert set(AUTO_ROWS) <= set(table) and "auto (labels)" in GIVEN_ROWS and AUTO not in GIVEN_ROWS
    assert all(np.isfinite(table[row]["0.3"]) for row in AUTO_ROWS)
    assert sorted((files / "run").rglob("*")) == kept  # the grid keeps nothing in the run folder


def test_a_peer_with_the_lowest_kfold_error_is_chosen(files):
    """Smooth motions of two shapes, which a Gaussian over trajectories predicts from a prefix almost
    exactly, on a run whose short-trained decoder cannot: a peer wins, and the record lists every candidate."""
    from primspace.train import load_run

    run = load_run(files / "run")
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 1.0, 16)[None, :, None]
    weights, joints = rng.normal(size=(len(run.latents), 2, 1)), np.linspace(-1.0, 1.0, run.model_config.n_joints)
    motor = 0.3 * joints * (weights[:, :1] * np.sin(np.pi * t) + weights[:, 1:] * t**2)  # a family of two numbers
    predictor = SelectedPredictor(run, prior_samples=SAMPLES, reuse=False).fit(motor, np.arange(len(motor)) % 3)
    selection = predictor.select(Observation.build(0.5))
    errors = selection["errors"]
    assert tuple(errors) == DEFAULT_CANDIDATES and all(np.isfinite(e) for e in errors.values())
    assert selection["chosen"] in (RAW_GAUSSIAN, PROMP_TUNED) and errors[selection["chosen"]] == min(errors.values())
    assert errors[selection["chosen"]] < 0.1 * min(errors[MIXTURE], errors[PRIOR])
    forecast = predictor.forecast(motor[:3], Observation.build(0.5))
    assert forecast.details["model_share"] == 0.0 and forecast.details["selection"]["chosen"] == selection["chosen"]


def test_the_candidates_table_aligns_every_name():
    from primspace.cli.fit_predictor import selection_table

    errors = {"mixture": 0.01, "prior": 0.02, "raw_gaussian": 0.005, "promp_tuned": None}
    lines = selection_table({"folds": 3, "errors": errors, "chosen": "raw_gaussian"}).splitlines()
    ends = {len(line.replace("   <- chosen", "")) for line in lines}
    assert len(ends) == 1, lines  # the error column ends at one place, whatever the names' lengths
    assert lines[3].startswith("raw_gaussian ") and lines[3].endswith("<- chosen")
