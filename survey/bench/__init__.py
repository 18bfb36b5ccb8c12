"""`python -m survey bench`: survey against its baselines, measured in the same run -- a
101-orbit grid end to end against heyoka's SIMD batch ensemble (`scan_vs_heyoka`), a
default cell against its bare orbit (`default_cell`), what a survey costs beside its cells
(`fixed_costs`), how busy a refined map keeps the workers (`refined_map`), where a step
goes and one orbit's step against the same step in plain scalar code (`step_costs`),
survey's DOP853 against scipy's DOP853 (NumPy right-hand side) and heyoka's
Taylor integrator on the paper's two orbits (`run`), the cost of indicators, sections and
the torus analysis, the scaling on 1 vs 2 workers and from 10^3 to 10^5 cells
(`survey_scale`), the driver's memory, and what the paper's one-term systems would pay on
the general path of sums of terms (`interaction_terms`), and the explorer's latency
(`explorer_latency`).

Speed claims are ratios against baselines timed here, never absolute numbers: machines
differ, ratios on one machine in one run do not. Compilation (numba's cached load, heyoka's
LLVM JIT) is timed separately from integration.

Its parts, one module each by what they measure: `baselines` (scipy, heyoka), `costs` (what
survey's own parts cost beside the bare orbit), `surveys` (whole surveys), `steps` (where a
step goes), `common` (the cases, timing, commands run as a user runs them).
"""
from .baselines import run, scan_vs_heyoka, vector_doubles
from .common import CASES, timed_command
from .costs import (
    GeneralPath,
    default_cell,
    fixed_costs,
    indicator_overhead,
    interaction_terms,
    newton_step,
    torus_overhead,
)
from .explorer import explorer_latency
from .steps import (
    arithmetic_probe,
    divider_ops,
    divider_rates,
    fma_peak,
    plain_step,
    step_costs,
    step_flops,
)
from .surveys import refined_map, survey_memory, survey_scale, survey_scaling

__all__ = ["CASES", "GeneralPath", "arithmetic_probe", "default_cell", "divider_ops",
           "divider_rates", "explorer_latency", "fixed_costs", "fma_peak",
           "indicator_overhead", "interaction_terms", "newton_step", "plain_step",
           "refined_map", "run", "scan_vs_heyoka", "step_costs", "step_flops", "survey_memory",
           "survey_scale", "survey_scaling", "timed_command", "torus_overhead",
           "vector_doubles"]
