"""Equilibria of a system: forces and the Hessian of U from the right-hand side's exact
tangent forces, and the equilibrium reached by descending the potential.

The descent's linear algebra is compiled here in a fixed order of IEEE operations
(portable.symmetric_eigen instead of LAPACK): a chaotic orbit started at an equilibrium
amplifies a difference in its last bit, so the start must be the same bits on every
machine."""
from __future__ import annotations

import numpy as np

from .jit import kernel
from .portable import orthonormal, symmetric_eigen
from .system import System, centre_of_mass, rhs


def forces(system: System, q: np.ndarray, hessian: bool = False):
    """Forces -dU/dq (N d) at positions q (N, d), and with `hessian` the Hessian of U
    (N d, N d) from the right-hand side's exact tangent forces."""
    nq = q.size
    n_tan = nq if hessian else 0
    tangents = np.concatenate([np.eye(n_tan, nq), np.zeros((n_tan, nq))], axis=1)
    state = np.concatenate([np.ravel(q), np.zeros(nq), tangents.ravel()])
    out = np.zeros_like(state)
    rhs(0.0, state, out, *system.kernel_args, n_tan)
    if not hessian:
        return out[nq:2 * nq]
    blocks = out[2 * nq:].reshape(nq, 2 * nq)
    return out[nq:2 * nq], -0.5 * (blocks[:, nq:] + blocks[:, nq:].T)


def _rigid_motions(q: np.ndarray) -> np.ndarray:
    """Orthonormal rows spanning the translations and rotations of positions q (N, d)."""
    N, d = q.shape
    r = np.pad(q - q.mean(axis=0), ((0, 0), (0, 3 - d)))
    rows = [np.tile(np.eye(d)[k], N) for k in range(d)]
    for axis in ([2] if d == 2 else [0, 1, 2]):
        rows.append(np.cross(np.eye(3)[axis], r)[:, :d].ravel())
    return orthonormal(np.array(rows))


@kernel
def _newton_step(hess, force, R):
    """The Newton step on |Hessian| in the space orthogonal to the orthonormal rows R:
    with P = 1 - R^T R and P H P = V diag(w) V^T, the step V |w|^-1 V^T P f over the
    eigenvalues above 1e-10 of the largest (a descent direction even at a saddle)."""
    n = force.size
    P = np.eye(n)
    for a in range(n):
        for b in range(n):
            for j in range(R.shape[0]):
                P[a, b] -= R[j, a] * R[j, b]
    HP = np.zeros((n, n))
    for a in range(n):
        for b in range(n):
            for c in range(n):
                HP[a, b] += hess[a, c] * P[c, b]
    M = np.zeros((n, n))
    for a in range(n):
        for b in range(n):
            for c in range(n):
                M[a, b] += P[a, c] * HP[c, b]
    w, V = symmetric_eigen(M)
    g = np.zeros(n)
    for a in range(n):
        for c in range(n):
            g[a] += P[a, c] * force[c]
    top = 0.0
    for i in range(n):
        top = max(top, abs(w[i]))
    step = np.zeros(n)
    for i in range(n):
        if abs(w[i]) > 1e-10 * top:
            c = 0.0
            for a in range(n):
                c += V[a, i] * g[a]
            c /= abs(w[i])
            for a in range(n):
                step[a] += V[a, i] * c
    return step


def equilibrium_positions(system: System, start, max_iter: int = 100) -> np.ndarray:
    """The equilibrium reached from `start` (N, d) by descending the potential: Newton
    steps on |Hessian| (a descent direction even at saddles) in the space orthogonal to
    translations and rotations, backtracking while U rises above its rounding level, until
    the steps are at rounding level. A start with a symmetry keeps it (the linear trimer
    stays linear). Centre of mass at the origin."""
    q = np.array(start, dtype=float)
    state = lambda x: np.concatenate([x.ravel(), np.zeros(x.size)])
    energy = lambda x: float(system.potential_energy(state(x)))
    u = energy(q)
    for _ in range(max_iter):
        if not np.isfinite(u):
            raise ValueError("the potential is not finite along the descent from positions")
        force, hess = forces(system, q, hessian=True)
        R = _rigid_motions(q)
        step = _newton_step(hess, force, R).reshape(q.shape)
        extent = np.abs(q - q.mean(axis=0)).max()
        if np.abs(step).max() <= 1e-13 * extent:
            break
        slack = 1e-13 * (abs(u) + 1.0)     # energies closer than this are equal
        for _ in range(60):
            trial = q + step
            ut = energy(trial)
            if ut <= u + slack:
                break
            step = 0.5 * step
        else:
            break
        q, u = trial, ut
    else:
        raise ValueError(f"no equilibrium within {max_iter} Newton steps from positions")
    return q - centre_of_mass(system.masses, q)

