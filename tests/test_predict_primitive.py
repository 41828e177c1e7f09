"""The primitive as an input (issue 39, deliverable 3): ``predict(..., primitive=)``, ``init="prior"``,
``AutoDecoder.predict(primitive=)`` and ``primspace predict --primitive / --primitives / --init prior``
on simulated data, LASA and an imported CSV folder: the primitive asked changes the prediction, a
bad name is one line listing the primitives, and without one result.json holds the posterior over
primitives and posterior.png draws it against the observed fraction."""

import dataclasses
import json

import numpy as np
import pytest

from conftest import assert_figure, assert_user_error
from primspace.data import MotionDataset
from primspace.predict import PRIOR, predict
from primspace.predict.posterior import POSTERIOR_FRACTIONS, posterior_by_fraction, top1_accuracy
from primspace.train import TrainConfig, fit
from primspace.utils.errors import UserError
from test_train import SMALL, primitives

NAMES = ["reach", "push", "lift"]
FAST = dict(batch_size=12, threads=1)
#: Draws per primitive: small and fast (users get 2000).
SAMPLES = 50
#: Draws per primitive of each fold of the prior's K-fold choice (users get 500).
CV_SAMPLES = 20


@pytest.fixture(scope="module", autouse=True)
def fewer_fold_draws():
    """The K-fold choice of the prior's noise, temperature and blend on fewer draws per fold: these
    tests ask what the primitive does to the prediction, not what the choice picks (test_prior.py)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("primspace.predict.prior.CV_SAMPLES", CV_SAMPLES)
        yield


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A run fitted on named simulated primitives (its data file read back by the prior), and new motions."""
    root = tmp_path_factory.mktemp("primitive")
    train = dataclasses.replace(primitives(8, seed=0), label_names=NAMES)
    train.save(root / "train.h5")
    fit(
        MotionDataset.load(root / "train.h5"),
        root / "run",
        model_config=SMALL,
        train_config=TrainConfig(epochs=20, **FAST),
        init="projection",
        progress=False,
    )
    dataclasses.replace(primitives(3, seed=100), label_names=NAMES).save(root / "data.h5")
    return root


def _predict(files, **kw):
    data = MotionDataset.load(files / "data.h5")
    return predict(files / "run", data, observe=0.25, frames=False, prior_samples=SAMPLES, **kw)


# ------------------------------------------------------------------------ Python


@pytest.mark.slow
def test_the_primitive_asked_changes_the_prediction(files):
    push = _predict(files, primitive="push", init=PRIOR)
    lift = _predict(files, primitive="lift", init=PRIOR)
    assert push.init == lift.init == PRIOR
    assert push.details["primitive"] == "push" and lift.details["primitive"] == "lift"
    assert "posterior" not in push.details  # asked, not inferred
    assert np.abs(push.motor - lift.motor).max() > 1e-3
    observed = push.motor_observed[..., None]  # the observed part is reproduced either way
    assert np.abs(np.where(observed, push.motor - lift.motor, 0)).max() < np.abs(push.motor - lift.motor).max()


@pytest.mark.slow
def test_without_a_primitive_the_posterior_is_in_the_details(files):
    p = _predict(files, init=PRIOR)
    posterior = np.asarray(p.details["posterior"])
    assert p.details["primitive"] is None and p.details["primitives"] == NAMES
    assert posterior.shape == (9, 3) and np.allclose(posterior.sum(axis=1), 1.0)
    assert p.details["top_primitive"] == [NAMES[k] for k in posterior.argmax(axis=1)]
    truth = MotionDataset.load(files / "data.h5").labels
    assert p.details["posterior_accuracy"] == pytest.approx(np.mean(posterior.argmax(axis=1) == truth))
    curve = posterior_by_fraction(p.predictor, MotionDataset.load(files / "data.h5"))
    assert curve.shape == (len(POSTERIOR_FRACTIONS), 9, 3) and np.allclose(curve.sum(axis=2), 1.0)
    assert not np.allclose(curve[0], curve[-1])  # more observed, another posterior


