"""How far a double-precision run of the chaotic 'sides' orbit (delta = 0) can be trusted:
the orbit in quad precision (heyoka's Taylor integrator in real128 at two tolerances, which
must agree) against survey's DOP853 at rtol = atol = 1e-12 and 1e-14, and the true minimum
of the perimeter over [0, 200]. Needs heyoka (pip install '.[bench]'); writes
results/sides_quad.md.

    python workflows/checks/sides_quad.py
"""
from pathlib import Path

import heyoka as hy
import numpy as np

from survey.numerics.integrate import integrate
from survey.physics.families import initial_state
from survey.physics.system import System

PAIRS = ((0, 1), (1, 2), (2, 0))
STEP, SPAN = 0.01, 200.0


def perimeter(y):
    return sum(np.hypot(y[:, 2 * j] - y[:, 2 * i], y[:, 2 * j + 1] - y[:, 2 * i + 1])
               for i, j in PAIRS)


def quad_orbit(y0, grid, tol):
    """Three bodies under U = P^2/2 (the paper's perimetric potential), written from the
    paper's forces: each side pulls its ends together with U'(P) = P."""
    q = hy.make_vars(*[f"q{i}" for i in range(6)])
    p = hy.make_vars(*[f"p{i}" for i in range(6)])
    sides = []
    for i, j in PAIRS:
        rx, ry = q[2 * j] - q[2 * i], q[2 * j + 1] - q[2 * i + 1]
        length = hy.sqrt(rx * rx + ry * ry)
        sides.append((i, j, rx / length, ry / length, length))
    P = sum(s[4] for s in sides)
    force = [0.0] * 6
    for i, j, ex, ey, _ in sides:
        force[2 * i] += P * ex
        force[2 * j] -= P * ex
        force[2 * i + 1] += P * ey
        force[2 * j + 1] -= P * ey
    F = hy.real128
    ta = hy.taylor_adaptive([(q[i], p[i]) for i in range(6)] + [(p[i], force[i])
                                                                for i in range(6)],
                            np.array([F(float(v)) for v in y0]), tol=F(tol), fp_type=F)
    return ta, np.array([F(float(t)) for t in grid])


def main():
    system = System.create()
    y0 = initial_state(system, "sides", delta=0.0)
    grid = np.arange(0.0, SPAN + STEP / 2, STEP)
    runs = {}
    for tol in (1e-26, 1e-32):
        ta, g = quad_orbit(y0, grid, tol)
        runs[tol] = ta.propagate_grid(g)[5].astype(float)
    quad = runs[1e-32]
    agree = float(np.max(np.abs(runs[1e-26] - quad)))
    k = int(np.argmin(perimeter(quad)))
    ta, _ = quad_orbit(y0, grid, 1e-32)
    fine = np.arange(grid[k] - 2 * STEP, grid[k] + 2 * STEP, 1e-5)
    ta.propagate_until(hy.real128(float(fine[0])))
    near = ta.propagate_grid(np.array([hy.real128(float(t)) for t in fine]))[5].astype(float)
    m = int(np.argmin(perimeter(near)))
    lines = ["# The 'sides' orbit in quad precision", "",
             f"`python workflows/checks/sides_quad.py`: heyoka {hy.__version__} real128 "
             f"Taylor at tol 1e-26 and 1e-32 (largest difference over [0, {SPAN:g}] on a "
             f"{STEP:g} grid: {agree:.1e}), E = {system.energy(y0):.6f}.", "",
             f"True minimum of the perimeter over [0, {SPAN:g}]: P = "
             f"{perimeter(near)[m]:.6f} at t = {fine[m]:.4f}.", "",
             "| DOP853 rtol = atol | first t with \\|y - y_quad\\| > 1e-6 | > 1e-3 | > 0.1 | "
             "its min P over [0, 200] (t) |", "| --- | --- | --- | --- | --- |"]
    for tol in (1e-12, 1e-14):
        out = integrate(system, y0, (0.0, SPAN), rtol=tol, atol=tol, t_eval=grid)
        diff = np.max(np.abs(out.samples[:, :12] - quad), axis=1)
        when = [f"{grid[np.argmax(diff > c)]:.1f}" if np.any(diff > c) else "never"
                for c in (1e-6, 1e-3, 0.1)]
        P = perimeter(out.samples)
        lines.append(f"| {tol:g} | {' | '.join(when)} | {P.min():.6f} "
                     f"({grid[np.argmin(P)]:.2f}) |")
    text = "\n".join(lines) + "\n"
    print(text)
    path = Path(__file__).parents[2] / "results" / "sides_quad.md"
    path.write_text(text)


if __name__ == "__main__":
    main()
