"""Effects are types, registered once (furuta_gym.effects): every kind carries its force law,
units, MuJoCo form, diagnosis scale and physical sign, and no code outside the registry compares
effect names — adding an effect is one class plus tests."""

import ast
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import furuta_gym
from furuta_gym.diagnose._library import Candidate, layout_for
from furuta_gym.effects import EFFECT_KINDS, Effect, EffectKind, MujocoForm, effect_kind
from furuta_gym.systems import get_spec

ROOT = Path(furuta_gym.__file__).resolve().parent
SOURCES = [
    p
    for folder in (ROOT, ROOT.parent / "models", ROOT.parent / "controllers")
    for p in folder.rglob("*.py")
    if p != ROOT / "effects.py"
]
NAMES = set(EFFECT_KINDS)


def _names_in(node) -> set[str]:
    """Effect names among a node's string constants (itself, or a tuple/list/set of them)."""
    elts = node.elts if isinstance(node, (ast.Tuple, ast.List, ast.Set)) else [node]
    return {e.value for e in elts if isinstance(e, ast.Constant) and e.value in NAMES}


def _name_uses(tree) -> list[tuple[int, str]]:
    """(line, name): effect names compared (==, !=, in, not in), used as a table's keys, or glued
    into a candidate key ("name:joint") by an f-string."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            for side in [node.left, *node.comparators]:
                found += [(node.lineno, n) for n in _names_in(side)]
        elif isinstance(node, ast.Dict) and not any(isinstance(v, (ast.Tuple, ast.List)) for v in node.values):
            # a table keyed by effect name (a plant preset's list of Effect objects is not one)
            found += [(node.lineno, n) for k in node.keys if k is not None for n in _names_in(k)]
        elif isinstance(node, ast.JoinedStr):
            for part in node.values:
                if isinstance(part, ast.Constant) and any(part.value.startswith(f"{n}:") for n in NAMES):
                    found.append((node.lineno, part.value))
    return found


def test_no_effect_name_comparisons_outside_the_registry():
    offenders = [
        f"{p.relative_to(ROOT.parent)}:{line}: {name!r}"
        for p in SOURCES
        for line, name in _name_uses(ast.parse(p.read_text()))
    ]
    assert not offenders, "effect names compared outside furuta_gym/effects.py:\n" + "\n".join(offenders)


def test_the_scan_finds_a_comparison():
    tree = ast.parse(
        'if e.name == "spring" or c.name in ("stiction", "x"):\n    k = {"com_offset": 1}\n'
        'key = f"coulomb_friction:{j}"\n'
    )
    assert sorted(n for _, n in _name_uses(tree)) == ["com_offset", "coulomb_friction:", "spring", "stiction"]


def test_every_kind_is_complete():
    for name, kind in EFFECT_KINDS.items():
        assert kind.name == name and isinstance(kind, EffectKind)
        assert len(kind.units) == 2 and all(kind.units)
        if kind.typical is not None:
            assert all(t > 0 for t in kind.typical), name
        assert not (kind.has_memory and kind.typical is not None), f"{name}: a stateful library candidate"
        if kind.has_memory:
            assert kind.home, f"{name} has memory but says nowhere where it is applied"
    with pytest.raises(ValueError, match="unknown effect 'springy'"):
        effect_kind("springy")


def test_a_new_kind_is_one_class():
    """A kind registered by subclassing is usable by Effect, WithEffects and MuJoCo's form alike."""

    class _Cubic(EffectKind):
        name, units, physically_positive, typical = "test_cubic_spring", ("N m/rad^3", "N/m^3"), True, (1.0, 1.0)

        def law(self, effect, smoothing, xp):
            return lambda q, qd: -effect.coefficient * q**3

    try:
        e = Effect("test_cubic_spring", "alpha", 2.0)
        assert e.unit(get_spec("furuta")) == "N m/rad^3"
        assert float(e.generalized_force(jnp.asarray(0.5), jnp.asarray(0.0))) == pytest.approx(-0.25)
        form = MujocoForm(np.zeros(2), np.zeros(2), np.zeros(2), shift=np.zeros(2))
        e.kind.to_mujoco(e, 0, form)
        assert form.laws == {0: [e]} and not form.stiffness.any()
        # ... and the diagnosis library tests it, with its law as the regressor
        layout = layout_for("furuta")
        assert Candidate("test_cubic_spring", "alpha") in layout.candidates
        theta = layout.nominal()
        theta[layout.index("test_cubic_spring:beta")] = 3.0
        model = layout.model(jnp.asarray(theta))
        q, qd = jnp.asarray([0.0, 0.2]), jnp.zeros(2)
        extra = model.nonconservative_force(q, qd) - layout.model(jnp.asarray(layout.nominal())).nonconservative_force(
            q, qd
        )
        np.testing.assert_allclose(np.asarray(extra), [0.0, -3.0 * 0.2**3], atol=1e-15)
        with pytest.raises(ValueError, match="registered twice"):
            type("_Again", (EffectKind,), {"name": "test_cubic_spring", "units": ("1", "1")})
    finally:
        del EFFECT_KINDS["test_cubic_spring"]


def test_mujoco_forms_of_the_native_kinds():
    form = MujocoForm(np.zeros(2), np.zeros(2), np.zeros(2), shift=np.zeros(2))
    for e in (
        Effect("spring", "alpha", 2e-3, reference=0.1),
        Effect("viscous_friction", "beta", 1e-5),
        Effect("com_offset", "beta", 0.01),
        Effect("input_gain", "u", -0.2),
        Effect("input_delay", "u", 0.004),
        Effect("coulomb_friction", "alpha", 1e-3),
    ):
        e.kind.to_mujoco(e, -1 if e.kind.on_input else e.joint_index(get_spec("furuta")), form)
    np.testing.assert_allclose(form.stiffness, [2e-3, 0.0])
    np.testing.assert_allclose(form.stiff_ref, [2e-4, 0.0])
    np.testing.assert_allclose(form.damping, [0.0, 1e-5])
    np.testing.assert_allclose(form.shift, [0.0, 0.01])
    assert form.gain == pytest.approx(0.8)
    assert [x.name for x in form.laws[0]] == ["coulomb_friction"] and set(form.laws) == {0}
