"""The survey archive: Dataset schema (units, long names, CF flags declared once, here),
provenance, and the atomic NetCDF write.

Dimensions: the grid axes (in the order the config writes them), then per variable at most
one of `crossing` (section points, NaN-padded, with n_crossings), `history_time`
(convergence histories), `component` (phase-space state) or `spatial` (3-D vectors).
"""
from __future__ import annotations

import datetime
import os
import subprocess
import sys
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Callable

import numpy as np
import xarray as xr

from .integrator import Status


@dataclass(frozen=True)
class Var:
    name: str
    long_name: str
    dtype: str = "f8"
    extra: str | None = None       # crossing, history_time, component, spatial
    units: str = "1"
    reproducible: bool = True      # part of the bit-for-bit contract
    when: Callable = lambda c: True

    @property
    def fill(self):
        return np.nan if self.dtype.startswith("f") else -1


def _which(*names):
    return lambda c: bool(set(names) & set(c.tables["indicators"]["which"]))


def _section(c):
    return c.tables["section_enabled"]


def _planar3(c):
    s = c.tables["system"]
    return s["bodies"] == 3 and s["dim"] == 2


VARIABLES = [
    Var("status", "integration outcome of the cell", "i1"),
    Var("t_end", "time reached by the integration"),
    Var("energy", "energy H at t = 0"),
    Var("angular_momentum", "total angular momentum at t = 0 (z component in 2-D)"),
    Var("energy_error", "max |E(t)/E(0) - 1| over the history times and the end"),
    Var("angular_momentum_error", "max |J(t) - J(0)| / max(|J(0)|, 1) over the same times"),
    Var("ftle", "finite-time maximal Lyapunov exponent at t_end, ensemble mean",
        when=_which("ftle")),
    Var("ftle_spread", "standard deviation of the FTLE over deviation vectors and perturbed "
                       "starts", when=_which("ftle")),
    Var("megno", "mean exponential growth factor of nearby orbits <Y> at t_end, ensemble "
                 "mean", when=_which("megno")),
    Var("megno_spread", "standard deviation of <Y> over the perturbed starts",
        when=_which("megno")),
    Var("megno_slope", "least-squares slope d<Y>/dt over the second half of the run "
                       "(about ftle/2 in chaos)", when=_which("megno")),
    Var("fli", "fast Lyapunov indicator: max ln(|w|/|w0|) of the first deviation vector",
        when=_which("fli")),
    Var("sali", "smaller alignment index of two deviation vectors at t_end",
        when=_which("sali")),
    Var("gali2", "generalized alignment index |w1^ ^ w2^| at t_end", when=_which("gali2")),
    Var("n_steps", "accepted integration steps of the nominal orbit", "i8"),
    Var("n_rhs", "right-hand-side evaluations of the nominal orbit", "i8"),
    Var("wall_time", "wall-clock time spent on the cell", units="s", reproducible=False),
    Var("initial_state", "phase-space state at t = 0", extra="component"),
    Var("n_crossings", "crossings of the surface of section (all, also those not kept)", "i8",
        when=_section),
    Var("crossing_time", "time of each kept section crossing", extra="crossing",
        when=_section),
    *[Var(f"crossing_{q}", f"reduced coordinate {q} at each kept section crossing",
          extra="crossing", when=lambda c: _section(c) and _planar3(c))
      for q in ("sigma", "p_sigma", "eta", "p_eta", "phi", "p_phi")],
    Var("crossing_state", "phase-space state at each kept section crossing",
        extra="crossing", when=lambda c: _section(c) and c.tables["section"]["store_state"]),
    Var("ftle_history", "FTLE convergence history", extra="history_time", when=_which("ftle")),
    Var("megno_history", "<Y> convergence history", extra="history_time",
        when=_which("megno")),
    Var("fli_history", "FLI convergence history", extra="history_time", when=_which("fli")),
    Var("sali_history", "SALI convergence history", extra="history_time",
        when=_which("sali")),
]


def variables(config) -> list[Var]:
    """The variables a config's archive holds. A variable named like a grid axis (energy, or
    the section family's angular_momentum) is left out: that axis holds its value."""
    axes = {a.name for a in config.axes}
    out = []
    for v in VARIABLES:
        if not v.when(config) or v.name in axes:
            continue
        if v.name == "angular_momentum" and config.tables["system"]["dim"] == 3:
            v = Var(v.name, "total angular momentum at t = 0", extra="spatial")
        out.append(v)
    return out


def extra_size(config, extra: str | None) -> int:
    s = config.tables["system"]
    return {None: 1, "crossing": config.tables["section"]["max_crossings"],
            "history_time": config.tables["indicators"]["history_points"],
            "component": 2 * s["bodies"] * s["dim"], "spatial": 3}[extra]


