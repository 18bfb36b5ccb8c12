"""Defaults shared by more than one layer, each written once: the integration's, a single
orbit's, the system's and the torus analysis'. The config schema, the Python API's keyword
defaults, the command line and the report (for configs that omit a key) all read them."""

T_FINAL = 2000.0            # integration time of a survey cell (the paper's T)
RTOL = 1e-12                # DOP853 tolerances
ATOL = 1e-12
MAX_STEPS = 10_000_000      # step attempts per orbit before status step_limit
ORBIT_T_FINAL = 500.0       # integration time of a single orbit (`orbit`)
BODIES = 3
DIM = 2
POTENTIAL = "perimetric_power"     # with its default parameters, the paper's U = P^2/2
SAMPLE_INTERVAL = 0.1       # time between the orbit samples of the torus analysis
NAFF_LINES = 5              # NAFF lines per shape signal and half orbit
EXTEND = 4                  # a verdict in doubt at T is decided again at EXTEND * T ...
EXTEND_ROUNDS = 1           # ... up to this many times
EXCURSION = 1e3             # a periodic orbit leaves its start by this times its return error
TURNING = 0.99              # ... and its velocity turns through this much of 2 pi at least

# what each [check] variant changes: together with the grid's own step they make up an
# onset's uncertainty (report: the budget)
CHECK_VARIANTS = {
    "seed": "another seed and ensemble size, the nominal starts nudged",
    "rounding": "the nominal starts nudged alone: other last bits of the same arithmetic",
    "horizon": "twice t_final",
    "tolerance": "rtol and atol times [check].tolerance",
}


def check_archive(archive, variant: str):
    """Where a survey archive's [check] run of `variant` is written: beside it, as
    <stem>_check_<variant>.nc."""
    from pathlib import Path
    archive = Path(archive)
    return archive.with_name(f"{archive.stem}_check_{variant}.nc")


def check_change(variant: str, indicators: dict, integration: dict) -> str:
    """What a [check] variant's run changed, in words with its values, from its
    [indicators] and [integration] tables (a validated config's or an archive's stored
    one): what the run prints when it starts and the report's budget names."""
    return {"seed": f"seed {indicators.get('seed', 0)} and "
                    f"{indicators.get('perturbations', 0)} perturbed orbits a cell, the "
                    f"nominal starts {indicators.get('nudge', 0.0):g} (relative) away",
            "rounding": f"the nominal starts {indicators.get('nudge', 0.0):g} (relative) "
                        "away: other last bits",
            "horizon": f"t_final = {integration.get('t_final', T_FINAL):g}",
            "tolerance": f"rtol = {integration.get('rtol', RTOL):g}, atol = "
                         f"{integration.get('atol', ATOL):g}"}[variant]

