"""Orbits integrated as SIMD lanes give, each, the bits of the same orbit integrated alone:
every field of every Outcome, whatever the lane count (below and above the SIMD width, and
not a divisor of the job count; a batch's last jobs move to fewer lanes, then one after
another to one), whatever the neighbours -- orbits that end early (terminal
events, a nonfinite start, a step limit) and hand their lane to the next start, orbits that
record crossings, samples and the torus analysis' fine samples beside orbits that record
nothing -- for the paper's perimetric and areal systems (SIMD right-hand sides) and for
other systems (lane by lane)."""
import numpy as np
import pytest

from survey.numerics.events import Event, Sides
from survey.numerics.indicators import deviation_vectors
from survey.numerics.integrate import EVAL, EVENTS, FINE, integrate_batch
from survey.numerics.sections import section_event
from survey.physics.families import initial_state
from survey.physics.system import System
from survey.physics.terms import make_potential


def same(a, b) -> list[str]:
    """The Outcome fields in which a and b differ, bit for bit."""
    differ = []
    for field in a._fields:
        x, y = getattr(a, field), getattr(b, field)
        pairs = zip(x, y) if field == "crossings" else [(x, y)]
        if not all(np.shape(p) == np.shape(q) and np.asarray(p).tobytes() ==
                   np.asarray(q).tobytes() for p, q in pairs):
            differ.append(field)
    return differ


def check(system, starts, tangents, record, t_final, lanes, **options):
    batch = {L: integrate_batch(system, starts, t_final, tangents=tangents, record=record,
                                lanes=L, **options) for L in lanes}
    for j in range(len(starts)):
        alone = integrate_batch(system, starts[j:j + 1], t_final,
                                tangents=None if tangents is None else tangents[j:j + 1],
                                record=record[j], lanes=1, **options)[0]
        for L, outcomes in batch.items():
            assert same(outcomes[j], alone) == [], (j, L, same(outcomes[j], alone))
    return batch[lanes[0]]


def test_the_paper_system_in_lanes_with_every_ending_and_record():
    system = System.create()
    deltas = np.linspace(0.0, 8.0, 37)
    starts = np.array([initial_state(system, "equilateral", delta=float(d)) for d in deltas])
    starts[5, 0] = np.nan                                   # ends at once: nonfinite
    tangents = np.array([deviation_vectors(system, y if np.isfinite(y).all() else starts[0],
                                           1, 0, c) for c, y in enumerate(starts)])
    record = np.zeros(len(starts), dtype=np.int64)
    record[2::5] = FINE                 # their samples wait for a batch's dense output
    record[::4] = EVENTS | EVAL | FINE
    record[1::7] = EVENTS                                  # terminal events end these early
    events = [section_event(system), Event(Sides(offset=-11.0), direction=1, terminal=True)]
    outcomes = check(system, starts, tangents, record, 40.0, (1, 3, 4, 6, 8, 16, 17, 32),
                     megno=True, events=events, t_eval=np.linspace(1.0, 40.0, 8),
                     sample_tangents=True, t_fine=(np.arange(399) + 0.5) * 0.1,
                     max_events=20)
    statuses = {o.status.name for o in outcomes}
    assert {"OK", "EVENT", "NONFINITE"} <= statuses, statuses


def test_a_step_limit_and_backwards_in_time():
    system = System.create()
    starts = np.array([initial_state(system, "sides", delta=float(d))
                       for d in np.linspace(0.0, 1.0, 18)])
    outcomes = check(system, starts, None, np.full(18, EVAL), (0.0, -30.0), (1, 17),
                     max_steps=2000, t_eval=np.linspace(0.0, -30.0, 7))
    assert {o.status.name for o in outcomes} >= {"STEP_LIMIT"}


def test_the_areal_system_in_lanes():
    system = System.create(potential="areal_barrier")
    starts = np.array([initial_state(system, "equilateral", side=3 ** 0.5, delta=float(d),
                                     energy=9.0) for d in np.linspace(0.0, 3.0, 16)])
    tangents = np.array([deviation_vectors(system, y, 2, 1) for y in starts])
    check(system, starts, tangents, np.full(16, EVENTS), 20.0, (1, 5, 8, 16), megno=True,
          events=[section_event(system)])


