"""TrainConfig.step "captured" and "compiled" (primspace.train.captured): the eager step within
float tolerance, the static-shape logic checked on the CPU; the CUDA graph and inductor on a GPU."""

import numpy as np
import pytest
import torch

from primspace.data import JointScaler, MotionDataset
from primspace.model.decoder import ModelConfig, MTRNNDecoder
from primspace.model.latent import LatentTable
from primspace.train import TrainConfig, captured, fit, infer
from primspace.train.captured import padded_rows
from primspace.train.loss import DataTensors, batch_loss
from primspace.utils.errors import UserError

MC = ModelConfig(latent_dim=3, layer_sizes=(6, 4), image_channels=(8, 4))
TOL = 1e-5
cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")


def _data(lengths=None):
    rng = np.random.default_rng(0)
    images = rng.integers(0, 255, (14, 12, 16, 16, 3), dtype=np.uint8)
    motor = rng.standard_normal((14, 12, 3)).astype(np.float32)
    if lengths is None:
        return MotionDataset(motor=motor, images=images)
    # one segment per sample, -1 past each length: the step fields go with lengths
    steps = np.where(np.arange(12)[None, :] < np.asarray(lengths)[:, None], 0, -1)
    return MotionDataset(motor=motor, images=images, lengths=lengths, step_labels=steps, step_segments=steps)


def _close(a, b, tol=TOL):
    assert np.abs(a.latents - b.latents).max() < tol
    for x, y in zip(a.model.state_dict().values(), b.model.state_dict().values()):
        assert torch.allclose(x.cpu(), y.cpu(), atol=tol, rtol=0)
    assert np.allclose([h["loss"] for h in a.history], [h["loss"] for h in b.history], rtol=tol)


def _fit(ds, step, device="cpu", **train):
    tc = TrainConfig(epochs=3, batch_size=4, vision_frames=3, step=step, device=device, **train)
    return fit(ds, model_config=MC, train_config=tc, init="projection", indices=np.arange(10), progress=False)


@pytest.mark.parametrize("reduction", ["mean", "sum", "precision"])
@pytest.mark.parametrize("lengths", [None, [12, 9, 7, 12, 10, 12, 8, 12, 11, 12, 12, 6, 12, 12]])
def test_captured_step_is_the_eager_step(reduction, lengths):
    # 10 samples at batch 4: the last batch padded with 2 rows of weight 0; K = 3 frames
    ds = _data(lengths)
    eager, padded = (_fit(ds, step, loss_reduction=reduction) for step in ("eager", "captured"))
    _close(eager, padded)
    runs = [
        infer(eager, ds, epochs=3, indices=np.arange(7, 14), batch_size=3, step=s, progress=False)
        for s in ("eager", "captured")
    ]
    _close(*runs)


def test_padded_rows_are_distinct_and_keep_the_batch_first():
    rows = torch.tensor([7, 2, 5])
    padded = padded_rows(rows, n=9, size=6)
    assert padded[:3].tolist() == [7, 2, 5]
    assert len(set(padded.tolist())) == 6 and set(padded[3:].tolist()).isdisjoint({7, 2, 5})
    assert padded_rows(rows, n=9, size=3) is rows


def test_inactive_rows_keep_their_code_and_adam_state():
    torch.manual_seed(0)
    codes = torch.randn(6, 2)
    a, b = LatentTable(codes, 0.1), LatentTable(codes, 0.1)
    for table in (a, b):
        table.step(torch.tensor([0, 1, 2]), torch.ones(3, 2))  # some state on every row first
    idx, grad = torch.tensor([1, 4, 3, 5]), torch.randn(4, 2)
    a.step(idx[:2], grad[:2])
    c = LatentTable.from_state_dict(b.state_dict())
    b.step(idx, grad, active=torch.tensor([True, True, False, False]))
    for name in ("codes", "exp_avg", "exp_avg_sq", "steps"):
        assert torch.equal(getattr(a, name), getattr(b, name)), name
    c.step(idx, grad, active=torch.tensor([True, True, False, False]), lr=torch.tensor(0.1))  # a rate in a tensor
    still = [0, 2, 3, 5]  # not stepped: untouched
    assert torch.allclose(c.codes, a.codes, atol=1e-7, rtol=0) and torch.equal(c.codes[still], a.codes[still])


