"""Terms written as formulas (physics.terms.make_expression): each built-in term written as
a formula gives the built-in forces and tangent forces; every formula's forces are minus
the gradient of its energy and its tangent forces their derivative (finite differences);
the energy of a one-body field is conserved along its orbits."""
import numpy as np
import pytest

from conftest import full_rhs
from survey.numerics.integrate import integrate
from survey.physics.system import System
from survey.physics.terms import make_expression, make_potential

HENON_HEILES = "(x**2 + y**2)/2 + x**2*y - y**3/3"
TODA = "(exp(2*y + 2*sqrt(3)*x) + exp(2*y - 2*sqrt(3)*x) + exp(-4*y)) / 24 - 1/8"


def states(system, rng, count, n_tan=2, spread=0.25):
    """States near an equilateral-ish configuration with momenta and tangent vectors."""
    N, d = system.n_bodies, system.dim
    base = np.zeros((N, d))
    for i in range(N):
        base[i, :2] = 1.2 * np.cos(2 * np.pi * i / N), 1.2 * np.sin(2 * np.pi * i / N)
    out = []
    for _ in range(count):
        q = base + spread * rng.normal(size=(N, d))
        p = rng.normal(size=(N, d))
        out.append(np.concatenate([q.ravel(), p.ravel(), rng.normal(size=n_tan * system.n)]))
    return out


PAIRS = [  # (formula term, the built-in term it writes)
    (make_expression("pair", "4*eps*((s/r)**12 - (s/r)**6)", {"eps": 0.8, "s": 1.1}),
     make_potential("lennard_jones", {"epsilon": 0.8, "sigma": 1.1}, kind="pair")),
    (make_expression("pair", "k * exp(-g*r) / r", {"k": 1.5, "g": 0.7}),
     make_potential("yukawa", {"coupling": 1.5, "gamma": 0.7}, kind="pair")),
    (make_expression("triplet", "P**2/2"), make_potential("perimetric_power")),
    (make_expression("triplet", "(a + b + c)**2/2"), make_potential("perimetric_power")),
    (make_expression("triplet", "c0 * P**3 / 3", {"c0": 0.4}),
     make_potential("perimetric_power", {"coupling": 0.4, "exponent": 3.0})),
    (make_expression("triplet", "w/A + A**2", {"w": 2.0}), make_potential("areal_barrier")),
    (make_expression("triplet", "-exp(-A)/A"), make_potential("areal_yukawa")),
]


@pytest.mark.parametrize("formula,builtin", PAIRS, ids=lambda t: t.describe()[:40])
@pytest.mark.parametrize("dim", [2, 3])
def test_a_builtin_term_written_as_a_formula_gives_its_forces(formula, builtin, dim):
    rng = np.random.default_rng(3)
    masses = np.array([1.0, 1.3, 0.7, 1.1])[:4 if dim == 3 else 3]
    ours, theirs = System(masses, dim, formula), System(masses, dim, builtin)
    assert ours.model.par.ndim == 2              # a formula runs on the general path
    for y in states(ours, rng, 20):
        a, b = full_rhs(ours, y, 2), full_rhs(theirs, y, 2)
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())
        assert ours.potential_energy(y) == pytest.approx(theirs.potential_energy(y),
                                                         rel=1e-13)


FORMULAS = [
    System(np.ones(1), 2, make_expression("external", HENON_HEILES)),
    System(np.ones(1), 2, make_expression("external", TODA)),
    System(np.array([1.0, 2.0]), 3, make_expression("external", "k*(x**2 + 2*y**2 + 3*z**2)"
                                                    " + x*y*z", {"k": 0.5}, True, dim=3)),
    System(np.array([1.0, 1.2, 0.9]), 2,
           make_expression("triplet", "exp(-a*b*c) + (a**2 + b**2 + c**2)/4 + A")),
    System(np.array([1.0, 1.2, 0.9, 1.1]), 3,
           (make_expression("triplet", "sqrt(a*b*c) + log(P)"),
            make_expression("pair", "1/r**6 - 1/r**3", mass_weighted=True))),
]


