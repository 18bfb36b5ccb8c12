"""Equilibria of a system: forces and the Hessian of U from the right-hand side's exact
tangent forces, the equilibrium reached by descending the potential, and relative
equilibria (rigid rotations) with their linear stability.

All the linear algebra is machine.linalg's, compiled in a fixed order of IEEE operations
instead of LAPACK and BLAS: a chaotic orbit started at an equilibrium amplifies a
difference in its last bit, and a family continued from one decides its steps by noise,
so both must be the same bits on every machine."""
from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from ..machine.jit import kernel
from ..machine import linalg
from ..machine.linalg import orthonormal, symmetric_eigen
from .system import System, centre_of_mass, rhs


def forces(system: System, q: np.ndarray, hessian: bool = False):
    """Forces -dU/dq (N d) at positions q (N, d), and with `hessian` the Hessian of U
    (N d, N d) from the right-hand side's exact tangent forces."""
    nq = q.size
    n_tan = nq if hessian else 0
    tangents = np.concatenate([np.eye(n_tan, nq), np.zeros((n_tan, nq))], axis=1)
    state = np.concatenate([np.ravel(q), np.zeros(nq), tangents.ravel()])
    out = np.zeros_like(state)
    rhs(0.0, state, out, system.model, n_tan)
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



# ------------------------------------------------------------------ relative equilibria
#
# A relative equilibrium rotates rigidly at a rate Omega: in the frame rotating with it the
# bodies are at rest, at a critical point of the amended potential U + J^2 / (2 I) (fixed
# angular momentum J) or of the augmented potential U - Omega^2 I / 2 (fixed rate). Both are
# solved, and linearised, in mass-weighted coordinates with the centre of mass removed:
# xi = B^T sqrt(m) q, with B an orthonormal basis of the configurations whose centre of mass
# is at the origin -- canonical with eta = B^T p / sqrt(m), I = |xi|^2.


class RelativeEquilibrium(NamedTuple):
    """A relative equilibrium and its linear stability in the reduced space (the centre of
    mass and the rotation with its conjugate, the angular momentum, removed)."""

    positions: np.ndarray     # (N, d) at t = 0, centre of mass at the origin
    rotation_rate: float      # Omega, counter-clockwise; 0 at rest
    energy: float
    angular_momentum: float
    eigenvalues: np.ndarray   # of the linearisation in the rotating frame, reduced (complex)
    krein: np.ndarray         # per eigenvalue: the Krein sign of an elliptic pair's upper
    #                           member (+1, -1), 0 for any other eigenvalue
    stable: bool              # spectrally stable: every reduced eigenvalue on the imaginary axis
    residual: float           # |gradient of the amended potential| relative to its terms
    morse: int = -1           # the amended potential's Morse index there (its descent
    #                           directions, rotations aside): 0 at a minimum

    @property
    def frequencies(self) -> np.ndarray:
        """The normal modes' frequencies in the rotating frame (cycles per unit time; the
        shape oscillates at these), ascending; only for eigenvalues on the imaginary axis."""
        lam = self.eigenvalues
        on_axis = (lam.imag > 0) & (np.abs(lam.real) <= AXIS_TOLERANCE * _size(lam))
        return np.sort(lam.imag[on_axis]) / (2 * np.pi)

    @property
    def unstable(self) -> np.ndarray:
        """The eigenvalues off the imaginary axis with a positive real part: the modes that
        grow, fastest first."""
        lam = self.eigenvalues
        grow = lam[lam.real > AXIS_TOLERANCE * _size(lam)]
        return grow[np.argsort(-grow.real)]

    @property
    def on_axis(self) -> int:
        """How many reduced eigenvalues lie on the imaginary axis."""
        lam = self.eigenvalues
        return int(np.sum(np.abs(lam.real) <= AXIS_TOLERANCE * _size(lam)))

    @property
    def rates(self) -> list[float]:
        """How fast nearby motions leave: the real parts of `unstable`."""
        return [float(z.real) for z in self.unstable]

    def state(self, system: System) -> np.ndarray:
        """The inertial-frame state at t = 0: positions, momenta m Omega e_z x q."""
        q = self.positions
        p = np.zeros_like(q)
        if q.shape[1] == 2:
            p[:, 0], p[:, 1] = -q[:, 1], q[:, 0]
        return system.state(q, self.rotation_rate * system.masses[:, None] * p)


