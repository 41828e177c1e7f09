"""Latent initialisation (zero, random, projection, pca), the code table's Adam, Appendix A."""

import numpy as np
import pytest
import torch

from primspace.model.latent import LatentInitializer, LatentTable, appendix_a_check
from primspace.utils.errors import UserError


def _motor(n=12, t=10, j=3, seed=0):
    return np.random.default_rng(seed).uniform(-1, 1, (n, t, j))


def test_projection_is_P_times_flattened_sequence_with_right_variance():
    q, m = 40, _motor(n=5, t=61, j=9)
    init = LatentInitializer("projection", q, random_state=3).fit(m)
    P = init.projection_
    assert P.shape == (q, 61 * 9)
    assert abs(P.mean()) < 0.01
    np.testing.assert_allclose(P.var(), 1 / q, rtol=0.03)  # 21960 draws of N(0, 1/q)
    z = init.transform(m)
    # time-major flattening: [m_1, m_2, ..., m_T]
    np.testing.assert_allclose(z[2], P @ np.concatenate([m[2, t] for t in range(61)]), rtol=1e-5, atol=1e-5)


def test_projection_depends_on_seed_and_shape_only_and_is_reused():
    a = LatentInitializer("projection", 8, random_state=1).fit(_motor(seed=0))
    b = LatentInitializer("projection", 8, random_state=1).fit(_motor(seed=1))
    np.testing.assert_array_equal(a.projection_, b.projection_)
    c = LatentInitializer("projection", 8, random_state=2).fit(_motor())
    assert not np.allclose(a.projection_, c.projection_)
    # saved and restored: new data is projected with the same P
    restored = LatentInitializer.from_state_dict(a.state_dict())
    new = _motor(n=4, seed=9)
    np.testing.assert_array_equal(restored.transform(new), a.transform(new))


def test_zero_and_random():
    m = _motor(n=2000, t=4, j=2)
    assert not LatentInitializer("zero", 5).fit_transform(m).any()
    r = LatentInitializer("random", 5, random_state=0).fit(m)
    z = r.transform(m)
    assert z.shape == (2000, 5) and z.dtype == np.float32
    assert abs(z.mean()) < 0.05 and abs(z.std() - 1) < 0.05
    np.testing.assert_array_equal(z, r.transform(m))  # seeded
    assert not np.allclose(z, r.transform(m, random_state=1))  # fresh draws for new data


def test_pca_matches_the_principal_directions():
    rng = np.random.default_rng(0)
    basis = rng.normal(size=(3, 30))
    coeff = rng.normal(size=(50, 3)) * np.array([5.0, 2.0, 0.5])
    m = (coeff @ basis + 0.3).reshape(50, 10, 3)
    init = LatentInitializer("pca", 5).fit(m)
    z = init.transform(m)
    x = m.reshape(50, -1)
    _, s, vt = np.linalg.svd(x - x.mean(0), full_matrices=False)
    for i in range(3):  # same directions up to sign, same scores
        np.testing.assert_allclose(np.abs(z[:, i]), np.abs((x - x.mean(0)) @ vt[i]), rtol=1e-4, atol=1e-4)
    assert np.allclose(z[:, 3:], 0, atol=1e-4)  # rank 3: the rest carry nothing
    # more dimensions than samples: padded with zero directions
    small = LatentInitializer("pca", 20).fit(m[:4])
    assert small.transform(m).shape == (50, 20)
    assert not small.projection_[4:].any()


def test_initializer_errors():
    with pytest.raises(UserError, match="unknown latent init"):
        LatentInitializer("sobol", 3).fit(_motor())
    with pytest.raises(UserError, match="at least 1"):
        LatentInitializer("zero", 0).fit(_motor())
    init = LatentInitializer("projection", 3).fit(_motor(t=10))
    with pytest.raises(UserError, match="T\\*J = 15"):
        init.transform(_motor(t=5))


@pytest.mark.parametrize("case", ["random", "correlated", "parallel"])
def test_appendix_a_expectation_and_variance_bound(case):
    rng = np.random.default_rng(7)
    a = rng.normal(size=549)
    b = {"random": rng.normal(size=549), "correlated": a + rng.normal(size=549), "parallel": -2 * a}[case]
    r = appendix_a_check(a, b, latent_dim=40, n_draws=2000, random_state=1)
    assert abs(r["mean_z"]) < 4  # E[Pa.Pb] = a.b within sampling error
    np.testing.assert_allclose(r["var"], r["var_exact"], rtol=0.12)
    assert r["var_exact"] <= r["var_bound"] * (1 + 1e-12)
    if case == "parallel":  # the bound is attained for parallel vectors
        np.testing.assert_allclose(r["var_exact"], r["var_bound"], rtol=1e-12)
    else:
        assert r["var"] < r["var_bound"]


def test_latent_table_is_adam_per_row():
    torch.manual_seed(0)
    codes = torch.randn(6, 3)
    table = LatentTable(codes, lr=0.05)
    rows = [torch.nn.Parameter(codes[i].clone()) for i in range(6)]
    opts = [torch.optim.Adam([p], lr=0.05) for p in rows]
    target = torch.randn(6, 3)
    for idx in ([0, 2, 4], [1, 2], [5, 0], [2, 3, 4]):
        idx_t = torch.tensor(idx)
        z = table.batch(idx_t)
        ((z - target[idx_t]) ** 3).sum().backward()
        table.step(idx_t, z.grad)
        for i in idx:
            opts[i].zero_grad()
            ((rows[i] - target[i]) ** 3).sum().backward()
            opts[i].step()
    expected = torch.stack([p.detach() for p in rows])
    torch.testing.assert_close(table.codes, expected, rtol=1e-5, atol=1e-6)
    # rows never drawn do not move at all
    fresh = LatentTable(codes, lr=0.05)
    idx_t = torch.tensor([1])
    z = fresh.batch(idx_t)
    z.sum().backward()
    fresh.step(idx_t, z.grad)
    assert torch.equal(fresh.codes[[0, 2, 3, 4, 5]], codes[[0, 2, 3, 4, 5]])
    assert not torch.equal(fresh.codes[1], codes[1])


def test_latent_table_state_roundtrip():
    table = LatentTable(torch.randn(4, 2), lr=0.1)
    idx = torch.tensor([0, 3])
    z = table.batch(idx)
    z.square().sum().backward()
    table.step(idx, z.grad)
    again = LatentTable.from_state_dict(table.state_dict())
    for name in ("codes", "exp_avg", "exp_avg_sq", "steps"):
        assert torch.equal(getattr(again, name), getattr(table, name))