@pytest.mark.parametrize("system", FORMULAS, ids=lambda s: s.describe()[:50])
def test_formula_forces_are_minus_the_gradient_and_tangents_their_derivative(system):
    rng = np.random.default_rng(5)
    nq = system.n // 2
    for y in states(system, rng, 6, n_tan=0, spread=0.15):
        rates = full_rhs(system, y)
        h = 1e-6
        for c in range(nq):
            e = np.zeros(system.n)
            e[c] = h
            fd = -(system.potential_energy(y + e) - system.potential_energy(y - e)) / (2 * h)
            assert rates[nq + c] == pytest.approx(fd, rel=1e-6, abs=1e-7)
        dq = np.concatenate([rng.normal(size=nq), np.zeros(nq)])
        tangent = full_rhs(system, np.concatenate([y, dq]), 1)[system.n + nq:]
        fd = (full_rhs(system, y + h * dq)[nq:] - full_rhs(system, y - h * dq)[nq:]) / (2 * h)
        np.testing.assert_allclose(tangent, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("formula,energy", [(HENON_HEILES, 0.125), (TODA, 1.0)])
def test_a_one_body_field_conserves_its_energy(formula, energy):
    system = System(np.ones(1), 2, make_expression("external", formula))
    y = np.array([0.0, 0.1, 0.0, 0.0])
    kinetic = energy - system.potential_energy(y)
    y[2:] = np.sqrt(2 * kinetic) * np.array([0.6, 0.8])
    out = integrate(system, y, 500.0, rtol=1e-12, atol=1e-12)
    assert out.ok
    assert system.energy(out.y) == pytest.approx(energy, rel=1e-10)


@pytest.mark.parametrize("kind,text,params,weighted,message", [
    ("triplet", "a**2 * b", {}, False, "not symmetric"),
    ("triplet", "P", {}, True, "mass_weighted applies to pair and external"),
    ("external", "x + q", {}, False, "unknown name 'q'"),
    ("external", "x", {"x": 1.0}, False, "must be a name that is not a variable"),
    ("pair", "k", {"k": 1.0}, False, "does not depend on r"),
    ("pair", "r", {"k": float("nan")}, False, "finite number"),
    ("quartet", "r", {}, False, "unknown kind"),
])
def test_bad_formula_terms_are_refused(kind, text, params, weighted, message):
    with pytest.raises(ValueError, match=message):
        make_expression(kind, text, params, weighted)


def test_a_formulas_parameter_is_a_grid_axis(tmp_path):
    from survey.pipeline.config import parse_config
    config = parse_config(f"""
[survey]
name = "f"
output = "{tmp_path / 'f.nc'}"
[system]
interactions = [{{kind = "triplet", expression = "k * P**2 / 2", params = {{k = {{start = 1.0, stop = 2.0, num = 3}}}}}}]
[initial]
family = "equilateral"
delta = 3.0
""")
    assert [a.name for a in config.axes] == ["triplet_formula_k"]
    systems = [config.system(i) for i in range(3)]
    assert [s.terms[0].params for s in systems] == [(1.0,), (1.5,), (2.0,)]
    y = np.array([1.0, 0.1, -0.5, 0.9, -0.4, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    forces = [full_rhs(s, y)[6:] for s in systems]
    np.testing.assert_allclose(forces[2], 2 * forces[0], rtol=1e-14)


def test_deviations_in_an_external_field_keep_the_centre_of_mass():
    """An external field breaks translation invariance: a deviation of the centre of mass
    (for one body, any deviation) grows like any other, so none is projected out."""
    from survey.numerics.indicators import deviation_vectors
    one = System(np.ones(1), 2, make_expression("external", HENON_HEILES))
    assert not one.translation_invariant
    y = np.array([0.0, 0.1, 0.3, 0.2])
    w = deviation_vectors(one, y, 2, seed=0)
    assert w.shape == (2, 4) and np.allclose(np.linalg.norm(w, axis=1), 1.0)
    two = System(np.ones(2), 2, make_expression("external", HENON_HEILES))
    w = deviation_vectors(two, np.r_[0.0, 0.1, 0.2, 0.0, 0.3, 0.2, -0.1, 0.1], 3, seed=1)
    assert np.abs(w[:, :2] + w[:, 2:4]).max() > 0.1      # centre-of-mass shifts kept