AXIS_TOLERANCE = 1e-7     # |Re lambda| / max |lambda| below which an eigenvalue is imaginary


def _size(lam) -> float:
    return float(np.max(np.abs(lam), initial=0.0)) or 1.0


def frame(masses: np.ndarray, d: int):
    """(T, w): T ((N d) x ((N - 1) d)) maps reduced mass-weighted coordinates xi to
    sqrt(m) q; w = 1 / sqrt(m) per coordinate of q."""
    s = np.sqrt(masses)
    rows = np.vstack([s / linalg.norm(s), np.eye(s.size)])
    B = orthonormal(rows)[1:s.size].T
    return np.kron(B, np.eye(d)), np.repeat(1.0 / s, d)


def _reduced_potential(system: System, T, w, xi):
    """U's gradient and Hessian in the reduced coordinates xi, from the exact tangent
    forces."""
    q = (w * linalg.dot(T, xi)).reshape(system.n_bodies, system.dim)
    force, hess = forces(system, q, hessian=True)
    return -linalg.dot(T.T, w * force), linalg.chain(T.T, w[:, None] * hess * w[None, :], T), q


def amended(system: System, T, w, xi, angular_momentum: float | None,
            rotation_rate: float | None):
    """(gradient, Hessian, scale) in reduced coordinates xi of the amended potential
    U + J^2 / (2 I) (given angular_momentum) or U - Omega^2 I / 2 (else; Omega = 0: U).
    scale: the Hessian times the smallest mutual distance (mass-weighted), a force that
    moves the closest bodies by their distance -- what the gradient is measured against."""
    g, H, q = _reduced_potential(system, T, w, xi)
    r2 = linalg.dot(xi, xi)
    eye = np.eye(xi.size)
    if angular_momentum is not None:
        c = angular_momentum ** 2 / r2 ** 2
        grad, hess = g - c * xi, H - c * eye + 4.0 * c / r2 * np.outer(xi, xi)
    else:
        omega2 = (rotation_rate or 0.0) ** 2
        grad, hess = g - omega2 * xi, H - omega2 * eye
    scale = linalg.norm2(hess) * np.min(_distances(q)) * np.sqrt(system.masses.min())
    return grad, hess, scale


