"""docs/reproduce.md's generated blocks (primspace.report.reproduce_blocks): the paper's own
setting beside ours, and the clustering ablation, from summaries built here."""

from primspace.report.reproduce_blocks import PAPER_SETTING, ablation, paper_setting, success_by_primitive

NAMES = ["touch", "grasp"]


def _summary(name: str, motor: dict, rates: dict) -> dict:
    """``motor``: {init: [final eval motor MSE per seed]}; ``rates``: {init: [(touch, grasp) per seed]}."""
    runs = [
        {
            "init": init,
            "latent_dim": 40,
            "seed": s,
            "fit": [{"epoch": 0, "loss": 1.0}],
            "infer": [{"epoch": 0, "loss": 1.0}],
            "final": {"fit": {}, "infer": {"motor": m, "psnr": 25.0}},
        }
        for init, ms in motor.items()
        for s, m in enumerate(ms)
    ]
    points = {
        s: {
            init: {
                "rates": dict(zip(NAMES, r[s])),
                "counts": dict.fromkeys(NAMES, 10),
                "overall": sum(r[s]) / 2,
            }
            for init, r in rates.items()
        }
        for s in range(len(next(iter(rates.values()))))
    }
    success = {"label_names": NAMES, "generated": points[0], "by_seed": {str(s): p for s, p in points.items() if s}}
    return {"name": name, "results": {"intra": {"runs": runs}, "success": success}}


def test_success_per_primitive_is_the_mean_over_seeds_of_each_init():
    s = _summary("ours", {"projection": [1e-4, 2e-4]}, {"projection": [(1.0, 0.8), (0.6, 0.6)]})
    columns, rows = success_by_primitive(s)
    assert columns == ["run", "touch", "grasp", "all"]
    assert rows[0][0] == "ours: projection (2 seeds)"
    assert rows[0][1] == "0.8 ± 0.3" and rows[0][2] == "0.7 ± 0.1"  # sample std (ddof 1; ddof 0 gives 0.2)
    assert rows[0][3] == "0.75"


def test_the_paper_setting_block_compares_each_stored_pair_and_names_what_is_missing():
    ours_name, theirs_name, _ = PAPER_SETTING[0]
    ours = _summary(
        ours_name, {"zero": [1e-3], "projection": [1e-4]}, {"zero": [(1.0, 0.5)], "projection": [(1.0, 1.0)]}
    )
    theirs = _summary(
        theirs_name, {"zero": [5e-2], "projection": [5e-3]}, {"zero": [(0.1, 0.0)], "projection": [(0.3, 0.0)]}
    )
    text = paper_setting({ours_name: ours, theirs_name: theirs})
    assert f"#### {ours_name} against {theirs_name}" in text
    assert "| projection | 1.0e-4 | 0.005 |" in text  # eval motor MSE, ours then the paper's setting
    assert f"| {theirs_name}: projection (1 seeds) | 0.3 | 0 | 0.15 |" in text
    assert "Not stored yet: paper-images-short-mean, paper-images-short-sum." in text
    alone = paper_setting({ours_name: ours})
    assert "against" not in alone and f"Not stored yet: {theirs_name}" in alone


def test_the_ablation_block_waits_for_both_sides():
    assert "not all stored yet" in ablation({})