@pytest.mark.parametrize("case", ["four bodies", "pair and triplet terms",
                                  "3-D pairs and triangles", "planar pairs of every profile",
                                  "perimetric and pair terms", "areal and triplet terms",
                                  "perimetric and areal terms in 3-D"])
def test_other_systems_in_lanes(case):
    """Systems beyond the paper's, in the SIMD loops of each term (system._general_lanes):
    a perimetric term of four bodies, perimetric and areal terms together in 3-D, LJAT, in
    3-D with unequal masses and mass-weighted gravity, pair profiles algebraic and
    transcendental, and pair or ATM terms beside the paper's perimetric or areal term,
    with one or two tangent vectors."""
    rng = np.random.default_rng(3)
    d, n_tan = 2, 1
    if case == "four bodies":
        system = System(np.array([1.0, 1.2, 0.8, 1.1]), 2, make_potential("perimetric_power"))
    elif case == "pair and triplet terms":
        system = System(np.ones(3), 2, (make_potential("lennard_jones", {}, "pair"),
                                        make_potential("axilrod_teller", {"strength": 0.3})))
    elif case == "3-D pairs and triangles":
        d, n_tan = 3, 2
        system = System(np.array([1.0, 1.3, 0.7, 1.1]), 3, (
            make_potential("lennard_jones", {}, "pair"),
            make_potential("gravity", {"G": 0.5}, "pair"),
            make_potential("axilrod_teller", {"strength": 0.4})))
    elif case == "planar pairs of every profile":
        system = System(np.array([1.0, 0.9, 1.2]), 2, (
            make_potential("yukawa", {}, "pair"), make_potential("power", {}, "pair"),
            make_potential("lennard_jones", {}, "pair")))
    elif case == "perimetric and areal terms in 3-D":
        d, n_tan = 3, 2
        system = System(np.array([1.0, 1.3, 0.7]), 3, (
            make_potential("perimetric_power"), make_potential("areal_barrier")))
    elif case == "perimetric and pair terms":
        system = System(np.array([1.0, 0.9, 1.2]), 2, (
            make_potential("perimetric_power"), make_potential("lennard_jones", {}, "pair"),
            make_potential("gravity", {"G": 0.5}, "pair")))
    else:
        n_tan = 2
        system = System(np.array([1.0, 1.1, 0.8]), 2, (
            make_potential("areal_barrier"), make_potential("axilrod_teller",
                                                            {"strength": 0.4})))
    N = system.n_bodies
    base = np.array([[np.cos(a), np.sin(a), 0.3 * np.sin(2 * a)][:d]
                     for a in np.linspace(0, 2 * np.pi, N, endpoint=False)]) * 1.2
    starts = np.array([system.state(base + 0.05 * rng.normal(size=(N, d)),
                                    0.2 * rng.normal(size=(N, d))) for _ in range(17)])
    tangents = np.array([deviation_vectors(system, y, n_tan, 2) for y in starts])
    check(system, starts, tangents, np.zeros(17, dtype=np.int64), 5.0, (1, 17), megno=True)


@pytest.mark.parametrize("t_final", [60.0, -25.0])
def test_waiting_fine_samples_are_the_dense_output_of_their_steps(t_final):
    """Orbit samples at t_fine, built in batches after their steps (the steps' stages
    copied and kept), are the bits of the same times sampled at t_eval, whose dense output
    is built at the step itself -- in lanes, alone, and at a grid's last time, which is the
    last step's end."""
    system = System.create()
    starts = np.array([initial_state(system, "equilateral", delta=float(d))
                       for d in np.linspace(0.0, 9.0, 20)])
    grid = np.linspace(0.0, t_final, 1201)
    for lanes in (1, 16):
        fine = integrate_batch(system, starts, t_final, record=FINE, t_fine=grid, lanes=lanes)
        now = integrate_batch(system, starts, t_final, record=EVAL, t_eval=grid, lanes=lanes)
        for a, b in zip(fine, now):
            assert np.isfinite(a.fine).all() and a.fine.shape == (grid.size, system.n)
            assert a.fine.tobytes() == b.samples.tobytes()