def relative_equilibrium(system: System, start, angular_momentum: float | None = None,
                         rotation_rate: float | None = None, max_iter: int = 80
                         ) -> RelativeEquilibrium:
    """The relative equilibrium reached from positions `start` (N, d) by Newton's method
    on the gradient of the amended potential U + J^2 / (2 I) (given angular_momentum) or
    of U - Omega^2 I / 2 (given rotation_rate; neither: an equilibrium at rest), least-
    squares steps (the rotation is a zero direction), halved while the gradient grows.
    Rotating solutions are planar: in 3-D only J = 0. Raises ValueError if it does not
    converge."""
    if angular_momentum is not None and rotation_rate is not None:
        raise ValueError("give the angular momentum or the rotation rate, not both")
    spin = angular_momentum if angular_momentum is not None else rotation_rate
    if system.dim == 3 and spin:
        raise ValueError("rotating relative equilibria are found in the plane (dim = 2); "
                         "in 3-D only equilibria at rest (J = 0)")
    T, w = frame(system.masses, system.dim)
    q0 = np.asarray(start, dtype=float).reshape(system.n_bodies, system.dim)
    q0 = q0 - centre_of_mass(system.masses, q0)
    xi = linalg.dot(T.T, q0.ravel() / w)

    def gradient(xi):
        return amended(system, T, w, xi, angular_momentum, rotation_rate)

    grad, hess, scale = gradient(xi)
    step = np.full(xi.size, np.inf)
    for _ in range(max_iter):
        if not (np.all(np.isfinite(grad)) and np.all(np.isfinite(hess))):
            raise ValueError("the potential is not finite on the way to a relative "
                             "equilibrium (a collision?)")
        step = _newton(hess, grad, xi, system.dim)
        if linalg.norm(grad) <= 1e-13 * scale:
            break
        for _ in range(40):
            trial = xi + step
            g_t, h_t, s_t = gradient(trial)
            if np.all(np.isfinite(g_t)) and linalg.norm(g_t) < linalg.norm(grad):
                break
            step = 0.5 * step
        else:
            break
        xi, grad, hess, scale = trial, g_t, h_t, s_t
    residual = float(linalg.norm(grad) / scale)
    size = np.min(_distances((w * linalg.dot(T, xi)).reshape(system.n_bodies, system.dim)))
    if not (residual <= 1e-10 and linalg.norm(step) <= 1e-8 * size):
        raise ValueError(f"no relative equilibrium from these positions within {max_iter} "
                         f"Newton steps (relative gradient {residual:.1e}, last step "
                         f"{linalg.norm(step) / size:.1e} of the closest distance)")
    r2 = linalg.dot(xi, xi)
    omega = angular_momentum / r2 if angular_momentum is not None else (rotation_rate or 0.0)
    q = (w * linalg.dot(T, xi)).reshape(system.n_bodies, system.dim)
    # a body that drifted off feels no force and no curvature: a limit, not an equilibrium
    d = system.dim
    hq = forces(system, q, hessian=True)[1]
    pull = np.array([linalg.norm(hq[i * d:(i + 1) * d, i * d:(i + 1) * d].ravel()) / m
                     for i, m in enumerate(system.masses)])
    if not np.all(pull > 1e-8 * pull.max()):
        raise ValueError("bodies drifted apart: no bound relative equilibrium from these "
                         "positions")
    lam, krein = linear_stability(system, q, omega)
    R = rotations(xi, d)
    P = np.eye(xi.size) - linalg.dot(R.T, R)
    curvature = symmetric_eigen(linalg.chain(P, hess, P))[0]
    morse = int(np.sum(curvature < -1e-8 * np.max(np.abs(curvature))))
    found = RelativeEquilibrium(q, float(omega), 0.0, float(omega * r2), lam, krein,
                                bool(np.all(np.abs(lam.real) <= AXIS_TOLERANCE * _size(lam))),
                                residual, morse)
    return found._replace(energy=float(system.energy(found.state(system))))


def _generators(d: int, k: int) -> list[np.ndarray]:
    """The infinitesimal rotations of k vectors in d dimensions, as matrices on their
    concatenation (one in the plane, three in space)."""
    gens = [np.array([[0.0, -1.0], [1.0, 0.0]])] if d == 2 else \
        [np.cross(np.eye(3)[a], -np.eye(3)) for a in range(3)]
    return [np.kron(np.eye(k), g) for g in gens]