def test_bad_requests_name_the_primitives_or_the_predictor(files):
    with pytest.raises(UserError, match=r"unknown primitive 'jump'.*0 \(reach\), 1 \(push\), 2 \(lift\)"):
        _predict(files, primitive="jump")
    with pytest.raises(UserError, match="primitive 5 is out of range"):
        _predict(files, primitive=5)
    for init in ("zero", "nearest"):
        with pytest.raises(UserError, match=f"take a primitive: init='{init}' does not"):
            _predict(files, primitive="push", init=init)
    with pytest.raises(UserError, match="primitives must be one of labels, clusters"):
        _predict(files, primitives="shapes")


def test_the_estimator_passes_the_primitive_through(files):
    from primspace import AutoDecoder

    model = AutoDecoder.load(files / "run")
    data = MotionDataset.load(files / "data.h5")
    motor, frames = model.predict(data, observe=0.25, primitive="lift", prior_samples=SAMPLES, init=PRIOR)
    assert model.prediction_.init == PRIOR and model.prediction_.details["primitive"] == "lift"
    assert motor.shape == data.motor.shape and frames is None


def test_online_the_prior_is_filtered_a_step_at_a_time_as_the_primitive_asked(files):
    p = _predict(files, primitive="push", online=1, init=PRIOR)
    assert p.init == PRIOR and p.details["primitive"] == "push" and p.details["online"]["latency_ms_mean"] > 0
    assert p.predictor is None and "posterior" not in p.details and np.isfinite(p.errors["motor_mse"]).all()


def test_top1_accuracy_counts_the_labelled_motions_only():
    posterior = np.array([[0.9, 0.1], [0.2, 0.8], [0.6, 0.4]])
    assert top1_accuracy(posterior, [5, 7], [5, 5, -1]) == 0.5
    assert top1_accuracy(posterior, [5, None], [-1, -1, -1]) is None and top1_accuracy(posterior, [5, 7], None) is None


def test_the_posterior_figure_without_labels_draws_each_top_primitive():
    import matplotlib.pyplot as plt

    from primspace.plots import plot_posterior

    rng = np.random.default_rng(0)
    curve = rng.dirichlet(np.ones(3), size=(10, 6))
    fig = plot_posterior(POSTERIOR_FRACTIONS, curve, ["a", "b", "c"])
    assert len([ax for ax in fig.axes if ax.lines]) == 1
    plt.close(fig)
    fig = plot_posterior(POSTERIOR_FRACTIONS, curve, ["a", "b", "c"], labels=[0, 0, 1, 1, 2, -1], label_names=NAMES)
    assert [ax.get_title() for ax in fig.axes if ax.lines] == [
        "label reach (n=2)",
        "label push (n=2)",
        "label lift (n=1)",
    ]
    plt.close(fig)


# ------------------------------------------------------------------------ the command line


def _cli(run_cli, files, out, *flags):
    return run_cli(
        "predict",
        files / "run",
        files / "data.h5",
        "--observe",
        "0.25",
        "--prior-samples",
        SAMPLES,
        "--out",
        out,
        *flags,
    )


@pytest.mark.slow
def test_the_command_predicts_every_motion_as_the_primitive_asked(run_cli, files, tmp_path):
    res = _cli(run_cli, files, tmp_path / "push", "--primitive", "push", "--init", "prior")
    assert res.code == 0, res.err
    assert "every motion as primitive push" in res.out
    result = json.loads((tmp_path / "push" / "result.json").read_text())
    assert result["init"] == PRIOR and result["primitive"] == "push" and result["command"]["primitive"] == "push"
    assert result["epochs"] == 0 and result["command"]["epochs"] is None  # says what ran, not --epochs' default
    assert result["prior"]["primitives"]["names"] == NAMES and "posterior" not in result
    assert not (tmp_path / "push" / "posterior.png").exists()
    assert _cli(run_cli, files, tmp_path / "lift", "--primitive", "2", "--init", "prior").code == 0  # an id
    push = MotionDataset.load(tmp_path / "push" / "predicted.h5").motor
    lift = MotionDataset.load(tmp_path / "lift" / "predicted.h5").motor
    assert np.abs(push - lift).max() > 1e-3
    assert json.loads((tmp_path / "lift" / "result.json").read_text())["primitive"] == "lift"


