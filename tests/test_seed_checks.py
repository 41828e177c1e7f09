"""A seed is checked where it enters, and libraries get seeds derived from ours.

A user's seed is a whole number in 0..2**63-1 (``primspace.utils.seeds.MAX_SEED``): the
command line refuses any other in one line (exit 2) before any work; scikit-learn takes
0..2**32-1, so what reaches it is :func:`primspace.utils.seeds.library_seed` of ours (the
seed itself where it fits, so numbers do not move), never the user's seed unchecked.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import assert_user_error
from primspace.utils.errors import UserError
from primspace.utils.seeds import MAX_SEED, library_seed


def test_library_seeds_are_ours_where_they_fit_and_derived_above():
    assert [library_seed(s) for s in (0, 7, 2**32 - 1)] == [0, 7, 2**32 - 1]
    big = [library_seed(s) for s in (2**32, 5_000_000_000, MAX_SEED)]
    assert all(isinstance(s, int) and 0 <= s <= 2**32 - 1 for s in big) and len(set(big)) == 3
    assert library_seed(5_000_000_000) == library_seed(np.int64(5_000_000_000))  # the same seed, the same word
    for bad in (-1, MAX_SEED + 1, 1.5, True, "3"):
        with pytest.raises(UserError, match="seed must be a whole number"):
            library_seed(bad)


@pytest.mark.parametrize("seed", ["-1", str(MAX_SEED + 1)])
def test_act_refuses_a_seed_before_any_work(run_cli, tmp_path, seed):
    """Before the run is read (it does not exist here) and before the output is made."""
    res = run_cli(
        "act", tmp_path / "run", "--primitive", "push", "--scene", "0.5,0,0.05", "--perturb", "--seed", seed,
        "--out", tmp_path / "o",
    )  # fmt: skip
    assert_user_error(res, "--seed", seed)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("flags", [["--scene", "--primitive", "push"], ["--init", "random"]])
@pytest.mark.parametrize("seed", ["-1", str(MAX_SEED + 1)])
def test_predict_refuses_a_seed_before_any_work(run_cli, tmp_path, flags, seed):
    res = run_cli("predict", tmp_path / "run", tmp_path / "d.h5", *flags, "--seed", seed, "--out", tmp_path / "o")
    assert_user_error(res, "--seed", seed)
    assert not (tmp_path / "o").exists()


def test_the_scene_policy_takes_any_seed_of_ours_and_refuses_others():
    """A run trained with seed 5e9 (train accepts it) fits the scene policy; a negative seed is one line."""
    from primspace.act.scene_policy import ScenePolicy
    from test_train import primitives

    data = primitives(2, seed=3, T=6, J=3, images=True)
    motor, frames = data.motor, np.asarray(data.images)
    fitted = ScenePolicy(random_state=5_000_000_000).fit(motor, data.labels, None, frames)
    assert fitted.primitives_.count == len(np.unique(data.labels))
    with pytest.raises(UserError, match="random_state must be a whole number"):
        ScenePolicy(random_state=-1).fit(motor, data.labels, None, frames)


def test_clusters_of_codes_take_any_seed_of_ours():
    """The prior's and the scene policy's clusters of the fitted codes (scikit-learn inside)."""
    from primspace.predict.primitives import primitives_from_clusters

    rng = np.random.default_rng(0)
    codes = np.vstack([rng.normal(size=4) + 0.01 * rng.normal(size=(6, 4)) for _ in range(2)])
    assert primitives_from_clusters(codes, 2, random_state=5_000_000_000).count == 2


def test_cluster_takes_any_seed_of_ours_and_names_its_option_for_others(run_cli, tmp_path):
    np.save(tmp_path / "z.npy", np.random.default_rng(0).normal(size=(30, 6)))
    for seed in ("-1", str(MAX_SEED + 1)):
        res = run_cli("cluster", tmp_path / "z.npy", "--k", 2, "--seed", seed, "--out", tmp_path / "c")
        assert_user_error(res, "--seed", seed)
        assert "z.npy" not in res.err and not (tmp_path / "c").exists()
    res = run_cli("cluster", tmp_path / "z.npy", "--k", 2, "--seed", 5_000_000_000, "--out", tmp_path / "c")
    assert res.code == 0, res.err