def rotations(xi, d):
    """Orthonormal rows spanning the infinitesimal rotations of reduced positions xi."""
    return orthonormal(np.array([linalg.dot(g, xi) for g in _generators(d, xi.size // d)]))


def _newton(hess, grad, xi, d):
    """The Newton step with the rotations (exact zero directions) held fixed: least squares
    on the Hessian with the rotations' directions given its own scale, so only a further
    degeneracy (the size of an isochronous family at a given rate) is cut."""
    R = rotations(xi, d)
    RR = linalg.dot(R.T, R)
    P = np.eye(xi.size) - RR
    M = linalg.chain(P, hess, P) + linalg.norm2(hess) * RR
    return -linalg.lstsq(M, linalg.dot(P, grad), 1e-14)


def linear_stability(system: System, positions, rotation_rate: float):
    """(eigenvalues, Krein signs) of the linearised flow at a relative equilibrium in the
    frame rotating with it, H = |eta|^2 / 2 + U - Omega xi x eta in the reduced coordinates:
    z' = J S z. The trivial part -- the rotation and its conjugate (the angular momentum, or
    the size along an isochronous family) -- is removed by restricting to the symplectic
    complement of the rotations and their partners in the generalised kernel of J S. The
    Krein sign of an elliptic eigenvalue i w (w > 0) with eigenvector v is the sign of
    v* S v: modes of opposite sign that collide can leave the axis, of one sign cannot."""
    d = system.dim
    T, w = frame(system.masses, d)
    q = np.asarray(positions, dtype=float).reshape(system.n_bodies, d)
    q = q - centre_of_mass(system.masses, q)
    xi = linalg.dot(T.T, q.ravel() / w)
    _, H, _ = _reduced_potential(system, T, w, xi)
    n = xi.size
    gens = _generators(d, n // d)
    rot = gens[0].T if d == 2 else np.zeros((n, n))     # xi x eta = xi . rot eta
    S = np.block([[H, -rotation_rate * rot], [-rotation_rate * rot.T, np.eye(n)]])
    J = np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]])
    A = linalg.dot(J, S)
    eta = rotation_rate * linalg.dot(rot.T, xi)     # the rotating frame's momenta at rest
    zrot = [np.concatenate([linalg.dot(g, xi), linalg.dot(g, eta)]) for g in gens]
    zrot = [z for z in zrot if linalg.norm(z) > 1e-12 * linalg.norm(xi)]
    W = nontrivial_subspace(A, zrot)
    lam, vec = linalg.eig(linalg.chain(W.T, A, W))
    order = np.lexsort((lam.real, lam.imag))
    lam, vec = lam[order], vec[:, order]
    krein = np.zeros(lam.size, dtype=np.int8)
    size = _size(lam)
    for i, (l, v) in enumerate(zip(lam, vec.T)):
        if l.imag > 0 and abs(l.real) <= AXIS_TOLERANCE * size:
            re, im = linalg.dot(W, v.real), linalg.dot(W, v.imag)   # v* S v, S symmetric
            krein[i] = 1 if linalg.dot(re, linalg.dot(S, re)) + \
                linalg.dot(im, linalg.dot(S, im)) > 0 else -1
    return lam, krein


def nontrivial_subspace(N: np.ndarray, known, form: np.ndarray | None = None) -> np.ndarray:
    """Orthonormal columns spanning what a symmetry leaves of a linearised Hamiltonian flow:
    N is A (a Hamiltonian matrix, J S) or M - 1 (M a monodromy matrix); `known` are vectors
    of its kernel that a symmetry gives (a rotation, a translation, the flow). Each is
    paired with the vector of the generalised kernel, null(N^2), that the symplectic form
    couples to it most (its conserved quantity's direction: angular momentum, momentum,
    energy -- or the size along an isochronous family); the result is the symplectic
    complement of those pairs, which the flow leaves invariant. form: the symplectic form's
    matrix in these coordinates (default the canonical J)."""
    dim = N.shape[0]
    n = dim // 2
    J = np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]]) \
        if form is None else form
    sv, vt = linalg.svd(linalg.dot(N, N))
    kernel = vt[sv <= 1e-9 * max(sv[0], 1e-300)].T
    trivial = []
    for z in known:
        pairing = linalg.chain(kernel.T, J.T, z)       # omega(z, K c) = z^T J K c
        if linalg.norm(pairing) > 1e-12 * linalg.norm(z):
            trivial += [z, linalg.dot(kernel, pairing)]
    if not trivial:
        return np.eye(dim)
    s2, v2 = linalg.svd(linalg.dot(np.array(trivial), J))
    return v2[np.sum(s2 > 1e-10 * s2[0]):].T


SHAPES = 64     # points of the shape sphere a planar three-body search starts from


