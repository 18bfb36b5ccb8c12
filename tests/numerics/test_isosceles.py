"""The isosceles plane (numerics.isosceles) against an independent integration of its
reduced Hamiltonian H = p_b^2 + 3/4 p_h^2 + U (paper, Special Solutions): scipy's DOP853 on
(b, h, p_b, p_h), switching sgn(b) at each pair collision by a terminal event."""
import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from survey.catalog.errors import ConfigError
from survey.numerics.isosceles import (
    plane_coordinates,
    plane_periodic,
    plane_section,
    plane_start,
    plane_state,
)
from survey.physics.system import System


def reduced_section(start, n, t_final, forces, height=0.0, tol=1e-13, direction=1):
    """The first n upward (direction = -1: downward) crossings of h = height, (t, b, p_b),
    of the reduced plane with forces(b, h, s) = (dp_b/dt, dp_h/dt) on the side s = sgn(b)."""
    def rhs(t, y, s):
        b, h, pb, ph = y
        fb, fh = forces(b, h, s)
        return [2 * pb, 1.5 * ph, fb, fh]

    def kink(t, y, s):
        return y[0]
    kink.terminal = True

    def section(t, y, s):
        return y[1] - height
    section.direction = direction
    out, t, y = [], 0.0, np.array(start, dtype=float)
    s = 1.0 if y[0] > 0 else -1.0
    while len(out) < n and t < t_final:
        kink.direction = -s
        sol = solve_ivp(rhs, (t, t_final), y, method="DOP853", rtol=tol, atol=tol,
                        events=[kink, section], args=(s,))
        out += [(te, ye[0], ye[2]) for te, ye in zip(sol.t_events[1], sol.y_events[1])
                if te > 1e-9]
        if sol.status != 1:
            break
        t, y, s = sol.t_events[0][0], sol.y_events[0][0].copy(), -s
    return np.array(out[:n])


def perimetric(b, h, s):
    """U = P^2/2, P = |b| + sqrt(b^2 + 4h^2): b'' = 2 dp_b/dt = -2 U'(P)(sgn b + b/r),
    h'' = 3/2 dp_h/dt = -6 U'(P) h / r (the paper's equations)."""
    r = np.sqrt(b * b + 4 * h * h)
    P = s * b + r
    return -P * (s + b / r), -4 * P * h / r


def areal(b, h, s):
    """U = 2/|A| + |A|^2, |A| = |b h|/2 (b, h > 0 here): b'' = -U'(|A|) |h| sgn b,
    h'' = -3/4 U'(|A|) |b| sgn h."""
    A = 0.5 * b * h
    U1 = -2 / A ** 2 + 2 * A
    return -0.5 * U1 * h, -0.5 * U1 * b


def test_the_plane_in_three_body_coordinates():
    system = System.create()
    y = plane_state(0.7, -0.4, 0.3, 0.9)
    assert np.allclose(plane_coordinates(y), (0.7, -0.4, 0.3, 0.9), rtol=0, atol=1e-15)
    q, p = system.split(y)
    assert np.allclose(q.sum(0), 0) and np.allclose(p.sum(0), 0)
    P = 0.7 + np.sqrt(0.49 + 4 * 0.16)
    assert system.energy(y) == pytest.approx(0.09 + 0.75 * 0.81 + P ** 2 / 2, rel=1e-14)
    start = plane_start(system, 1.0, 0.0, 0.69, 0.0)
    assert system.energy(plane_state(*start)) == pytest.approx(1.0, rel=1e-14)
    assert plane_start(system, 1.0, 0.0, 0.8, 0.0) is None        # beyond the shell


@pytest.mark.parametrize("b, p_b", [(0.69, 0.0), (0.1, 0.75)])
def test_perimetric_sections_agree_with_the_reduced_hamiltonian(b, p_b):
    """Regular orbits of the perimetric plane (the outermost invariant curve, and one in
    the large island about p_b = 0.8): the first 100 crossings of h = 0, each after dozens
    of passages through the pair collision, agree with the reduced integration to 1e-8."""
    system = System.create()
    start = plane_start(system, 1.0, 0.0, b, p_b)
    mine = plane_section(system, start, 400.0, crossings=101, rtol=1e-13, atol=1e-13)
    assert mine.passages > 100 and mine.energy_error < 1e-10
    points = np.stack([mine.t, mine.b, mine.p_b], 1)
    points = points[points[:, 0] > 1e-9][:100]
    ref = reduced_section(start, 100, 400.0, perimetric)
    assert len(points) == len(ref) == 100
    assert np.abs(points[:, 0] - ref[:, 0]).max() < 1e-8
    assert np.abs(points[:, 1:] - ref[:, 1:]).max() < 1e-8


