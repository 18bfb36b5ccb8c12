"""The isosceles plane (numerics.isosceles) against an independent integration of its
reduced Hamiltonian H = p_b^2 + 3/4 p_h^2 + U (paper, Special Solutions): scipy's DOP853 on
(b, h, p_b, p_h), switching sgn(b) at each pair collision by a terminal event."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from survey.catalog.errors import ConfigError
from survey.numerics.isosceles import (
    plane_coordinates,
    plane_section,
    plane_start,
    plane_state,
)
from survey.physics.system import System


def reduced_section(start, n, t_final, forces, height=0.0, tol=1e-13):
    """The first n upward crossings of h = height, (t, b, p_b), of the reduced plane with
    forces(b, h, s) = (dp_b/dt, dp_h/dt) on the side s = sgn(b)."""
    def rhs(t, y, s):
        b, h, pb, ph = y
        fb, fh = forces(b, h, s)
        return [2 * pb, 1.5 * ph, fb, fh]

    def kink(t, y, s):
        return y[0]
    kink.terminal = True

    def section(t, y, s):
        return y[1] - height
    section.direction = 1
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


def test_a_plane_workflow_draws_its_section(tmp_path, capsys):
    from survey.cli import orbit_workflow
    path = tmp_path / "plane.toml"
    path.write_text('[[plane]]\nname = "iso"\nenergy = 1.0\nstarts = [[0.69, 0.0], '
                    '[0.3, 0.2]]\ncrossings = 40\nt_final = 100.0\n')
    written = orbit_workflow(path, tmp_path)
    assert [p.name for p in written] == ["iso_plane.png"]
    out = capsys.readouterr().out
    assert "from (b, p_b) = (0.69, 0)" in out and "passages through b = 0" in out


@pytest.mark.parametrize("text, key, message", [
    ('starts = [[0.8, 0.0]]', "[[plane]] 1.starts[0]", "not on the section"),
    ('starts = [[0.1]]', "[[plane]] 1.starts", "[b, p_b] pairs"),
    ('starts = [[0.1, 0.0]]\ncrossing = 3', "[[plane]] 1.crossing", "unknown key"),
    ('starts = [[0.1, 0.0]]\nsystem = {masses = [1.0, 2.0, 1.0]}', "[[plane]] 1.system",
     "three unit masses"),
    ('starts = [[0.1, 0.0]]\ntol = 0.0', "[[plane]] 1.tol", "finite number >="),
])
def test_plane_tables_that_cannot_work_are_refused(tmp_path, text, key, message):
    from survey.pipeline.orbits import load_workflow
    path = tmp_path / "plane.toml"
    path.write_text(f'[[plane]]\nname = "iso"\nenergy = 1.0\n{text}\n')
    with pytest.raises(ConfigError) as err:
        load_workflow(path)
    assert err.value.key == key and message in str(err.value)