class Search(NamedTuple):
    """The distinct relative equilibria a search found (lowest energy first), how many of
    its tries reached each, and what it tried: the start, `shapes` points of the shape
    sphere (planar three bodies: each by Newton and by descent) and `seeded` random
    configurations."""

    equilibria: list
    hits: list[int]
    tries: int
    shapes: int
    seeded: int

    @property
    def missed(self) -> float:
        """An estimate of how many equilibria no try reached, from how many were reached
        once (f1) and twice (f2): Chao's f1^2 / (2 f2) (f1 (f1 - 1) / 2 without a pair),
        the species-richness estimator -- 0 when every one was reached at least twice."""
        f1, f2 = self.hits.count(1), self.hits.count(2)
        return f1 * f1 / (2.0 * f2) if f2 else f1 * (f1 - 1) / 2.0


def relative_equilibria(system: System, start, angular_momentum: float | None = None,
                        rotation_rate: float | None = None, starts: int = 0,
                        seed: int = 0, shapes: int = SHAPES,
                        on_guess: Callable | None = None) -> Search:
    """The distinct relative equilibria reached from `start`, from `shapes` points of the
    shape sphere (three bodies in the plane: a deterministic cover of every triangle,
    each tried by Newton's method, which converges to saddles as readily as to minima,
    and by descent on the amended potential, which reaches its minima) and from `starts`
    seeded random configurations (positions normal about the centre with the start's
    radius of gyration), all at the start's size. Two are the same up to rotations,
    reflections and permutations of the bodies when their energies and sorted mutual
    distances agree to 1e-7. `on_guess(tried, total, distinct)` after each guess (a
    progress display)."""
    q0 = np.asarray(start, dtype=float).reshape(system.n_bodies, system.dim)
    q0 = q0 - centre_of_mass(system.masses, q0)
    radius = np.sqrt(np.sum(system.masses[:, None] * q0 ** 2) / system.masses.sum())
    rng = np.random.default_rng(seed)
    planar3 = system.n_bodies == 3 and system.dim == 2
    covered = [shape_configuration(system.masses, w, radius) for w in
               shape_sphere(shapes)] if planar3 else []
    guesses = [(q0, False)] + [(q, descend) for q in covered for descend in (False, True)] \
        + [(rng.normal(0.0, radius, q0.shape), False) for _ in range(starts)]
    found: list[RelativeEquilibrium] = []
    hits: list[int] = []
    for tried, (guess, descend) in enumerate(guesses, 1):
        if on_guess is not None and tried > 1:
            on_guess(tried - 1, len(guesses), len(found))
        try:
            if descend:
                guess = _descend(system, guess, angular_momentum, rotation_rate)
            eq = relative_equilibrium(system, guess, angular_momentum, rotation_rate)
        except (ValueError, np.linalg.LinAlgError, FloatingPointError):
            continue
        same = next((k for k, other in enumerate(found) if _same(eq, other)), None)
        if same is None:
            found.append(eq)
            hits.append(1)
        else:
            hits[same] += 1
    if on_guess is not None:
        on_guess(len(guesses), len(guesses), len(found))
    order = np.argsort([e.energy for e in found], kind="stable")
    return Search([found[k] for k in order], [hits[k] for k in order], len(guesses),
                  len(covered), starts)