@pytest.mark.slow
def test_the_command_without_a_primitive_writes_the_posterior_and_its_figure(run_cli, files, tmp_path):
    out = tmp_path / "posterior"
    res = _cli(run_cli, files, out, "--init", "prior")
    assert res.code == 0, res.err
    result = json.loads((out / "result.json").read_text())
    assert result["primitive"] is None and result["primitives"] == NAMES
    posterior = np.asarray(result["posterior"])
    assert posterior.shape == (9, 3) and np.allclose(posterior.sum(axis=1), 1.0)
    assert 0.0 <= result["posterior_accuracy"] <= 1.0 and len(result["top_primitive"]) == 9
    assert result["model_share"] == pytest.approx(1.0 - result["prior"]["blend"])  # the decoded draws' weight
    assert_figure(out / "posterior.png", height=(200, 2500), min_coloured=200)
    assert sorted(p.name for p in out.iterdir()) == ["posterior.png", "predicted.h5", "prediction.png", "result.json"]


@pytest.mark.slow
def test_the_command_takes_clusters_of_the_codes(run_cli, files, tmp_path):
    res = _cli(run_cli, files, tmp_path / "k", "--primitives", "clusters", "--clusters", "2", "--init", "prior")
    assert res.code == 0, res.err
    result = json.loads((tmp_path / "k" / "result.json").read_text())
    assert result["prior"]["primitives"]["source"] == "clusters" and len(result["primitives"]) == 2
    assert (tmp_path / "k" / "posterior.png").is_file()


@pytest.mark.parametrize(
    "flags, fragments",
    [
        (["--primitive", "jump"], ["unknown primitive 'jump'", "0 (reach), 1 (push), 2 (lift)"]),
        (["--primitive", "9"], ["primitive 9 is out of range", "2 (lift)"]),
        (["--primitives", "clusters", "--init", "mixture"], ["--init mixture takes no --primitives"]),
        (["--primitives", "clusters", "--init", "zero"], ["--init zero takes no --primitives"]),
        (["--primitives", "shapes"], ["--primitives 'shapes'", "labels, clusters"]),
        (["--primitives", "labels", "--clusters", "2"], ["--clusters counts clusters"]),
        (["--primitive", "push", "--prior-samples", "1"], ["--prior-samples 1"]),
    ],
)
def test_bad_primitives_exit_2_and_write_nothing(run_cli, files, tmp_path, flags, fragments):
    out = tmp_path / "o"
    res = run_cli("predict", files / "run", files / "data.h5", "--observe", "0.25", "--out", out, *flags)
    assert_user_error(res, *fragments)
    assert not out.exists()


@pytest.mark.slow
def test_data_without_labels_asks_for_clusters_and_draws_each_top_primitive(run_cli, files, tmp_path):
    """Fitted data without labels: the prior needs clusters of the codes (said with the flags), and
    posterior.png then has one panel, each motion's top primitive."""
    for name in ("train", "data"):
        dataclasses.replace(MotionDataset.load(files / f"{name}.h5"), labels=None, label_names=None).save(
            tmp_path / f"{name}.h5"
        )
    args = ["predict", files / "run", tmp_path / "data.h5", "--fitted-data", tmp_path / "train.h5"]
    args += ["--prior-samples", SAMPLES]
    assert_user_error(run_cli(*args, "--init", "prior", "--out", tmp_path / "o"), "--primitives clusters")
    assert_user_error(run_cli(*args, "--primitives", "clusters", "--out", tmp_path / "o"), "--primitives K")
    assert not (tmp_path / "o").exists()
    res = run_cli(*args, "--primitives", "2", "--out", tmp_path / "k")
    assert res.code == 0, res.err
    result = json.loads((tmp_path / "k" / "result.json").read_text())
    assert result["primitives"] == ["cluster 0", "cluster 1"] and result["posterior_accuracy"] is None
    assert_figure(tmp_path / "k" / "posterior.png", min_coloured=200, min_colours=256)  # two lines: few colours


