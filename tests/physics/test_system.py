"""The right-hand side of many orbits at once (`rhs_lanes`, variable-major lanes) gives every
lane the bits of the one-state path (`rhs`): three bodies in the plane under every
perimetric and areal profile (the SIMD paths), and other systems (lane by lane, or the
SIMD loops of sums of terms); and the one-state code written for three bodies in the plane
gives the bits of the general N-body path. Random states over twelve decades, unequal
masses, up to three tangent vectors, lane counts on both sides of the vector width, and
states with exact zeros (collinear, axis-aligned, at rest) where only the signs of zeros
could tell the paths apart."""
import numpy as np
import pytest

from survey.physics.lanes import rhs_lanes, workspace_size
from survey.physics.system import System, _leading_forces, rhs
from survey.physics.terms import TERMS, make_expression, make_potential

PLANAR = [t for t in TERMS if t.kind == "triplet" and t.name.startswith(("perimetric",
                                                                           "areal"))]
OTHERS = {"four bodies": (4, 2, (make_potential("perimetric_power"),)),
          "3-D": (3, 3, (make_potential("areal_barrier"),)),
          "3-D perimetric": (3, 3, (make_potential("perimetric_power", {"exponent": 3.0}),)),
          "four areal bodies in 3-D": (4, 3, (make_potential("areal_power"),)),
          "a sum of terms": (3, 2, (make_potential("perimetric_power"),
                                    make_potential("lennard_jones", {}, "pair"))),
          "two triplet terms": (5, 2, (make_potential("areal_barrier"),
                                       make_potential("perimetric_power"),
                                       make_potential("axilrod_teller"))),
          "triplet terms and pairs in 3-D": (4, 3, (
              make_potential("perimetric_power"), make_potential("areal_barrier"),
              make_potential("gravity", {"G": 0.5}, "pair"))),
          # terms written as formulas: their programs run over the lanes (a formula of
          # the sides, lane by lane through rhs)
          "Henon-Heiles": (1, 2, (make_expression(
              "external", "(x**2 + y**2)/2 + x**2*y - y**3/3"),)),
          "a mass-weighted field in 3-D": (3, 3, (make_potential("perimetric_power"),
                                                  make_expression(
              "external", "x**2 + y**2/2 + z**4 + x*y*z + exp(-x**2)", {}, True, dim=3))),
          "a pair formula": (3, 2, (make_potential("perimetric_power"), make_expression(
              "pair", "4*e*((1/r)**12 - (1/r)**6)", {"e": 0.7}, True))),
          "a perimetric formula of four bodies": (4, 2, (make_expression(
              "triplet", "P**2/2 + tanh(P)"),)),
          "an areal formula in 3-D": (3, 3, (make_expression("triplet", "w/A + A**2",
                                                             {"w": 2.0}),)),
          "a formula of the sides": (3, 2, (make_expression("triplet", "a*b*c + a + b + c"),))}


def states(rng, nq, n_tan, count):
    """count states (count, 2 nq (1 + n_tan)), some with exact zeros."""
    y = rng.normal(size=(count, 2 * nq * (1 + n_tan))) * 10.0 ** rng.uniform(-6, 6, (count, 1))
    y[::5, rng.integers(0, nq, 3)] = 0.0          # axis-aligned, some bodies at rest
    y[::7, 1:nq:2] = 0.0                          # collinear on the x axis
    return y


def check(system, rng, trials=60):
    model = system.model
    nq = system.n // 2
    for trial in range(trials):
        n_tan, L = trial % 4, (1, 3, 16, 17)[trial % 4 if trial % 8 < 4 else 3 - trial % 4]
        y = states(rng, nq, n_tan, L)
        nf = y.shape[1]
        Y = np.ascontiguousarray(y.T).ravel()
        dY = np.full(Y.size, np.nan)
        registers = 0 if model.expr is None else model.expr.regs.size
        rhs_lanes(0.0, Y, dY, L, model, n_tan,
                  np.zeros(workspace_size(L, nf, registers)), None)
        for k in range(L):
            one = np.full(nf, np.nan)
            rhs(0.0, y[k], one, model, n_tan)
            assert dY[k::L].tobytes() == one.tobytes(), (n_tan, L, k, y[k])


@pytest.mark.parametrize("shift", [False, True], ids=["defaults", "shifted"])
@pytest.mark.parametrize("term", PLANAR, ids=[t.name for t in PLANAR])
def test_the_simd_lanes_give_the_general_path_bit_for_bit(term, shift):
    """At the terms' defaults (the paper's P^2 / 2 and |A|^2 / 2 have loops of their own)
    and at other parameters (a power other than 2 takes the general profile's loops)."""
    rng = np.random.default_rng(7)
    params = {p.name: 1.1 * p.default + 0.05 if shift else p.default
              for p in term.parameters}
    check(System(rng.uniform(0.5, 2.0, 3), 2, make_potential(term.name, params)), rng)


@pytest.mark.parametrize("case", OTHERS, ids=list(OTHERS))
def test_other_systems_in_lanes_give_the_same_bits(case):
    """Perimetric and areal terms of more bodies or in 3-D, alone, together and beside pair
    and ATM terms (lanes.general_lanes from SIMD_MIN lanes on, `rhs` lane by lane below);
    the paper's term beside a pair term (its own SIMD loops, then the pair's)."""
    rng = np.random.default_rng(8)
    N, d, terms = OTHERS[case]
    check(System(rng.uniform(0.5, 2.0, N), d, terms), rng, trials=16)