def test_areal_sections_agree_without_passages():
    """Under the areal barrier the plane never reaches b = 0 (|A| = 0 costs infinite
    energy): a regular orbit's section h = 1.5 at E = 3.5 agrees with the reduced
    integration to 1e-8."""
    system = System.create(potential="areal_barrier")
    start = plane_start(system, 3.5, 1.5, 1.9, 0.0)
    mine = plane_section(system, start, 2000.0, height=1.5, crossings=100, rtol=1e-13,
                         atol=1e-13)
    ref = reduced_section(start, 100, 2000.0, areal, height=1.5)
    assert mine.passages == 0 and mine.b.size == ref.shape[0] == 100
    assert np.abs(mine.b - ref[:, 1]).max() < 1e-8
    assert np.abs(mine.p_b - ref[:, 2]).max() < 1e-8


def test_passing_the_collision_exactly_is_what_keeps_the_energy():
    """Stepping across the force's jump at b = 0 (a plain integration) costs the
    integrator its order and half its steps; no step across it (measured: energy errors
    1.1e-9 and 1.9e-11 at rtol 1e-13, 9.8e-11 and 2.6e-12 at 1e-14)."""
    from survey.numerics.integrate import integrate
    system = System.create()
    start = plane_start(system, 1.0, 0.0, 0.69, 0.0)
    plain = integrate(system, plane_state(*start), 200.0, rtol=1e-13, atol=1e-13)
    exact = plane_section(system, start, 200.0, crossings=10 ** 6, rtol=1e-13, atol=1e-13)
    plain_error = abs(system.energy(plain.y) - 1.0)
    assert exact.passages > 50 and exact.t_end == 200.0
    assert exact.energy_error < 1e-10 and plain_error > 10 * exact.energy_error
    assert plain.n_rejected > 0.3 * plain.n_steps      # every jump: a cascade of rejections


@pytest.mark.parametrize("sign", [1, -1])
def test_the_equilateral_breathing_through_triple_collision_is_elliptic(sign):
    """Under U = P^2/2 at E = 1 the equilateral triangle breathes through the triple
    collision (h = +-(sqrt 3 / 2) b, b = (sqrt 2 / 3) sin 3t): a fixed point of the
    section map at (0, +-1/sqrt 2) with period 2 pi / 3. Along its ray the Hessian is
    constant (U is homogeneous of degree 2) with transverse frequency 3/sqrt 2 in
    mass-weighted coordinates, so the map's trace is 2 cos(pi sqrt 2) = -0.5325."""
    system = System.create()
    orbit = plane_periodic(system, 1.0, 0.0, (0.02 * sign, 0.69 * sign))
    assert orbit.converged and orbit.crossings == 1 and orbit.residual < 1e-10
    assert abs(orbit.b[0]) < 1e-9 and abs(orbit.p_b[0] - sign / np.sqrt(2)) < 1e-9
    assert orbit.period == pytest.approx(2 * np.pi / 3, abs=1e-9)
    assert orbit.kind == "elliptic"
    assert orbit.trace == pytest.approx(2 * np.cos(np.pi * np.sqrt(2)), abs=1e-4)
    assert np.linalg.det(orbit.jacobian) == pytest.approx(1.0, abs=1e-4)   # area kept
    # asked for two points on the section, it says the orbit has one
    twice = plane_periodic(system, 1.0, 0.0, (0.0, 0.7 * sign), crossings=2)
    assert twice.converged and twice.crossings == 1 and twice.same_as(orbit)