def empty_results(config, count: int) -> dict[str, np.ndarray]:
    """Fill-valued result arrays for `count` cells (the layout a task returns)."""
    out = {}
    for v in variables(config):
        k = extra_size(config, v.extra)
        shape = (count,) if v.extra is None else (count, k)
        out[v.name] = np.full(shape, v.fill, dtype=v.dtype)
    return out


# ---------------------------------------------------------------- provenance

def versions() -> dict[str, str]:
    names = ["survey", "numpy", "numba", "llvmlite", "dask", "distributed", "xarray",
             "netCDF4"]
    out = {"python": sys.version.split()[0]}
    for n in names:
        try:
            out[n] = metadata.version(n)
        except metadata.PackageNotFoundError:
            out[n] = "unknown"
    return out


def git_commit() -> str:
    here = Path(__file__).resolve().parent
    try:
        res = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=5)
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "--", "."],
                               capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    if res.returncode != 0:
        return "unknown"
    return res.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")


def _component_labels(config):
    s = config.tables["system"]
    axes = "xyz"[:s["dim"]]
    q = [f"{c}{b}" for b in range(s["bodies"]) for c in axes]
    return q + [f"p{c}" for c in q]


def coordinates(config) -> dict:
    coords = {a.name: (a.name, a.values, {"long_name": f"initial-condition parameter "
                                                     f"{a.name}", "units": "1"})
              for a in config.axes}
    coords["history_time"] = ("history_time", _history_times(config),
                              {"long_name": "time of the convergence history points",
                               "units": "1"})
    coords["component"] = ("component", _component_labels(config),
                           {"long_name": "phase-space component (positions, then momenta)"})
    if config.tables["section_enabled"]:
        n = config.tables["section"]["max_crossings"]
        coords["crossing"] = ("crossing", np.arange(n), {"long_name": "index of the kept "
                                                                      "section crossing"})
    if config.tables["system"]["dim"] == 3:
        coords["spatial"] = ("spatial", ["x", "y", "z"], {"long_name": "spatial axis"})
    return coords


def _history_times(config):
    t, k = config.tables["integration"]["t_final"], config.tables["indicators"]["history_points"]
    return np.linspace(t / k, t, k)


def attributes(config, command: str) -> dict:
    ver = versions()
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    init = config.tables["initial"]
    return {
        "Conventions": "CF-1.10",
        "title": f"survey '{config.name}': chaos indicators of the {init['family']} family "
                 f"under {config.tables['system']['potential']}",
        "history": f"{now}: {command} (survey {ver['survey']})",
        "source": f"survey {ver['survey']}: numba DOP853 (rtol "
                  f"{config.tables['integration']['rtol']:g}) with variational equations",
        "references": "J.D. Meiss, Hamiltonian Triplet Interactions: Areal and Perimetric "
                      "Forces",
        "config": config.text,
        "config_sha256": config.sha256,
        "result_key": config.result_key(),
        "grid_axes": " ".join(a.name for a in config.axes),
        "git_commit": git_commit(),
        **{f"version_{k}": v for k, v in ver.items()},
    }


def variable_attrs(v: Var) -> dict:
    attrs = {"long_name": v.long_name}
    if v.name == "status":
        attrs["flag_values"] = np.array([s.value for s in Status], dtype=np.int8)
        attrs["flag_meanings"] = " ".join(s.name.lower() for s in Status)
    else:
        attrs["units"] = v.units
    if not v.reproducible:
        attrs["reproducible"] = "no: differs between runs"
    return attrs


# ---------------------------------------------------------------- writing

def write(config, load: Callable[[str], np.ndarray], command: str) -> Path:
    """Write the archive atomically: to a temporary file beside the output, variable by
    variable (peak memory: one variable), then renamed into place. `load(name)` returns a
    variable over all cells in flat C order, shape (n_cells, ...)."""
    out = config.output
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.partial-{os.getpid()}")
    dims = tuple(a.name for a in config.axes)
    try:
        base = xr.Dataset(coords={k: xr.Variable(*v) for k, v in coordinates(config).items()},
                          attrs=attributes(config, command))
        base.to_netcdf(tmp, mode="w", engine="netcdf4")
        for v in variables(config):
            data = load(v.name).reshape(config.shape + (() if v.extra is None else (-1,)))
            var_dims = dims + (() if v.extra is None else (v.extra,))
            one = xr.Dataset({v.name: xr.Variable(var_dims, data, variable_attrs(v))})
            enc = {v.name: {"zlib": True, "complevel": 4,
                            "_FillValue": None if v.dtype.startswith("i") else np.nan}}
            one.to_netcdf(tmp, mode="a", engine="netcdf4", encoding=enc)
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()
    return out


def reproducible_variables(ds: xr.Dataset) -> list[str]:
    return [k for k, v in ds.data_vars.items() if v.attrs.get("reproducible") is None]
