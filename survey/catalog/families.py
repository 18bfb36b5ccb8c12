"""The variables of a family archive, each declared once: a family of relative equilibria
or of periodic orbits along a parameter (`python -m survey equilibria|periodic --output`)
and the invariant manifolds of a section map (`[[plane]] manifolds`). pipeline.archive
builds a family's Dataset from these (a variable not declared, or one declared and not
given, is an error there) and `verify` reads them back; `{parameter}` in a long name is
the family's parameter.
"""
from __future__ import annotations

from typing import NamedTuple


class FamilyVar(NamedTuple):
    name: str
    dims: tuple[str, ...]
    long_name: str
    dtype: str = "f8"          # f8, i8, i1 (a flag), str
    units: str = ""


EQUILIBRIA, PERIODIC, MANIFOLDS = "equilibria", "periodic", "manifolds"


def _bifurcations(where: str, accuracy: str) -> tuple[FamilyVar, ...]:
    return (FamilyVar("bifurcation_parameter", ("bifurcation",), "{parameter} " + where),
            FamilyVar("bifurcation_accuracy", ("bifurcation",), "how far the parameter may "
                      "be off: " + accuracy),
            FamilyVar("bifurcation_kind", ("bifurcation",), "", "str"))


FAMILY_VARIABLES: dict[str, tuple[FamilyVar, ...]] = {
    EQUILIBRIA: (
        FamilyVar("energy", ("member",), "energy"),
        FamilyVar("angular_momentum", ("member",), "angular momentum"),
        FamilyVar("rotation_rate", ("member",), "rotation rate Omega"),
        FamilyVar("positions", ("member", "body", "axis"), "positions at t = 0, centre of "
                  "mass at the origin"),
        FamilyVar("eigenvalue_real", ("member", "eigenvalue"), "reduced linearisation's "
                  "eigenvalues, real part"),
        FamilyVar("eigenvalue_imag", ("member", "eigenvalue"), "reduced linearisation's "
                  "eigenvalues, imaginary part"),
        FamilyVar("stable", ("member",), "1 where every reduced eigenvalue is on the "
                  "imaginary axis", "i1"),
        *_bifurcations("where the stability changes", "the bisection's bracket"),
    ),
    PERIODIC: (
        FamilyVar("period", ("member",), "period"),
        FamilyVar("rotation", ("member",), "angle the orbit returns rotated by", units="rad"),
        FamilyVar("energy", ("member",), "energy"),
        FamilyVar("angular_momentum", ("member",), "angular momentum"),
        FamilyVar("return_error", ("member",), "relative return error of the converged "
                  "orbit"),
        FamilyVar("excursion", ("member",), "how far the orbit leaves its start, relative "
                  "to its size (in the frame turning with it)"),
        FamilyVar("turning", ("member",), "full circles its velocity turns through over a "
                  "period (at least 1 for a closed orbit)"),
        FamilyVar("initial_state", ("member", "component"), "state at t = 0 (positions, "
                  "then momenta)"),
        FamilyVar("multiplier_real", ("member", "multiplier"), "non-trivial Floquet "
                  "multipliers, real part"),
        FamilyVar("multiplier_imag", ("member", "multiplier"), "non-trivial Floquet "
                  "multipliers, imaginary part"),
        FamilyVar("index_real", ("member", "pair"), "stability index (mu + 1/mu)/2, real "
                  "part"),
        FamilyVar("index_imag", ("member", "pair"), "stability index (mu + 1/mu)/2, "
                  "imaginary part"),
        FamilyVar("stable", ("member",), "1 where every non-trivial multiplier is on the "
                  "unit circle", "i1"),
        FamilyVar("kind", ("member",), "", "str"),
        *_bifurcations("at a fold or where multipliers leave or join the unit circle",
                       "the bisection's bracket, or the stability indices' error over "
                       "their slope")[:1],
        FamilyVar("bifurcation_period", ("bifurcation",), "period there"),
        *_bifurcations("", "the bisection's bracket, or the stability indices' error over "
                           "their slope")[1:],
    ),
    MANIFOLDS: (
        FamilyVar("orbit_b", ("orbit",), "base b of the orbit's first point on the section "
                  "(where Newton ended if not converged)"),
        FamilyVar("orbit_p_b", ("orbit",), "p_b of that point"),
        FamilyVar("orbit_crossings", ("orbit",), "k: its points on the section", "i8"),
        FamilyVar("orbit_period", ("orbit",), "period"),
        FamilyVar("orbit_converged", ("orbit",), "1 where Newton converged", "i1"),
        FamilyVar("orbit_kind", ("orbit",), "", "str"),
        FamilyVar("orbit_multiplier", ("orbit",), "unstable multiplier of the section map "
                  "P^k"),
        FamilyVar("branch_orbit", ("branch",), "the orbit it belongs to", "i8"),
        FamilyVar("branch_kind", ("branch",), "", "str"),
        FamilyVar("branch_side", ("branch",), "the half of the eigenvector it leaves along",
                  "i1"),
        FamilyVar("branch_resolved", ("branch",), "1 where it reached manifold_length "
                  "within the point budget", "i1"),
        FamilyVar("point_branch", ("point",), "the branch it is on", "i8"),
        FamilyVar("b", ("point",), "base b"),
        FamilyVar("p_b", ("point",), "p_b = (db/dt)/2"),
        FamilyVar("arclength", ("point",), "arclength along its branch from the orbit's "
                  "point"),
        FamilyVar("level", ("point",), "n: the point is P^n (P^-n) of its seed", "i8"),
        FamilyVar("seed", ("point",), "sigma: its seed is x + s0 |mu|^sigma v"),
        FamilyVar("homoclinic_b", ("homoclinic",), "base b of the first crossing of an "
                  "unstable and a stable branch"),
        FamilyVar("homoclinic_p_b", ("homoclinic",), "p_b of that crossing"),
        FamilyVar("homoclinic_accuracy", ("homoclinic",), "how far it may be off: its "
                  "chords' error or its move at a 10 times looser tolerance, the larger"),
        FamilyVar("homoclinic_unstable", ("homoclinic",), "the unstable branch", "i8"),
        FamilyVar("homoclinic_stable", ("homoclinic",), "the stable branch", "i8"),
        FamilyVar("homoclinic_angle", ("homoclinic",), "angle between the branches there, "
                  "radians"),
        FamilyVar("homoclinic_arclength", ("homoclinic",), "arclength along the unstable "
                  "branch"),
    ),
}

# what the computation sets beside its variables, compared by `verify`
FAMILY_ATTRIBUTES = ("title", "family", "complete", "ended")