def test_the_areal_equilateral_breathing_has_the_quadrature_period():
    """Under the areal barrier the equilateral triangle breathes between the barrier's
    walls: on the section h = 1.5 at b = sqrt 3, p_b = sqrt((E - U)/2) (the breathing's
    kinetic energy b'^2/2 is 2 p_b^2), period 2 int db / sqrt(2 (E - U(b))) with
    A = sqrt(3) b^2 / 4."""
    system = System.create(potential="areal_barrier")
    E = 3.5

    def U(b):
        A = np.sqrt(3) * b * b / 4
        return 2 / A + A * A
    orbit = plane_periodic(system, E, 1.5, (1.7, 0.35))
    assert orbit.converged and orbit.kind == "elliptic"
    assert orbit.b[0] == pytest.approx(np.sqrt(3), abs=1e-9)
    assert orbit.p_b[0] == pytest.approx(np.sqrt((E - U(np.sqrt(3))) / 2), abs=1e-9)
    from scipy.optimize import brentq
    b_min, b_max = (brentq(lambda b: U(b) - E, lo, hi) for lo, hi in ((0.5, 1.5), (1.6, 3)))
    def dt(theta):      # b = b_min + (b_max - b_min)(1 - cos theta)/2: no end singularity
        b = b_min + (b_max - b_min) * (1 - np.cos(theta)) / 2
        return (b_max - b_min) * np.sin(theta) / 2 / np.sqrt(2 * (E - U(b)))
    period = 2 * quad(dt, 0, np.pi, epsabs=1e-12, epsrel=1e-12)[0]
    assert orbit.period == pytest.approx(period, rel=1e-8)


def test_periodic_orbits_close_in_the_reduced_integration():
    """The hyperbolic fixed point on p_b = 0 and the elliptic period-2 orbit of the
    perimetric plane at E = 1 come back to where they started (and the period-2 orbit's
    two points swap) in the independent reduced integration."""
    system = System.create()
    saddle = plane_periodic(system, 1.0, 0.0, (0.57, 0.0))
    assert saddle.converged and saddle.kind == "hyperbolic" and saddle.trace > 2.5
    mu = np.sort(np.abs(saddle.multipliers))
    assert mu[0] * mu[1] == pytest.approx(1.0, abs=1e-6)
    pair = plane_periodic(system, 1.0, 0.0, (0.18, 0.0), crossings=2)
    assert pair.converged and pair.crossings == 2 and pair.kind == "elliptic"
    for orbit in (saddle, pair):
        ref = reduced_section(plane_start(system, 1.0, 0.0, orbit.b[0], orbit.p_b[0]),
                              orbit.crossings, 20.0, perimetric)
        assert ref[-1, 0] == pytest.approx(orbit.period, abs=1e-8)
        assert np.abs(ref[:, 1] - np.roll(orbit.b, -1)).max() < 1e-8
        assert np.abs(ref[:, 2] - np.roll(orbit.p_b, -1)).max() < 1e-8


def test_a_guess_newton_cannot_use_is_reported_not_raised():
    system = System.create()
    orbit = plane_periodic(system, 1.0, 0.0, (0.3, 0.45), crossings=3, max_iter=1)
    assert not orbit.converged and orbit.residual > 1e-10
    from survey.pipeline.orbits import describe_periodic
    assert describe_periodic(orbit).startswith("not found")


def test_a_plane_workflow_draws_its_section(tmp_path, capsys):
    from survey.cli import orbit_workflow
    path = tmp_path / "plane.toml"
    path.write_text('[[plane]]\nname = "iso"\nenergy = 1.0\nstarts = [[0.69, 0.0], '
                    '[0.3, 0.2]]\ncrossings = 40\nt_final = 100.0\n'
                    'periodic = [[0.0, 0.7], [0.0, 0.71], [0.57, 0.0]]\n')
    written = orbit_workflow(path, tmp_path)
    assert [p.name for p in written] == ["iso_plane.png"]
    out = capsys.readouterr().out
    assert "from (b, p_b) = (0.69, 0)" in out and "passages through b = 0" in out
    assert "guess (0, 0.7), k = 1: 1 point (0.00000000, 0.70710678)" in out
    assert "period T = 2.0943951024, elliptic" in out
    assert "guess (0, 0.71), k = 1: the same orbit as guess 1" in out
    assert "guess (0.57, 0), k = 1: 1 point (0.56590170, 0.00000000)" in out


