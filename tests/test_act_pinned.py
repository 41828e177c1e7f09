"""The acting numbers pinned before the scene policy, its peers and features moved into
``primspace.act`` (0.9.0): the scene policy's plans, the scene-only peers' motions, and one
episode of each planner in MuJoCo (closed loop, open loop, the block moved, ProMP
re-conditioned). A pure move must reproduce them.

On the tiny simulated set of test_scene_policy.py (touch and push, a 3 x 3 grid of blocks,
T = 31, with frames; the centre block of each primitive held out), the scaler fitted on the
other demonstrations. The numbers are sums and selected values, per CPU class
(:func:`conftest.pinned_for_this_cpu`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from conftest import pinned_for_this_cpu
from primspace.data.scaling import JointScaler
from test_scene_policy import T, held_out, simulate

PINNED = Path(__file__).with_suffix(".json")
STEPS = (0, 6, 12)
EVERY = 6

pytestmark = pytest.mark.usefixtures("one_thread")  # one thread (tests/conftest.py)


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    data = simulate(tmp_path_factory.mktemp("act_pinned") / "sim.h5")
    held = held_out(data)
    fitted = np.setdiff1d(np.arange(len(data)), held)
    scaler = JointScaler().fit(data.motor[fitted])
    motor = scaler.transform(data.motor).astype(np.float64)
    return dict(data=data, held=held, fitted=fitted, scaler=scaler, motor=motor, frames=np.asarray(data.images))


def _digest(a) -> list[float]:
    """Sum, sum of squares and three entries of ``a``: enough to see any change."""
    a = np.asarray(a, dtype=np.float64).reshape(-1)
    return [float(a.sum()), float((a**2).sum()), float(a[0]), float(a[len(a) // 2]), float(a[-1])]


def numbers(case) -> dict:
    """The pinned numbers of ``case`` (module docstring)."""
    from primspace.act import ProMPPlanner, run_episode
    from primspace.act.episode import BlockMove
    from primspace.act.planners import PolicyPlanner
    from primspace.act.scene_peers import ContextualProMPPeer, NearestFramePeer
    from primspace.act.scene_policy import ScenePolicy
    from primspace.predict.peers import ProMPPeer
    from primspace.predict.primitives import primitives_from_clusters
    from primspace.sim.execute import Executor
    from primspace.sim.scene import Scene

    data, held, fitted, motor, frames = (case[k] for k in ("data", "held", "fitted", "motor", "frames"))
    labels = data.labels
    out = {}
    policy = ScenePolicy(steps=tuple(range(0, T - 1, EVERY)), label_names=data.label_names)
    policy.fit(motor[fitted], labels[fitted], None, frames[fitted])
    out["policy"] = _digest(policy.forecast(motor[held], labels=labels[held], frames=frames[held]).motor)
    small = ScenePolicy(steps=STEPS, label_names=data.label_names).fit(
        motor[fitted], labels[fitted], None, frames[fitted]
    )
    out["policy steps 0 6 12"] = _digest(small.forecast(motor[held], labels=labels[held], frames=frames[held]).motor)
    for name, peer in (("contextual ProMP", ContextualProMPPeer()), ("nearest frame", NearestFramePeer())):
        peer.fit(motor[fitted], labels[fitted], frames=frames[fitted])
        seen = np.where((np.arange(T) < 1)[None, :, None], motor[held], np.nan)
        observed = np.broadcast_to(np.arange(T) < 1, (len(held), T))
        out[name] = _digest(peer.predict(seen, observed, labels[held], frames=frames[held]))
    promp = ProMPPeer().fit(motor[fitted], labels[fitted], None)
    i = int(held[labels[held] == data.label_names.index("push")][0])
    x, y, size = (float(v) for v in data.params[i, :3])
    k, label, scene = policy.primitives_.resolve("push"), int(labels[i]), Scene()
    planners = {
        "closed": (PolicyPlanner(policy, k, EVERY), None),
        "open": (PolicyPlanner(policy, k, None), None),
        "moved": (PolicyPlanner(policy, k, EVERY), BlockMove(9, 0.0, 0.04)),
        "promp": (ProMPPlanner(promp, label, T, EVERY), None),
        "promp moved": (ProMPPlanner(promp, label, T, EVERY), BlockMove(9, 0.0, 0.04)),
    }
    for name, (planner, move) in planners.items():
        with Executor("push", x, y, size, T, scene=scene) as executor:
            episode = run_episode(planner, executor, data.motor[i, 0], case["scaler"], T, move)
        out[f"episode {name}"] = {
            "motor": _digest(episode.motor),
            "first_plan": _digest(episode.first_plan),
            "success": bool(episode.success),
            "looks": [int(s) for s in episode.plan_steps],
            "corrections": [int(s) for s in getattr(planner, "corrections", [])],
        }
    codes = np.random.default_rng(0).normal(size=(24, 4))
    clusters = primitives_from_clusters(codes, 3, np.repeat([0, 1, 2], 8), ("a", "b", "c"), random_state=0)
    out["clusters"] = [[int(r) for r in clusters.members(c)] for c in range(clusters.count)]
    return out


def _close(got, want, where: str) -> None:
    if isinstance(want, dict):
        assert set(got) == set(want), where
        for key in want:
            _close(got[key], want[key], f"{where}/{key}")
    elif isinstance(want, list) and want and isinstance(want[0], float):
        assert got == pytest.approx(want, rel=1e-6, abs=1e-9), where
    else:
        assert got == want, where


@pytest.mark.slow
def test_acting_keeps_its_numbers(case):
    pinned = pinned_for_this_cpu(json.loads(PINNED.read_text()), "acting numbers", vendor=True)
    _close(numbers(case), pinned, "acting")
