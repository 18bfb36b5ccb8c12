"""The validated config as typed records, one per table of pipeline.schema.SCHEMA.

Generated from the schema (python -m survey.pipeline.schema writes this file; the
tests check it is current): edit the schema, not this file."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class SurveyTable:
    """[survey]"""

    name: str                           # name of the survey: archive title and default file name
    output: str                         # archive path (default runs/<name>.nc, outside version c...


@dataclass(frozen=True)
class SystemTable:
    """[system]"""

    bodies: int                         # number of bodies N (3 or more with a triplet term, 2 wi...
    dim: int                            # dimension of space
    masses: list[float] | None          # masses, one per body (default all 1)
    potential: str                      # triplet potential <measure>_<profile> or axilrod_teller
    params: dict                        # potential parameters, e.g. {coupling = 1, exponent = 2}...
    interactions: list[dict] | None     # the potential as a sum of terms, instead of potential/p...


@dataclass(frozen=True)
class InitialTable:
    """[initial]"""

    family: str                         # initial-condition family
    energy: Any                         # target energy: rescales centre-of-mass-frame velocities...
    starts_per_cell: int                # seeded starts per grid point, for a family with a seed:...


@dataclass(frozen=True)
class IntegrationTable:
    """[integration]"""

    t_final: float                      # integration time of every cell
    rtol: float                         # relative tolerance of DOP853 (at least 10 eps = 2.2e-15)
    atol: float                         # absolute tolerance of DOP853
    max_steps: int                      # step attempts per orbit before step_limit
    cell_time_limit: float              # wall-clock budget of each orbit of a cell (they run sid...
    control_tangents: bool              # include tangent vectors in the error norm


@dataclass(frozen=True)
class IndicatorsTable:
    """[indicators]"""

    which: list[str]                    # indicators to compute; [] integrates the orbit alone
    deviations: int                     # seeded deviation vectors per orbit (sali and gali2 need 2)
    seed: int                           # seed of the deviation vectors and perturbed starts (wit...
    renorm_interval: float              # time between renormalisations of the deviation vectors
    history_points: int                 # points of the convergence histories
    project_flow: bool                  # project deviation vectors off the flow and grad H
    perturbations: int                  # orbits started perturbation_size away, for the spread o...
    perturbation_size: float            # relative size of those perturbations
    nudge: float                        # relative size of a seeded displacement of each cell's n...


@dataclass(frozen=True)
class SectionTable:
    """[section]"""

    coordinate: str                     # surface coordinate = value
    value: float                        # surface value (default pi/2 for phi, else 0)
    direction: int                      # +1 coordinate increasing, -1 decreasing, 0 both
    max_crossings: int                  # crossings kept per cell (all are counted)
    triplet: list[int] | None           # bodies of the triangle for side/area surfaces
    coefficients: list[float] | None    # state coefficients of a 'linear' surface
    store_state: bool                   # also store the Cartesian state at each crossing


@dataclass(frozen=True)
class OutcomesTable:
    """[outcomes]"""

    escape: bool                        # stop a cell where a body escapes (at escape_radius); fa...
    escape_radius: float                # a body escapes when its distance from the others' centr...
    escape_binding: float               # kinetic energy of the relative motion above which a bod...
    exits: list[float] | None           # in an external field, directions (degrees in the x-y pl...
    thin: float                         # a triangle is thin where |A|/P^2 is below this share of...


@dataclass(frozen=True)
class ToriTable:
    """[tori]"""

    analyse: bool                       # weighted Birkhoff digits and frequency analysis of ever...
    sample_interval: float              # time between the orbit samples they are computed from (...
    observables: list[str]              # observables of the Birkhoff averages (default: perimete...
    lines: int                          # NAFF lines per shape signal and half orbit
    extend: int                         # a cell whose verdict changed from t_final / 2 to t_fina...
    extend_rounds: int                  # how many times a verdict still in doubt is extended aga...
    digits_regular: float               # Birkhoff digits (mean over observables) at or above whi...
    digits_chaotic: float               # Birkhoff digits at or below which the WBA votes chaotic
    megno_regular: float                # <Y> at or below which MEGNO votes regular (-> 2 on tori...
    megno_chaotic: float                # <Y> at or above which MEGNO votes chaotic (~ lambda T /...
    ftle_regular: float                 # FTLE, in units of ln(T)/T (a torus's FTLE), at or below...
    ftle_chaotic: float                 # FTLE in units of ln(T)/T at or above which it votes cha...
    sali_regular: float                 # SALI at or above which it votes regular (it fluctuates...
    sali_chaotic: float                 # SALI at or below which it votes chaotic (Skokos et al.'...
    diffusion_regular: float            # frequency diffusion log10 |dnu|/|nu| at or below which...
    diffusion_chaotic: float            # frequency diffusion at or above which it votes chaotic...
    resonance_order: int                # highest order |m|_1 of the resonances m . nu = 0 searched
    resonance_width: float              # |m . nu| / (|m| max|nu|) at or below which a regular or...
    harmonic_width: float               # |q nu_i - p nu_j| / (|(p, q)| max|nu|) at or below whic...


@dataclass(frozen=True)
class CheckTable:
    """[check]"""

    variants: list[str]                 # what each second run of the same survey changes, one ar...
    seed: int                           # seed of the seed variant, with another ensemble (-1: [i...
    perturbations: int                  # perturbed orbits per cell of the seed variant (-1: twic...
    nudge: float                        # relative size of the displacement of each cell's nomina...
    tolerance: float                    # factor on rtol and atol of the tolerance variant


@dataclass(frozen=True)
class RefineTable:
    """[refine]"""

    max_level: int                      # refinement steps after the grid: each halves the spacin...
    max_cells: int                      # cells in all, the grid's included; a level that would p...
    by: str                             # what makes neighbouring cells disagree: their verdict c...
    indicator: str                      # also split where this indicator jumps by more than `jum...
    jump: float                         # that jump, in the indicator's units (0: none)
    ratio: float                        # that factor, for positive indicators spanning decades s...
    tolerance: float                    # one axis: a boundary is bisected until its interval is...


@dataclass(frozen=True)
class ReferenceTable:
    """[reference]"""

    source: str                         # who published the regular shares below, and how they me...
    axis: str                           # the grid axis the published values are at (the survey's...
    at: list[float] | None              # the axis values they are at, each one of the grid's
    regular_share: list[float] | None   # the published regular share at each (0 to 1): the repor...
    spread: float                       # their stated spread, or how closely they can be read of...
    crossings: int                      # the published shares were decided by how far two nearby...
    growth: float                       # the largest growth of that separation the publication c...


@dataclass(frozen=True)
class DaskTable:
    """[dask]"""

    workers: int                        # local worker processes (1 thread each)
    scheduler: str                      # address of an existing dask scheduler, e.g. tcp://host:...
    connect_timeout: float              # seconds to wait for that scheduler to answer
    chunk_size: int                     # cells per task, whose orbits run as SIMD lanes; 0 picks...
    retries: int                        # retries of a task whose worker raised


@dataclass(frozen=True)
class Settings:
    """Every table of a validated config, and whether the optional ones were
    given."""

    survey: SurveyTable
    system: SystemTable
    initial: InitialTable
    integration: IntegrationTable
    indicators: IndicatorsTable
    section: SectionTable
    outcomes: OutcomesTable
    tori: ToriTable
    check: CheckTable
    refine: RefineTable
    reference: ReferenceTable
    dask: DaskTable
    section_enabled: bool
    check_enabled: bool
    refine_enabled: bool
    reference_enabled: bool