def shape_sphere(n: int) -> np.ndarray:
    """n points spread evenly over the unit sphere (a Fibonacci lattice): deterministic,
    so a search gives the same list on every run."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (1.0 + np.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([z, r * np.cos(phi), r * np.sin(phi)], axis=1)


def shape_configuration(masses: np.ndarray, w: np.ndarray, radius: float) -> np.ndarray:
    """Three positions in the plane (centre of mass at the origin, radius of gyration
    `radius`) whose triangle is the point w of the shape sphere: with mass-weighted Jacobi
    vectors z1, z2 as complex numbers, w = (|z1|^2 - |z2|^2, 2 z1 conj(z2)) / (|z1|^2 +
    |z2|^2) -- every triangle up to rotation and size once, reflections as mirror points."""
    m0, m1, m2 = masses
    M = masses.sum()
    mu1, mu2 = m0 * m1 / (m0 + m1), (m0 + m1) * m2 / M
    R2 = M * radius * radius
    a2, b2 = R2 * (1.0 + w[0]) / 2.0, R2 * (1.0 - w[0]) / 2.0
    c = R2 * complex(w[1], w[2]) / 2.0             # z1 conj(z2)
    if a2 >= b2:
        z1 = complex(np.sqrt(a2), 0.0)
        z2 = np.conj(c / z1)
    else:
        z2 = complex(np.sqrt(b2), 0.0)
        z1 = c / z2
    x1 = np.array([z1.real, z1.imag]) / np.sqrt(mu1)        # q1 - q0
    x2 = np.array([z2.real, z2.imag]) / np.sqrt(mu2)        # q2 - centre of q0, q1
    pair = -x2 * m2 / M
    return np.array([pair - x1 * m1 / (m0 + m1), pair + x1 * m0 / (m0 + m1),
                     x2 * (m0 + m1) / M])


def _descend(system: System, start, angular_momentum, rotation_rate, max_iter: int = 200):
    """Positions moved downhill on the amended potential from `start` (Newton's step with
    the Hessian's eigenvalues taken by magnitude, the rotations held, halved until the
    potential falls): towards a minimum, where Newton alone is drawn to saddles. Newton
    then polishes whatever it reaches."""
    T, w = frame(system.masses, system.dim)
    q = np.asarray(start, dtype=float).reshape(system.n_bodies, system.dim)
    xi = linalg.dot(T.T, (q - centre_of_mass(system.masses, q)).ravel() / w)

    def value(xi):
        q = (w * linalg.dot(T, xi)).reshape(system.n_bodies, system.dim)
        u = float(system.potential_energy(system.state(q, np.zeros_like(q))))
        r2 = linalg.dot(xi, xi)
        return u + (angular_momentum ** 2 / (2.0 * r2) if angular_momentum is not None
                    else -0.5 * (rotation_rate or 0.0) ** 2 * r2)

    here = value(xi)
    for _ in range(max_iter):
        grad, hess, scale = amended(system, T, w, xi, angular_momentum, rotation_rate)
        if not (np.isfinite(here) and np.all(np.isfinite(hess))):
            raise ValueError("the descent ran into a collision")
        if linalg.norm(grad) <= 1e-8 * scale:
            break
        R = rotations(xi, system.dim)
        P = np.eye(xi.size) - linalg.dot(R.T, R)
        lam, V = linalg.symmetric_eigen(linalg.chain(P, hess, P))
        lam = np.maximum(np.abs(lam), 1e-6 * np.max(np.abs(lam)))
        step = -linalg.dot(V, linalg.dot(V.T, linalg.dot(P, grad)) / lam)
        for _ in range(40):
            there = value(xi + step)
            if np.isfinite(there) and there < here:
                break
            step = 0.5 * step
        else:
            break
        xi, here = xi + step, there
    return (w * linalg.dot(T, xi)).reshape(system.n_bodies, system.dim)


def _distances(q):
    i, j = np.triu_indices(q.shape[0], 1)
    return np.sort(np.linalg.norm(q[i] - q[j], axis=1))


def _same(a: RelativeEquilibrium, b: RelativeEquilibrium) -> bool:
    scale = max(abs(a.energy), abs(b.energy), 1e-300)
    da, db = _distances(a.positions), _distances(b.positions)
    return abs(a.energy - b.energy) <= 1e-7 * scale and \
        bool(np.all(np.abs(da - db) <= 1e-7 * np.max(da)))


class Bifurcation(NamedTuple):
    """Where a family's linear stability changes (or, for periodic orbits, its parameter
    turns back), located by bisection."""

    parameter: float
    kind: str                 # what the unstable side has: a complex quartet (a Krein
    #                           collision: Hamiltonian-Hopf) or a real pair; for a periodic
    #                           family also a fold, or where multipliers leave the circle
    period: float = float("nan")   # a periodic family's period there
    accuracy: float = float("nan")  # how far the parameter may be off: the bisection's
    #                                 bracket, or for a periodic family's crossing the
    #                                 stability indices' own error over their slope