def test_weighted_loss_is_the_loss_of_the_real_rows():
    ds = _data([12, 9, 7, 12, 10, 12, 8, 12, 11, 12, 12, 6, 12, 12])
    model = MTRNNDecoder(
        ModelConfig(latent_dim=3, layer_sizes=(6, 4), image_channels=(8, 4), n_joints=3, length=12, image_size=(16, 16))
    )
    tensors = DataTensors.build(ds, JointScaler().fit(ds.motor), True, torch.device("cpu"))
    z = torch.randn(4, 3)
    for reduction in ("mean", "sum"):
        tc = TrainConfig(loss_reduction=reduction)
        real, values = batch_loss(model, z[:2], torch.tensor([3, 1]), tensors, tc, torch.autocast("cpu", enabled=False))
        weighted, wvalues = batch_loss(
            model,
            z,
            torch.tensor([3, 1, 0, 2]),
            tensors,
            tc,
            torch.autocast("cpu", enabled=False),
            weights=torch.tensor([1.0, 1, 0, 0]),
        )
        assert torch.allclose(real, weighted, rtol=1e-6) and torch.allclose(values, wvalues, rtol=1e-6)


@pytest.mark.slow
def test_compiled_step_is_the_eager_step(monkeypatch):
    # dynamo traces the recurrent loop; "eager" runs the traced graph (inductor's first compile
    # takes minutes on two cores: tests/gpu, benchmarks/bench_train.py --paths compiled measure it)
    monkeypatch.setattr(captured, "COMPILE_BACKEND", "eager")
    ds = _data()
    _close(_fit(ds, "eager"), _fit(ds, "compiled"))


def test_a_run_resumes_across_steps(tmp_path):
    ds = _data()
    kw = dict(model_config=MC, init="projection", indices=np.arange(10), progress=False)
    tc = dict(batch_size=4, vision_frames=3, final_lr_fraction=1.0)
    fit(ds, tmp_path / "run", train_config=TrainConfig(epochs=2, step="captured", **tc), **kw)
    resumed = fit(ds, tmp_path / "run", train_config=TrainConfig(epochs=3, **tc), resume=True, **kw)
    _close(resumed, fit(ds, train_config=TrainConfig(epochs=3, **tc), **kw))


def test_captured_needs_one_process_and_whole_batches():
    with pytest.raises(UserError, match="one process, in whole batches"):
        _fit(_data(), "captured", micro_batches=2)
    with pytest.raises(UserError, match="step must be one of eager, compiled, captured"):
        TrainConfig(step="graph").validate()


# ------------------------------------------------------------------ on a GPU (tests/gpu runs them)


@cuda
@pytest.mark.parametrize("step", ["captured", "compiled"])
def test_on_the_gpu_the_step_is_the_eager_step(step):
    ds = _data()
    _close(_fit(ds, "eager", device="cuda"), _fit(ds, step, device="cuda"), tol=1e-4)


def test_the_graphs_warm_up_leaves_the_state_as_it_found_it():
    # StepGraph runs a few steps before it records the graph; they must not count (CPU-checkable part)
    from primspace.train.captured import CapturedStep, StepGraph
    from primspace.train.sessions import fit_session

    ds = _data()
    tc = TrainConfig(epochs=2, batch_size=4, vision_frames=3, step="captured")
    session, _ = fit_session(ds, model_config=MC, train_config=tc, indices=np.arange(10))
    try:
        session.start(None)
        step = session.captured
        assert isinstance(step, CapturedStep) and step.graph is None  # no graph on the CPU
        epoch = session.begin_epoch()
        _, parts = epoch.batches[0]
        ((_, rows, steps),) = parts
        step.autocast = epoch.autocast
        step.code_lr.fill_(session.table.lr)
        step._load(rows, steps)
        table = session.table
        state = [table.codes, table.exp_avg, table.exp_avg_sq, table.steps, *session.model.parameters()]
        before = [t.detach().clone() for t in state]
        graph = StepGraph(step._compute, state, [session.theta_opt])
        graph.warm_up()
        assert all(torch.equal(t, b) for t, b in zip(state, before))
        fresh = [st for st in session.theta_opt.state.values()]
        assert fresh and all(float(v.abs().sum()) == 0 for st in fresh for v in st.values())  # as if never stepped
        graph.warm_up()  # again, now with a state to put back
        assert all(torch.equal(t, b) for t, b in zip(state, before))
    finally:
        session.close()