def test_a_plane_workflow_archives_manifolds_that_verify(tmp_path, capsys):
    """manifolds = [...] grows the manifolds of the orbits found there (an elliptic one
    has none, and says so), draws them and archives them in NAME_plane.nc, which `verify`
    computes again bit for bit -- and which fails once a point is moved."""
    import netCDF4

    from survey.cli import main, orbit_workflow
    path = tmp_path / "plane.toml"
    path.write_text('[[plane]]\nname = "iso"\nenergy = 1.0\nstarts = [[0.69, 0.0]]\n'
                    'crossings = 10\nt_final = 100.0\nmanifolds = [[0.57, 0.0], [0.0, 0.7]]\n'
                    'manifold_length = 0.5\nmanifold_gap = 0.1\n')
    written = orbit_workflow(path, tmp_path)
    assert [p.name for p in written] == ["iso_plane.png", "iso_plane.nc"]
    out = capsys.readouterr().out
    assert "of the hyperbolic orbit at (0.56590170, 0.00000000) (multiplier 2.21884)" in out
    assert "unstable +: " in out and "stable -: " in out
    assert "guess (0, 0.7), k = 1: the orbit there is elliptic" in out
    archive = tmp_path / "iso_plane.nc"
    assert main(["verify", str(archive), "--cells", "3"]) == 0
    assert "3 of " in capsys.readouterr().out
    with netCDF4.Dataset(archive, "a") as ds:
        ds["b"][0] = ds["b"][0] + 1e-15
    assert main(["verify", str(archive), "--cells", "3"]) == 1
    assert "point 0 (branch 0, level 0)" in capsys.readouterr().out


@pytest.mark.parametrize("text, key, message", [
    ('starts = [[0.8, 0.0]]', "[[plane]] 1.starts[0]", "not on the section"),
    ('starts = [[0.1]]', "[[plane]] 1.starts", "[b, p_b] pairs"),
    ('starts = [[0.1, 0.0]]\ncrossing = 3', "[[plane]] 1.crossing", "unknown key"),
    ('starts = [[0.1, 0.0]]\nsystem = {masses = [1.0, 2.0, 1.0]}', "[[plane]] 1.system",
     "three unit masses"),
    ('starts = [[0.1, 0.0]]\ntol = 0.0', "[[plane]] 1.tol", "finite number >="),
    ('starts = [[0.1, 0.0]]\nperiodic = [[0.1, 0.0, 0]]', "[[plane]] 1.periodic",
     "[b, p_b, k]"),
    ('starts = [[0.1, 0.0]]\nperiodic = [0.1, 0.0]', "[[plane]] 1.periodic", "guesses"),
    ('starts = [[0.1, 0.0]]\nperiodic = [[0.1, 0.0], [0.9, 0.0]]',
     "[[plane]] 1.periodic[1]", "not on the section"),
    ('starts = [[0.1, 0.0]]\nmanifolds = [[0.9, 0.0]]', "[[plane]] 1.manifolds[0]",
     "not on the section"),
    ('starts = [[0.1, 0.0]]\nmanifolds = [0.57, 0.0]', "[[plane]] 1.manifolds", "guesses"),
    ('starts = [[0.1, 0.0]]\nmanifold_gap = 0.0', "[[plane]] 1.manifold_gap",
     "finite number >="),
    ('starts = [[0.1, 0.0]]\nmanifold_length = 1e9', "[[plane]] 1.manifold_length",
     "<= 1000"),
])
def test_plane_tables_that_cannot_work_are_refused(tmp_path, text, key, message):
    from survey.pipeline.orbits import load_workflow
    path = tmp_path / "plane.toml"
    path.write_text(f'[[plane]]\nname = "iso"\nenergy = 1.0\n{text}\n')
    with pytest.raises(ConfigError) as err:
        load_workflow(path)
    assert err.value.key == key and message in str(err.value)


@pytest.fixture(scope="module")
def saddle_manifolds():
    """The manifolds of the perimetric plane's hyperbolic fixed point (0.5659, 0) at E = 1
    (multiplier 2.21884), each branch to arclength 3.5: far enough for first homoclinic
    crossings."""
    from survey.numerics.isosceles import plane_manifolds
    system = System.create()
    saddle = plane_periodic(system, 1.0, 0.0, (0.57, 0.0))
    return system, plane_manifolds(system, 1.0, 0.0, saddle, length=3.5, gap=0.05)


def reduced_map(system, x, n, backward=False):
    """P^n(x) (P^-n backward: the time-reversed orbit's downward crossings) in the
    independent reduced integration."""
    b, h, p_b, p_h = plane_start(system, 1.0, 0.0, *x)
    way = -1 if backward else 1
    out = reduced_section((b, h, way * p_b, way * p_h), n, 100.0 * n, perimetric,
                          direction=way)
    return np.array([out[-1, 1], way * out[-1, 2]])


