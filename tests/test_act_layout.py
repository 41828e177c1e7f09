"""``primspace.predict`` predicts the rest of a motion from its beginning, nothing else: no module
under predict/ imports ``primspace.act``, has "scene" in its file name or defines a public name
with "scene" in it; the scene policy, its peers and features live in ``primspace.act``, behind
one planner interface (:class:`primspace.act.planner.Planner`)."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

PREDICT = Path(__file__).resolve().parents[1] / "src" / "primspace" / "predict"
MODULES = sorted(PREDICT.rglob("*.py"))


def _imported(tree: ast.Module, package: str) -> list[str]:
    """The modules ``tree`` imports, relative imports resolved against ``package``."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
            named = ".".join(base + ([node.module] if node.module else []))
            out += [named] + [f"{named}.{alias.name}" for alias in node.names]
    return out


def _public_names(tree: ast.Module) -> list[str]:
    """The names a module defines at its top level (functions, classes, assignments) and lists in ``__all__``."""
    names = []
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.append(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names += [t.id for t in targets if isinstance(t, ast.Name)]
            if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets) and isinstance(
                node.value, (ast.List, ast.Tuple)
            ):
                names += [e.value for e in node.value.elts if isinstance(e, ast.Constant)]
    return [n for n in names if not n.startswith("_")]


def test_predict_has_modules_to_check():
    assert len(MODULES) > 5 and (PREDICT / "__init__.py") in MODULES


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PREDICT)))
def test_no_module_under_predict_imports_act_or_names_a_scene(path):
    assert "scene" not in path.name.lower(), f"{path.name}: a scene module under predict/"
    tree = ast.parse(path.read_text(encoding="utf-8"))
    acting = [m for m in _imported(tree, "primspace.predict") if m == "primspace.act" or m.startswith("primspace.act.")]
    assert not acting, f"{path.name} imports {acting}"
    scenes = [n for n in _public_names(tree) if "scene" in n.lower()]
    assert not scenes, f"{path.name} defines {scenes}"


def test_act_exports_the_scene_policy_and_one_planner_interface():
    import primspace.act as act
    from primspace.act.planner import Planner
    from primspace.act.planners import PolicyPlanner, ProMPPlanner
    from primspace.act.scene_policy import ScenePolicy

    assert act.ScenePolicy is ScenePolicy and act.Planner is Planner
    assert issubclass(PolicyPlanner, Planner) and issubclass(ProMPPlanner, Planner)
    with pytest.raises(TypeError):
        Planner(None)  # abstract: a planner says how it plans
    assert ScenePolicy.planner.__annotations__["return"] in (PolicyPlanner, "PolicyPlanner")


class _Policy:
    """A stand-in for a fitted scene policy: the belief is the frame's mean, every later look surprises."""

    def see(self, frames):
        return np.asarray(frames, dtype=float).mean(axis=(1, 2, 3))[:, None]

    def correct(self, primitive, step, belief, seen):
        return seen

    def replan(self, primitive, belief, executed):
        return np.full((6, 2), float(belief[0]) + len(executed))


def test_the_policy_planner_is_reset_before_each_episode():
    from primspace.act.planners import PolicyPlanner

    planner = PolicyPlanner(_Policy(), 0, every=2)
    assert [s for s in range(6) if planner.due(s)] == [0, 2, 4]
    frame = np.ones((4, 4, 3))
    assert planner.plan(0, frame, np.zeros((1, 2)))[0, 0] == 2.0 and planner.corrections == []
    assert planner.plan(2, 3 * frame, np.zeros((3, 2)))[0, 0] == 6.0 and planner.corrections == [2]
    planner.reset()
    assert planner.belief is None and planner.current is None and planner.corrections == []
    assert planner.plan(0, frame, np.zeros((1, 2)))[0, 0] == 2.0  # a new episode starts from its first frame
    assert not any(PolicyPlanner(_Policy(), 0, every=None).due(s) for s in range(1, 6))  # open loop
