"""The regimes a cell can be given (the CF flag variable `regime`) and the thresholds at
which each line of evidence votes regular or chaotic."""
from __future__ import annotations

import enum
import json
from dataclasses import asdict, dataclass, field, fields


class Regime(enum.IntEnum):
    """The regime of a cell (stored as the CF flag variable `regime`)."""

    TORUS = 0
    RESONANT = 1
    PERIODIC = 2
    STICKY = 3
    CHAOTIC = 4
    COLLISION = 5
    INACCESSIBLE = 6
    UNDETERMINED = 7
    EQUILIBRIUM = 8
    ESCAPED = 9

    @property
    def meaning(self) -> str:
        return REGIME_MEANINGS[self]


REGIME_MEANINGS = {
    Regime.TORUS: "quasi-periodic: every line of evidence regular",
    Regime.RESONANT: "regular, with frequencies on a low-order resonance m . nu = 0 (to "
                     "resonance_width)",
    Regime.PERIODIC: "regular, every shape line a harmonic of one frequency (a periodic "
                     "orbit of the shape, e.g. the figure-eight)",
    Regime.STICKY: "regular in the first half, chaotic by T: an orbit that clung to tori",
    Regime.CHAOTIC: "every line of evidence chaotic",
    Regime.COLLISION: "the integration stopped at a near collision",
    Regime.INACCESSIBLE: "no start at this grid point",
    Regime.UNDETERMINED: "the lines of evidence disagree, or the run failed",
    Regime.EQUILIBRIUM: "regular, the shape does not move: at rest at a critical point, or a "
                        "relative equilibrium (the rotating triangle)",
    Regime.ESCAPED: "a body escaped (status escaped): the orbit is neither regular nor "
                    "chaotic by its indicators, which stop at the escape",
}


# the regimes a map or report counts as regular, and as irregular
REGULAR = (Regime.TORUS, Regime.RESONANT, Regime.PERIODIC, Regime.EQUILIBRIUM)
IRREGULAR = (Regime.CHAOTIC, Regime.STICKY)


@dataclass(frozen=True)
class Thresholds:
    """Where each line of evidence votes regular or chaotic (between the two: no vote).
    Chosen from this system's histograms at T = 2000 (the paper's equilateral family and
    'sides' orbit; see the README), in line with the literature's values."""

    digits_regular: float = field(default=5.0, metadata={"doc": (
        "Birkhoff digits (mean over observables) at or above which the WBA votes regular; "
        "at T = 2000 the paper's tori reach 6.5-10.7, its chaotic orbits 2.2-2.7")})
    digits_chaotic: float = field(default=3.5, metadata={"doc": (
        "Birkhoff digits at or below which the WBA votes chaotic")})
    megno_regular: float = field(default=2.25, metadata={"doc": (
        "<Y> at or below which MEGNO votes regular (-> 2 on tori, 0 at isochronous periodic "
        "orbits; 1.8-2.0 on this system's tori at T = 2000)")})
    megno_chaotic: float = field(default=3.0, metadata={"doc": (
        "<Y> at or above which MEGNO votes chaotic (~ lambda T / 2; 3.2-20 in the weak "
        "chaos at the onset)")})
    ftle_regular: float = field(default=1.5, metadata={"doc": (
        "FTLE, in units of ln(T)/T (a torus's FTLE), at or below which it votes regular "
        "(0.7-0.9 on this system's tori)")})
    ftle_chaotic: float = field(default=3.0, metadata={"doc": (
        "FTLE in units of ln(T)/T at or above which it votes chaotic")})
    sali_regular: float = field(default=1e-4, metadata={"doc": (
        "SALI at or above which it votes regular (it fluctuates about 1e-2..1 on tori)")})
    sali_chaotic: float = field(default=1e-8, metadata={"doc": (
        "SALI at or below which it votes chaotic (Skokos et al.'s usual cut)")})
    diffusion_regular: float = field(default=-4.0, metadata={"doc": (
        "frequency diffusion log10 |dnu|/|nu| at or below which it votes regular (tori "
        "-8.4..-4.5 at T = 2000)")})
    diffusion_chaotic: float = field(default=-3.0, metadata={"doc": (
        "frequency diffusion at or above which it votes chaotic (chaos -2.4..0)")})
    resonance_order: int = field(default=6, metadata={"doc": (
        "highest order |m|_1 of the resonances m . nu = 0 searched")})
    resonance_width: float = field(default=1e-7, metadata={"doc": (
        "|m . nu| / (|m| max|nu|) at or below which a regular orbit is resonant")})
    harmonic_width: float = field(default=1e-6, metadata={"doc": (
        "|q nu_i - p nu_j| / (|(p, q)| max|nu|) at or below which two shape frequencies are "
        "harmonics of one (p + q <= resonance_order), or within their change between the "
        "orbit's halves: all of them so, the orbit is periodic in shape (the figure-eight's "
        "weakest line is known to ~1e-6 at 100 periods)")})

    def describe(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_table(cls, table: dict | None) -> "Thresholds":
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in (table or {}).items() if k in names})