def test_manifolds_leave_along_the_eigenvectors_of_an_independent_jacobian(saddle_manifolds):
    from survey.numerics.isosceles import eigen2
    system, found = saddle_manifolds
    x, step = np.array([found.orbit.b[0], found.orbit.p_b[0]]), 1e-5
    J = np.column_stack([(reduced_map(system, x + e, 1) - reduced_map(system, x - e, 1))
                         / (2 * step) for e in (np.array([step, 0.0]), np.array([0.0, step]))])
    reference = eigen2(J)
    for (mu, v), (mu_ref, v_ref) in zip(eigen2(found.orbit.jacobian), reference):
        assert mu == pytest.approx(mu_ref, rel=1e-6)
        assert min(np.hypot(*(v - v_ref)), np.hypot(*(v + v_ref))) < 1e-6
    assert reference[0][0] == pytest.approx(2.21884, abs=1e-5)


def test_manifold_points_match_an_independent_integration(saddle_manifolds):
    """The first 20 points of the unstable and the stable + branch beyond 0.05 of the
    fixed point (levels 8 to 14: each P^n, or P^-n, of its seed) agree with the reduced
    integration from the same seed to 1e-8."""
    from survey.numerics.isosceles import manifold_seeds
    system, found = saddle_manifolds
    made = manifold_seeds(system, 1.0, 0.0, found.orbit)
    fixed = np.array([found.orbit.b[0], found.orbit.p_b[0]])
    for index, backward in ((0, False), (2, True)):
        branch = found.branches[index]
        far = np.flatnonzero(np.hypot(*(branch.points - fixed).T) > 0.05)[:20]
        assert far.size == 20 and branch.level[far].max() >= 10
        for i in far:
            ref = reduced_map(system, made[index].seed(branch.seed[i]), branch.level[i],
                              backward)
            assert np.abs(ref - branch.points[i]).max() < 1e-8, (index, i)


def test_stable_branches_are_the_unstable_ones_reflected(saddle_manifolds):
    """The section map's reversing symmetry R (b, p_b) -> (b, -p_b) (time reversal with
    the reflection h -> -h, which keeps the section h = 0 crossed upwards) takes the
    unstable manifold to the stable one: R of each stable point P^-n(x* + s v_s) is
    P^n(R x* + s R v_s) (x* is on Fix R to 1e-10), and R v_s is an unstable eigenvector."""
    from survey.numerics.isosceles import manifold_seeds
    from survey.numerics.manifolds import seeds
    system, found = saddle_manifolds
    made = manifold_seeds(system, 1.0, 0.0, found.orbit)
    R = np.array([1.0, -1.0])
    assert abs(found.orbit.p_b[0]) < 1e-10                   # the fixed point is on Fix R
    for stable in (2, 3):
        mirrored = R * made[stable].vector
        twin = next(k for k in (0, 1) if np.hypot(*(made[k].vector - mirrored)) < 1e-7)
        forward = seeds(made[0].step, R * made[0].fixed, mirrored, made[stable].stretch, 1)
        branch = found.branches[stable]
        picks = np.linspace(0, branch.points.shape[0] - 1, 20).astype(int)
        for i in picks:
            ours = forward.point(branch.seed[i], branch.level[i])
            assert np.abs(ours - R * branch.points[i]).max() < 1e-8, (stable, i)
        assert found.branches[twin].points.shape == branch.points.shape


def test_a_first_homoclinic_point_goes_to_the_fixed_point_both_ways(saddle_manifolds):
    """The unstable - and stable + branches cross by arclength 3.5; the crossing, mapped
    forward as often as the stable branch took to bring it out, and backward as often as
    the unstable one did, lands near the fixed point both times."""
    system, found = saddle_manifolds
    h = next(h for h in found.homoclinic if (h.unstable, h.stable) == (1, 2))
    assert h.accuracy < 1e-8 and h.angle > 0.1
    fixed = np.array([found.orbit.b[0], found.orbit.p_b[0]])
    u, s = found.branches[h.unstable], found.branches[h.stable]
    near_u = u.level[np.searchsorted(u.arclength, h.arclength_unstable)]
    near_s = s.level[np.argmin(np.hypot(*(s.points - h.point).T))]
    for n, backward in ((near_s, False), (near_u, True)):
        end = reduced_map(system, h.point, n, backward)
        assert np.hypot(*(end - fixed)) < 1e-3, (n, backward, end)