def test_a_batch_gives_its_lanes_the_costliest_orbits_first():
    """Along the equilateral scan the chaotic orbits (delta >= 5) take 3-4x the steps of the
    regular ones near delta = 0: a batch starts them first, so its last lanes do not run
    them alone."""
    from survey.numerics.driver import Control
    from survey.numerics.integrate import _costliest_first
    system = System.create()
    deltas = [0.0, 6.0, 0.5, 7.0, 1.0, 8.0]
    starts = np.array([initial_state(system, "equilateral", delta=x) for x in deltas])
    control = Control(t0=0.0, t1=2000.0, n_tan=0, megno=False, rtol=1e-12, atol=1e-12,
                      n_err=starts.shape[1], max_steps=10**6, h0=0.0, h_max=0.0, h_min=0.0,
                      renorm_dt=1.0, time_limit=0.0)
    model = system.model
    order = _costliest_first(starts, model, control, 4, None)
    assert sorted(order[:3]) == [1, 3, 5], order
    full = integrate_batch(system, starts, 2000.0, lanes=1)
    assert min(full[k].n_steps for k in (1, 3, 5)) > 2 * max(full[k].n_steps for k in (0, 2, 4))


def test_the_driver_compiles_once_for_every_batch():
    """One compiled driver for every batch of a system's kind of state (here the relative
    motion; a second specialisation, e.g. from a Fortran-ordered argument, would double a
    new machine's first run): batches of more
    orbits than lanes (ordered by a pilot run), fewer, one, with and without tangent
    vectors, events and samples, backwards, all run the driver the first one compiled."""
    from survey.numerics.driver import _run
    system = System.create()
    starts = np.array([initial_state(system, "equilateral", delta=x)
                       for x in np.linspace(0.0, 6.0, 21)])
    tangents = np.array([deviation_vectors(system, y, 1, 0) for y in starts])
    integrate_batch(system, starts[:1], 1.0)
    compiled = set(_run.signatures)
    integrate_batch(system, starts, 3.0, tangents=tangents, megno=True)
    integrate_batch(system, starts[:5], (0.0, -2.0), events=[section_event(system)],
                    t_eval=np.linspace(0.0, -2.0, 5), t_fine=-np.arange(20) * 0.1)
    integrate_batch(system, starts[:1], 2.0, tangents=tangents[:1], lanes=1)
    assert set(_run.signatures) == compiled


def test_samples_in_a_reused_buffer_are_those_of_a_fresh_array():
    """Batches that write their orbit samples into this thread's reused buffer
    (reuse_samples, as a worker's cells do) get the bits and the NaNs past an orbit's end
    that a fresh array holds, whatever the buffer held before: a shorter batch's samples,
    then a longer one's under orbits cut short by their step budget."""
    system = System.create()
    starts = np.array([initial_state(system, "equilateral", delta=x) for x in (0.0, 3.0, 7.0)])
    for t_final, max_steps in ((20.0, 10**6), (60.0, 10**6), (30.0, 300)):
        grid = (np.arange(int(t_final / 0.1)) + 0.5) * 0.1
        fresh = integrate_batch(system, starts, t_final, t_fine=grid, max_steps=max_steps)
        reused = integrate_batch(system, starts, t_final, t_fine=grid, max_steps=max_steps,
                                 reuse_samples=True)
        for a, b in zip(fresh, reused):
            assert b.fine.shape == (grid.size, system.n)
            assert a.fine.tobytes() == b.fine.tobytes()
        cut = [np.isnan(b.fine[:, 0]).sum() for b in reused]
        assert (min(cut) > 0) == (max_steps == 300), cut
