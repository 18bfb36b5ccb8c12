"""Escapes and close approaches, checked against what would show them wrong: the escape time
of a Lennard-Jones pair and of a Henon-Heiles orbit against an independent integration
(scipy's DOP853 on hand-written equations) to 1e-6 relative; a bound pair and a bound
trimer never flagged; an escape in the middle of a batch of SIMD lanes the bits of the
same orbit alone; the closest approaches at step ends against a dense sampling of the
orbit, and the same from a reduced state (three bodies in the plane) as from a full one."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from survey.catalog.status import Status
from survey.numerics.events import Event, Sides, escape_defaults, escape_events
from survey.numerics.integrate import EVENTS, integrate, integrate_batch
from survey.physics.families import initial_state
from survey.physics.system import System
from survey.physics.terms import make_expression, make_potential

from test_lanes import same

LJ = make_potential("lennard_jones", {}, "pair")
TIGHT = dict(rtol=1e-12, atol=1e-12)


def lj_pair_escape(r0, v, b, radius):
    """The time two unit masses of a Lennard-Jones pair, r0 apart and moving apart at v
    with impact parameter b (angular momentum mu v b), reach distance `radius`: the
    relative motion in polar coordinates, integrated by scipy."""
    mu = 0.5
    L = mu * v * b

    def f(t, z):
        r, pr = z
        du = 4.0 * (-12.0 * r ** -13 + 6.0 * r ** -7)
        return [pr / mu, L * L / (mu * r ** 3) - du]
    hit = lambda t, z: z[0] - radius      # noqa: E731
    hit.terminal, hit.direction = True, 1
    pr0 = mu * v * np.sqrt(max(0.0, 1.0 - (b / r0) ** 2))
    sol = solve_ivp(f, (0.0, 1e3), [r0, pr0], method="DOP853", events=hit, rtol=1e-13,
                    atol=1e-13)
    return sol.t_events[0]


def pair_start(r0, v, b):
    """Body 0 at the origin, body 1 at (r0, 0), moving apart at relative speed v with
    impact parameter b (the transverse part of the relative velocity v b / r0)."""
    w = np.array([np.sqrt(max(0.0, 1.0 - (b / r0) ** 2)), b / r0]) * v
    return np.array([0.0, 0.0, r0, 0.0, *(-w / 2), *(w / 2)])


def test_a_lennard_jones_pair_escapes_when_an_independent_integration_says():
    system = System(np.ones(2), 2, (LJ,))
    radius, binding = escape_defaults(system)
    assert 7.0 < radius < 9.0 and 0.0 < binding < 2e-3     # twice where |u| < 1e-3, ~8 sigma
    for r0, v, b in [(1.12, 2.5, 0.0), (1.0, 2.2, 0.4), (1.5, 3.0, 1.2)]:
        y0 = pair_start(r0, v, b)
        assert system.energy(y0) > 0.0
        out = integrate(system, y0, 100.0, events=escape_events(system, radius, binding),
                        **TIGHT)
        expected = lj_pair_escape(r0, v, b, radius)
        assert out.status == Status.EVENT and expected.size == 1
        assert abs(out.t - expected[0]) <= 1e-6 * expected[0], (out.t, expected)


def test_bound_pairs_and_a_bound_trimer_are_never_flagged():
    system = System(np.ones(2), 2, (LJ,))
    events = escape_events(system, *escape_defaults(system))
    # below dissociation (E < 0): a vibrating, a rotating and a nearly unbound pair
    for r0, v, b in [(1.12, 1.0, 0.0), (1.2, 1.5, 0.9), (1.12, 1.99, 0.0)]:
        y0 = pair_start(r0, v, b)
        assert system.energy(y0) < 0.0
        out = integrate(system, y0, 2000.0, events=events)
        assert out.status == Status.OK and out.crossings.index.size == 0
    trimer = System(np.ones(3), 2, (LJ,))
    starts = [initial_state(trimer, "equilibrium", positions=[[0.0, 0.0], [1.12, 0.0],
                                                              [0.56, 0.97]], seed=s,
                            energy=-1.2) for s in range(4)]
    for out in integrate_batch(trimer, starts, 1000.0, events=escape_events(
            trimer, *escape_defaults(trimer))):
        assert out.status == Status.OK


def test_an_escape_mid_batch_in_lanes_is_the_orbit_alone():
    """Trimers above dissociation among bound ones: the lanes of the escaping orbits end at
    their escapes and take the next starts; every outcome, its closest approaches too, the
    bits of its orbit alone."""
    trimer = System(np.ones(3), 2, (LJ,))
    at = [[0.0, 0.0], [1.12, 0.0], [0.56, 0.97]]
    starts = np.array([initial_state(trimer, "equilibrium", positions=at, seed=s,
                                     energy=e) for s, e in
                       enumerate([-1.5, -0.6, -0.3, 0.2, -1.8, -0.5, 0.5, -2.0, -0.4, 0.1,
                                  -1.0, 0.3])])
    events = escape_events(trimer, *escape_defaults(trimer))
    record = np.full(len(starts), EVENTS)
    options = dict(events=events, approach=True, thin=0.005)
    alone = [integrate_batch(trimer, starts[j:j + 1], 300.0, record=record[j:j + 1],
                             lanes=1, **options)[0] for j in range(len(starts))]
    assert sum(o.status == Status.EVENT for o in alone) >= 4
    assert sum(o.status == Status.OK for o in alone) >= 3
    for L in (4, 8):
        batch = integrate_batch(trimer, starts, 300.0, record=record, lanes=L, **options)
        for j, (a, b) in enumerate(zip(batch, alone)):
            assert same(a, b) == [], (L, j, same(a, b))


@pytest.mark.parametrize("kind", ["reduced", "full", "four bodies in 3-D"])
def test_closest_approaches_in_lanes_are_those_of_each_orbit_alone(kind):
    """A batch computes its lanes' closest approaches at step ends in SIMD loops over every
    lane (driver.near_terms), at a job's start and a terminal event for its lane alone:
    each orbit's record -- pairs, least perimeter and area, thin time -- and every other
    output are the bits of the orbit alone, whether every orbit records approaches or one
    in four (the others' lanes computed and ignored); full and reduced states, and four
    bodies in 3-D (six pairs; triangles are recorded for three bodies)."""
    if kind == "four bodies in 3-D":
        system = System(np.ones(4), 3, (make_potential("perimetric_power"),))
        tetrahedron = [[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]]
        starts = [initial_state(system, "equilibrium", positions=tetrahedron,
                                displacement=0.2, speed=0.5, seed=s) for s in range(12)]
    else:
        system = System(np.ones(3), 2, (make_potential("perimetric_power"),))
        starts = [initial_state(system, "equilateral", delta=float(d))
                  for d in np.linspace(0.5, 6.0, 12)]
    starts = np.array(starts)
    events = [Event(Sides(offset=-1e6), direction=1)] if kind == "full" else []
    options = dict(events=events, approach=True, thin=0.01, **TIGHT)
    for record in (np.full(12, EVENTS), np.where(np.arange(12) % 4 == 0, EVENTS, 0)):
        alone = [integrate_batch(system, starts[j:j + 1], 30.0, record=record[j:j + 1],
                                 lanes=1, **options)[0] for j in range(12)]
        batch = integrate_batch(system, starts, 30.0, record=record, lanes=8, **options)
        for j, (a, b) in enumerate(zip(batch, alone)):
            assert same(a, b) == [], (kind, j, same(a, b))
            if record[j]:
                kept = a.near[:2 * 6] if kind == "four bodies in 3-D" else a.near
                assert a.near.size and np.all(np.isfinite(kept)), a.near
            else:
                assert a.near.size == 0


def test_a_henon_heiles_orbit_escapes_through_the_exit_an_independent_run_finds():
    system = System(np.ones(1), 2, (make_expression(
        "external", "(x**2 + y**2)/2 + x**2*y - y**3/3"),))
    radius = 10.0

    def f(t, z):
        x, y, px, py = z
        return [px, py, -x - 2 * x * y, -y - x * x + y * y]
    hit = lambda t, z: z[0] ** 2 + z[1] ** 2 - radius ** 2      # noqa: E731
    hit.terminal, hit.direction = True, 1
    rng = np.random.default_rng(3)
    exits = np.array([90.0, 210.0, 330.0])
    seen = set()
    for _ in range(8):
        y, py = rng.uniform(-0.5, 0.5), rng.uniform(-0.4, 0.4)
        px = np.sqrt(0.5 - y * y + 2 * y ** 3 / 3 - py * py)
        y0 = np.array([0.0, y, px, py])
        out = integrate(system, y0, 500.0, events=escape_events(system, radius), **TIGHT)
        sol = solve_ivp(f, (0.0, 500.0), y0, method="DOP853", events=hit, rtol=1e-13,
                        atol=1e-13)
        assert out.status == Status.EVENT and sol.t_events[0].size == 1
        t = sol.t_events[0][0]
        assert abs(out.t - t) <= 1e-6 * t, (out.t, t)
        angle = np.degrees(np.arctan2(out.y[1], out.y[0]))
        theirs = np.degrees(np.arctan2(*sol.y_events[0][0][1::-1]))
        gap = lambda a: np.abs((a - exits + 180.0) % 360.0 - 180.0)    # noqa: E731
        assert np.argmin(gap(angle)) == np.argmin(gap(theirs))
        seen.add(int(np.argmin(gap(angle))))
    assert len(seen) >= 2               # not every start leaves by one exit


@pytest.mark.parametrize("measure", ["perimetric_power", "areal_barrier"])
def test_closest_approaches_at_step_ends_against_a_dense_sampling(measure):
    """The step-end minima bound the sampled ones from above and miss them by little,
    from a reduced state (three bodies in the plane under one triplet term, the third
    rebuilt from the others) as from the full one (a sides event forces the full frame);
    the thin time within a few percent of the sampled one."""
    system = System(np.ones(3), 2, (make_potential(measure),))
    y0 = initial_state(system, "equilateral", delta=3.0) if measure.startswith("peri") \
        else initial_state(system, "areal_example")
    thin = 0.2 * np.sqrt(3) / 36
    t_eval = np.linspace(0.0, 40.0, 400001)
    for events in ([], [Event(Sides(offset=-1e6), direction=1)]):
        out = integrate(system, y0, 40.0, approach=True, thin=thin, t_eval=t_eval,
                        events=events, **TIGHT)
        q = out.samples[:, :6].reshape(-1, 3, 2)
        pairs = [(0, 1), (0, 2), (1, 2)]
        r = np.stack([np.linalg.norm(q[:, i] - q[:, j], axis=1) for i, j in pairs], 1)
        for p in range(3):
            least, when = out.near[2 * p], out.near[2 * p + 1]
            assert r[:, p].min() <= least <= r[:, p].min() * (1 + 1e-2)
            assert abs(when - t_eval[np.argmin(r[:, p])]) < 0.2
        u, v = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]
        area = 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
        perimeter = r.sum(1)
        assert perimeter.min() <= out.near[-5] <= perimeter.min() * (1 + 1e-2)
        assert area.min() <= out.near[-3] <= area.min() + 1e-2 * area.max()
        sampled_thin = np.mean(area / perimeter ** 2 < thin) * 40.0
        assert abs(out.near[-1] - sampled_thin) <= 0.05 * 40.0