@pytest.mark.parametrize("term", PLANAR, ids=[t.name for t in PLANAR])
def test_the_planar_path_gives_the_general_n_body_path_bit_for_bit(term):
    """The paper's systems never reach the general path (see system._encode), so it is
    called here directly on the same states."""
    rng = np.random.default_rng(9)
    params = {p.name: 1.1 * p.default + 0.05 for p in term.parameters}
    model = System(rng.uniform(0.5, 2.0, 3), 2, make_potential(term.name, params)).model
    masses, d, measure, prof, par = model[:5]
    for n_tan in range(4):
        for y in states(rng, 6, n_tan, 40):
            own, general = np.full(y.size, np.nan), np.full(y.size, np.nan)
            rhs(0.0, y, own, model, n_tan)
            _leading_forces(y, general, masses, 3, 2, measure, prof, (par[0], par[1]), n_tan)
            assert own.tobytes() == general.tobytes(), (n_tan, y)


@pytest.mark.parametrize("shift", [False, True], ids=["defaults", "shifted"])
@pytest.mark.parametrize("term", PLANAR, ids=[t.name for t in PLANAR])
def test_a_reduced_state_has_the_full_states_rates_to_roundoff(term, shift):
    """Bodies 0 and 1 alone (the third rebuilt from the centre of mass at rest at 0), each
    lane count: their rates are those of the full state, for the orbit and for tangent
    vectors without a centre-of-mass part, within a few units of roundoff (the rebuilt
    third body is the full one's to roundoff, not its bits)."""
    rng = np.random.default_rng(9)
    params = {p.name: 1.1 * p.default + 0.05 if shift else p.default
              for p in term.parameters}
    system = System(rng.uniform(0.5, 2.0, 3), 2, make_potential(term.name, params))
    model = system.model
    masses = model.masses
    m = masses[None, :, None]
    for L, n_tan in ((1, 0), (3, 1), (4, 2), (16, 3), (17, 1)):
        q, p = rng.normal(size=(2, L, 3, 2))
        q -= (m * q).sum(1, keepdims=True) / masses.sum()
        p -= p.sum(1, keepdims=True) * m / masses.sum()
        w = rng.normal(size=(L, n_tan, 2, 3, 2))
        w[:, :, 0] -= (m[:, None] * w[:, :, 0]).sum(2, keepdims=True) / masses.sum()
        w[:, :, 1] -= w[:, :, 1].sum(2, keepdims=True) * m[:, None] / masses.sum()
        full = np.concatenate([q.reshape(L, 6), p.reshape(L, 6), w.reshape(L, -1)], 1)
        part = np.concatenate([q[:, :2].reshape(L, 4), p[:, :2].reshape(L, 4),
                               w[:, :, :, :2].reshape(L, -1)], 1)
        rates = []
        ratios = (masses[0] / masses[2], masses[1] / masses[2])
        for y, rb in ((full, None), (part, ratios)):
            Y = np.ascontiguousarray(y.T).ravel()
            dY = np.full(Y.size, np.nan)
            rhs_lanes(0.0, Y, dY, L, model, n_tan,
                      np.zeros(workspace_size(L, full.shape[1])), rb)
            rates.append(dY.reshape(-1, L).T)
        kept = np.concatenate([12 * b + np.r_[0:4, 6:10] for b in range(1 + n_tan)])
        scale = np.abs(rates[0]).max()
        assert np.all(np.isfinite(rates[1]))
        assert np.abs(rates[0][:, kept] - rates[1]).max() <= 1e-14 * scale, (L, n_tan)


def test_every_specialised_copy_of_the_forces_is_named_with_its_test():
    """physics.forces.SPECIALISED names every hand-specialised copy of the perimetric and
    areal forces, what it specialises and the test of this file that holds it there: each
    name must exist and each test must be here; and every compiled function of the physics
    layer named for these forces is the reference, a listed copy, or a part of one (a new
    copy left out of the table fails here)."""
    import importlib

    from survey.physics import forces, lanes, system
    here = {name for name in globals() if name.startswith("test_")}
    listed = set()
    for copy, reference, test in forces.SPECIALISED:
        for dotted in (copy.split(" ")[0], reference):
            module, name = dotted.rsplit(".", 1)
            assert hasattr(importlib.import_module(f"survey.{module}"), name), dotted
        assert test in here, test
        listed.add(copy.split(" ")[0])
    reference = {"physics.forces.perimetric_forces", "physics.forces.areal_forces"}
    parts = {   # pieces of the reference or of a listed copy, held by the same tests
        "physics.forces._perimetric_sides", "physics.forces._perimetric_tangent",
        "physics.forces._areal_vector", "physics.forces._areal_gradients",
        "physics.forces._areal_tangent", "physics.lanes._perimetric_lane",
        "physics.lanes._areal_lane", "physics.lanes._areal_sides"}
    for module in (forces, lanes, system):
        for name, value in vars(module).items():
            func = getattr(value, "py_func", None)
            if func is None or func.__module__ != module.__name__ or not (
                    "perimetric" in name or "areal" in name):
                continue
            dotted = f"{module.__name__.removeprefix('survey.')}.{name}"
            assert dotted in listed | reference | parts, f"{dotted} is not in SPECIALISED"