def test_the_primitives_option_parses_labels_clusters_and_a_number():
    from primspace.cli.predict import parse_primitives

    assert parse_primitives(None, None) == ("labels", None)
    assert (
        parse_primitives("3", None) == parse_primitives("clusters", 3) == parse_primitives(None, 3) == ("clusters", 3)
    )
    with pytest.raises(UserError, match="give the number of clusters once"):
        parse_primitives("3", 4)
    with pytest.raises(UserError, match="at least 1"):
        parse_primitives("0", None)
    assert parse_primitives("labels", None, scene=True) == ("labels", None)  # the scene policy groups by labels
    assert parse_primitives("4", None, scene=True) == ("clusters", 4)


# ------------------------------------------------------------------------ real data


@pytest.mark.slow
def test_lasa_shapes_by_name(run_cli, tmp_path):
    shapes = ["Sine", "Angle", "CShape"]
    data = tmp_path / "lasa.h5"
    res = run_cli("import", "--format", "lasa", "--length", "30", "--shapes", ",".join(shapes), "--out", data)
    assert res.code == 0, res.err
    res = run_cli("train", data, "--epochs", "3", "--latent-dim", "4", "--out", tmp_path / "run")
    assert res.code == 0, res.err
    args = ["predict", tmp_path / "run", data, "--observe", "0.3", "--prior-samples", SAMPLES]
    assert run_cli(*args, "--primitive", "Angle", "--out", tmp_path / "angle").code == 0
    assert json.loads((tmp_path / "angle" / "result.json").read_text())["primitive"] == "Angle"
    assert_user_error(run_cli(*args, "--primitive", "Circle", "--out", tmp_path / "bad"), "0 (Sine), 1 (Angle)")
    assert not (tmp_path / "bad").exists()
    res = run_cli(*args, "--out", tmp_path / "free", "--init", "prior")
    assert res.code == 0, res.err
    result = json.loads((tmp_path / "free" / "result.json").read_text())
    assert result["primitives"] == shapes and np.asarray(result["posterior"]).shape == (21, 3)
    assert result["posterior_accuracy"] is not None and (tmp_path / "free" / "posterior.png").is_file()
    angle = MotionDataset.load(tmp_path / "angle" / "predicted.h5").motor
    free = MotionDataset.load(tmp_path / "free" / "predicted.h5").motor
    assert np.abs(angle - free).max() > 1e-3  # every motion as an Angle, or each weighed by its posterior


@pytest.mark.slow
def test_an_imported_csv_folder_by_its_folder_names(run_cli, tmp_path):
    """Labels from the subfolders' names are the primitives a user names."""
    data = primitives(4, seed=7, T=20, J=3)
    for i, (motion, label) in enumerate(zip(data.motor, data.labels)):
        folder = tmp_path / "csv" / ["wave", "push", "lift"][label]
        folder.mkdir(parents=True, exist_ok=True)
        rows = "\n".join(",".join(f"{v:.6f}" for v in step) for step in motion)
        (folder / f"demo{i}.csv").write_text("j0,j1,j2\n" + rows + "\n")
    d = tmp_path / "d.h5"
    assert run_cli("import", tmp_path / "csv", "--format", "csv", "--length", "20", "--out", d).code == 0
    assert run_cli("train", d, "--epochs", "3", "--latent-dim", "4", "--out", tmp_path / "run").code == 0
    names = MotionDataset.load(d).label_names
    args = ["predict", tmp_path / "run", d, "--observe-steps", "5", "--prior-samples", SAMPLES]
    res = run_cli(*args, "--primitive", "wave", "--out", tmp_path / "wave")
    assert res.code == 0, res.err
    assert json.loads((tmp_path / "wave" / "result.json").read_text())["primitive"] == "wave"
    assert_user_error(run_cli(*args, "--primitive", "jump", "--out", tmp_path / "bad"), *names)
    assert not (tmp_path / "bad").exists()
    res = run_cli(*args, "--out", tmp_path / "free", "--primitives", "labels", "--init", "prior")
    assert res.code == 0, res.err
    result = json.loads((tmp_path / "free" / "result.json").read_text())
    assert sorted(result["primitives"]) == sorted(names) and (tmp_path / "free" / "posterior.png").is_file()
