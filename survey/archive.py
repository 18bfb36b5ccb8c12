"""The survey archive: every variable declared once (units, long name, fill, which cells
carry it, how a cell's result fills it, whether it is reproducible), the CF attributes and
provenance, the atomic NetCDF write, and the checks `verify` runs on a file.

Everything else follows from VARIABLES: the arrays a task returns (`layout`), how a cell
fills them (`fill_row`), the archive's variables and attributes, the schema `verify`
expects (`problems`) and the README's variable table (`markdown_table`).

Dimensions: the grid axes (in the order the config writes them), then a variable's own:
`crossing` (section points, NaN-padded, with n_crossings), `history_time` (convergence
histories), `component` (phase-space state) or `spatial` (3-D vectors).
"""
from __future__ import annotations

import datetime
import hashlib
import os
import subprocess
import sys
from dataclasses import dataclass, replace
from importlib import metadata
from pathlib import Path
from typing import Any, Callable, NamedTuple

import numpy as np

from .status import Status
from .tori import Regime, fundamental_names

# which cells a variable has values for; elsewhere it holds its fill value
ALL, STARTED, FINISHED = "all cells", "cells with a start", "cells with status ok or event"


class CellResult(NamedTuple):
    """What one cell computed: the source every archive variable is filled from."""

    status: Status
    wall_time: float
    n_steps: int = 0
    n_rhs: int = 0
    start: np.ndarray | None = None        # None where no start exists (inaccessible)
    t_end: float = np.nan
    energy: Any = np.nan
    angular_momentum: Any = np.nan
    energy_error: float = np.nan
    angular_momentum_error: float = np.nan
    indicators: Any = None                 # indicators.ChaosIndicators
    tori: Any = None                       # tori.TorusEvidence
    n_crossings: int = 0
    crossing_time: np.ndarray | None = None    # kept crossings
    crossing_state: np.ndarray | None = None
    reduced: Any = None                    # coordinates.Reduced of the kept crossings


@dataclass(frozen=True)
class Var:
    name: str
    long_name: str
    value: Callable[[CellResult], Any]     # how a cell's result fills it
    cells: str = STARTED                   # ALL, STARTED or FINISHED
    dtype: str = "f8"
    extra: tuple[str, ...] = ()            # own dimensions after the grid's
    units: str = "1"
    reproducible: bool = True              # part of the bit-for-bit contract
    when: Callable = lambda config: True   # whether a config's archive holds it
    flags: Any = None                      # an IntEnum: a CF flag variable
    derived: bool = False                  # computed from the other variables (tori.classify)

    @property
    def fill(self):
        return np.nan if self.dtype.startswith("f") else -1

    def attrs(self) -> dict:
        attrs = {"long_name": self.long_name}
        if self.flags is not None:
            attrs["flag_values"] = np.array([s.value for s in self.flags], dtype=np.int8)
            attrs["flag_meanings"] = " ".join(s.name.lower() for s in self.flags)
        else:
            attrs["units"] = self.units
        if self.derived:
            attrs["comment"] = "derived by survey.tori.classify from the other variables"
        elif self.cells != ALL:
            attrs["comment"] = f"{'NaN' if self.dtype.startswith('f') else '-1'} except in " \
                               f"{self.cells}"
        if not self.reproducible:
            attrs["reproducible"] = "no: differs between runs"
        return attrs


def _which(*names):
    return lambda c: bool(set(names) & set(c.tables["indicators"]["which"]))


def _section(c):
    return c.tables["section_enabled"]


def _planar3(c):
    s = c.tables["system"]
    return s["bodies"] == 3 and s["dim"] == 2


def _tori(c):
    return c.tables["tori"]["analyse"]


def _torus(name, long_name, value, dtype="f8", extra=(), when=_tori):
    return Var(name, long_name, value, FINISHED, dtype, extra, when=when)


def _indicator(name, long_name, when):
    return Var(name, long_name, lambda r: getattr(r.indicators, name), FINISHED, when=when)


def _history(name, of, when):
    return Var(f"{name}_history", f"{of} convergence history",
               lambda r: getattr(r.indicators, f"{name}_history"), FINISHED,
               extra=("history_time",), when=when)


def _reduced_crossing(q):
    return Var(f"crossing_{q}", f"reduced coordinate {q} at each kept section crossing",
               lambda r: getattr(r.reduced, q), extra=("crossing",),
               when=lambda c: _section(c) and _planar3(c))


VARIABLES = [
    Var("status", "integration outcome of the cell", lambda r: r.status, ALL, "i1",
        flags=Status),
    Var("regime", "regular or chaotic: the verdict of all the evidence", None, ALL, "i1",
        flags=Regime, derived=True),
    Var("regime_confidence", "share of the lines of evidence present that support the "
                             "regime", None, ALL, derived=True),
    Var("t_end", "time reached by the integration", lambda r: r.t_end),
    Var("energy", "energy H at t = 0", lambda r: r.energy),
    Var("angular_momentum", "total angular momentum at t = 0 (z component in 2-D)",
        lambda r: r.angular_momentum),
    Var("energy_error", "max |E(t)/E(0) - 1| over the history times and the end",
        lambda r: r.energy_error),
    Var("angular_momentum_error", "max |J(t) - J(0)| / max(|J(0)|, 1) over the same times",
        lambda r: r.angular_momentum_error),
    _indicator("ftle", "finite-time maximal Lyapunov exponent at t_end, ensemble mean",
               _which("ftle")),
    _indicator("ftle_spread", "standard deviation of the FTLE over deviation vectors and "
                              "perturbed starts", _which("ftle")),
    _indicator("megno", "mean exponential growth factor of nearby orbits <Y> at t_end, "
                        "ensemble mean", _which("megno")),
    _indicator("megno_spread", "standard deviation of <Y> over the perturbed starts",
               _which("megno")),
    _indicator("megno_slope", "least-squares slope d<Y>/dt over the second half of the run "
                              "(about ftle/2 in chaos)", _which("megno")),
    _indicator("fli", "fast Lyapunov indicator: max ln(|w|/|w0|) of the first deviation "
                      "vector", _which("fli")),
    _indicator("sali", "smaller alignment index of two deviation vectors at t_end",
               _which("sali")),
    _indicator("gali2", "generalized alignment index |w1^ ^ w2^| at t_end", _which("gali2")),
    _indicator("ftle_wba", "weighted Birkhoff average of the growth rate d ln|w|/dt of the "
                           "first deviation vector (Sander & Meiss 2025)", _which("ftle")),
    _torus("birkhoff_digits", "weighted Birkhoff digits of convergence at t_end, mean over "
                              "the observables", lambda r: r.tori.digits),
    _torus("birkhoff_digits_half", "weighted Birkhoff digits of convergence at t_end / 2, "
                                   "mean over the observables", lambda r: r.tori.digits_half),
    _torus("birkhoff_digits_observable", "weighted Birkhoff digits of convergence at t_end "
                                         "of each observable", lambda r: r.tori.digits_each,
           extra=("observable",)),
    _torus("birkhoff_digits_observable_half", "weighted Birkhoff digits of convergence at "
                                              "t_end / 2 of each observable",
           lambda r: r.tori.digits_each_half, extra=("observable",)),
    _torus("frequency", "fundamental frequency in cycles per unit time (mean of the two "
                        "halves of the orbit)", lambda r: r.tori.frequencies.frequency,
           extra=("fundamental",)),
    _torus("frequency_change", "change of each fundamental frequency from the first half "
                               "of the orbit to the second", lambda r: r.tori.frequencies.change,
           extra=("fundamental",)),
    _torus("frequency_diffusion", "log10 max |nu(second half) - nu(first half)| / max |nu|",
           lambda r: r.tori.frequencies.diffusion),
    _torus("resonance", "integer vector m of the nearest resonance m . nu = 0",
           lambda r: r.tori.frequencies.resonance, "i8", ("fundamental",)),
    _torus("resonance_order", "order |m|_1 of the nearest resonance (-1: none searched)",
           lambda r: r.tori.frequencies.resonance_order, "i8"),
    _torus("resonance_distance", "|m . nu| / (|m| max |nu|) of the nearest resonance",
           lambda r: r.tori.frequencies.resonance_distance),
    Var("n_steps", "accepted integration steps of the nominal orbit", lambda r: r.n_steps,
        ALL, "i8"),
    Var("n_rhs", "right-hand-side evaluations of the nominal orbit", lambda r: r.n_rhs,
        ALL, "i8"),
    Var("wall_time", "wall-clock time spent on the cell", lambda r: r.wall_time, ALL,
        units="s", reproducible=False),
    Var("initial_state", "phase-space state at t = 0", lambda r: r.start,
        extra=("component",)),
    Var("n_crossings", "crossings of the surface of section (all, also those not kept)",
        lambda r: r.n_crossings, dtype="i8", when=_section),
    Var("crossing_time", "time of each kept section crossing", lambda r: r.crossing_time,
        extra=("crossing",), when=_section),
    *[_reduced_crossing(q) for q in ("sigma", "p_sigma", "eta", "p_eta", "phi", "p_phi")],
    Var("crossing_state", "phase-space state at each kept section crossing",
        lambda r: r.crossing_state, extra=("crossing", "component"),
        when=lambda c: _section(c) and c.tables["section"]["store_state"]),
    _history("ftle", "FTLE", _which("ftle")),
    _history("megno", "<Y>", _which("megno")),
    _history("fli", "FLI", _which("fli")),
    _history("sali", "SALI", _which("sali")),
]
BY_NAME = {v.name: v for v in VARIABLES}


def variables(config) -> list[Var]:
    """The variables a config's archive holds. A variable named like a grid axis (energy, or
    the section family's angular_momentum) is left out: that axis holds its value."""
    axes = {a.name for a in config.axes}
    out = []
    for v in VARIABLES:
        if not v.when(config) or v.name in axes:
            continue
        if v.name == "angular_momentum" and config.tables["system"]["dim"] == 3:
            v = replace(v, long_name="total angular momentum at t = 0", extra=("spatial",))
        out.append(v)
    return out


def cell_shape(config, v: Var) -> tuple[int, ...]:
    """The shape of one cell's value of v (its own dimensions' sizes)."""
    s = config.tables["system"]
    sizes = {"crossing": config.tables["section"]["max_crossings"],
             "history_time": config.tables["indicators"]["history_points"],
             "component": 2 * s["bodies"] * s["dim"], "spatial": 3,
             "observable": len(config.tables["tori"]["observables"]),
             "fundamental": len(fundamental_names(s["bodies"], s["dim"]))}
    return tuple(sizes[d] for d in v.extra)


class Slot(NamedTuple):
    """One result array of a task: its name, dtype and the shape of one cell's value."""

    name: str
    dtype: str
    shape: tuple


def layout(config) -> tuple[Slot, ...]:
    """The arrays a task returns for a config: small, picklable, shipped with every task."""
    return tuple(Slot(v.name, v.dtype, cell_shape(config, v)) for v in variables(config)
                 if not v.derived)


def empty_results(slots, count: int) -> dict[str, np.ndarray]:
    """Fill-valued result arrays for `count` cells."""
    return {s.name: np.full((count,) + s.shape, BY_NAME[s.name].fill, dtype=s.dtype)
            for s in slots}


def fill_row(results: dict, k: int, cell: CellResult):
    """Row k of every result array from one cell's result, as each variable declares."""
    finished, started = cell.status.finished, cell.start is not None
    for name, row in results.items():
        v = BY_NAME[name]
        if (v.cells == FINISHED and not finished) or (v.cells == STARTED and not started):
            continue
        value = v.value(cell)
        if row.ndim == 1:
            row[k] = value
        else:
            value = np.asarray(value)
            row[k, :value.shape[0]] = value


def markdown_table() -> str:
    """The README's table of archive variables."""
    lines = ["| variable | meaning | units | dimensions beyond the grid | cells |",
             "| --- | --- | --- | --- | --- |"]
    for v in VARIABLES:
        units = "flags" if v.name == "status" else v.units
        extra = "spatial (3-D)" if v.name == "angular_momentum" else ", ".join(v.extra)
        note = "" if v.reproducible else " (not reproducible)"
        text = (v.long_name + note).replace("|", "\\|").replace("<", "&lt;").replace(">", "&gt;")
        lines.append(f"| `{v.name}` | {text} | {units} | {extra} | {v.cells} |")
    return "\n".join(lines)


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
    """Coordinate variables (numeric, monotone: CF section 1.3) and the string labels of the
    component and spatial dimensions as auxiliary coordinates (CF section 6.1)."""
    from .indicators import history_times
    from .config import system_terms
    terms = system_terms(config.tables["system"])
    coords = {a.name: (a.name, a.values, {
        "long_name": f"parameter {a.param} of the {terms[a.term][0]} term {terms[a.term][1]}"
        if a.term >= 0 else f"initial-condition parameter {a.name}", "units": "1"})
        for a in config.axes}
    coords["history_time"] = ("history_time", history_times(
        config.tables["integration"]["t_final"], config.tables["indicators"]["history_points"]),
        {"long_name": "time of the convergence history points", "units": "1"})
    coords["component_name"] = ("component", _component_labels(config),
                                {"long_name": "phase-space component (positions, then "
                                              "momenta)"})
    if config.tables["section_enabled"]:
        n = config.tables["section"]["max_crossings"]
        coords["crossing"] = ("crossing", np.arange(n), {"long_name": "index of the kept "
                                                                      "section crossing",
                                                         "units": "1"})
    if config.tables["system"]["dim"] == 3:
        coords["spatial_axis"] = ("spatial", ["x", "y", "z"], {"long_name": "spatial axis"})
    if config.tables["tori"]["analyse"]:
        s = config.tables["system"]
        coords["observable_name"] = ("observable", config.tables["tori"]["observables"],
                                     {"long_name": "observable of the Birkhoff averages"})
        coords["fundamental_name"] = ("fundamental", fundamental_names(s["bodies"], s["dim"]),
                                      {"long_name": "fundamental frequency: a basis of shape "
                                                    "frequencies, then the rotation"})
    return coords


def attributes(config, command: str) -> dict:
    from .config import system_terms
    ver = versions()
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    init = config.tables["initial"]
    return {
        "Conventions": "CF-1.10",
        "title": f"survey '{config.name}': chaos indicators of the {init['family']} family "
                 f"under {' + '.join(name for _, name, _ in system_terms(config.tables['system']))}",
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


# ---------------------------------------------------------------- writing

# the archive is written a group of variables at a time, each group at most this large
# in memory: one pass over the checkpoint files per group, not per variable
GROUP_BYTES = 256 * 2 ** 20


def write(config, load: Callable[[list[str]], dict], command: str) -> Path:
    """Write the archive atomically: to a temporary file beside the output, in groups of
    variables of at most GROUP_BYTES together (peak memory: a group, or one variable if
    larger), then renamed into place. `load(names)` returns those variables over all cells in flat C order, each
    of shape (n_cells, ...)."""
    import xarray as xr
    out = config.output
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = partial_path(out)
    dims = tuple(a.name for a in config.axes)
    try:
        coords = coordinates(config)
        base = xr.Dataset(coords={k: xr.Variable(*v) for k, v in coords.items()},
                          attrs=attributes(config, command))
        base.to_netcdf(tmp, mode="w", engine="netcdf4",
                       encoding={k: {"_FillValue": None} for k in coords})
        for group in _groups(config, [v for v in variables(config) if not v.derived]):
            data = load([v.name for v in group])
            _append(tmp, [(v, data.pop(v.name).reshape(config.shape + cell_shape(config, v)),
                           dims + v.extra, {}) for v in group])
        with xr.open_dataset(tmp, engine="netcdf4") as ds:    # reads only what it needs
            derived = derive(ds)
        _append(tmp, [(v, derived[v.name], dims, derived.get(v.name + ":attrs", {}))
                      for v in variables(config) if v.derived])
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()
    return out


def _groups(config, vs: list[Var]):
    """Consecutive runs of variables whose arrays over all cells fit in GROUP_BYTES
    together (a larger variable goes alone)."""
    group, size = [], 0
    for v in vs:
        nbytes = config.n_cells * int(np.prod(cell_shape(config, v))) * np.dtype(v.dtype).itemsize
        if group and size + nbytes > GROUP_BYTES:
            yield group
            group, size = [], 0
        group.append(v)
        size += nbytes
    if group:
        yield group


def _append(path, entries):
    """Append variables (Var, data, dims, extra attributes) to the file in one opening."""
    import xarray as xr
    one = xr.Dataset({v.name: xr.Variable(dims, data, {**v.attrs(), **extra})
                      for v, data, dims, extra in entries})
    enc = {v.name: {"zlib": True, "complevel": 4,
                    "_FillValue": None if v.dtype.startswith("i") else np.nan}
           for v, *_ in entries}
    one.to_netcdf(path, mode="a", engine="netcdf4", encoding=enc)


def derive(ds) -> dict:
    """The derived variables of an archive's Dataset (and the attributes they carry): the
    regime and its confidence, with the thresholds that decided them."""
    from .tori import Thresholds, classify, stored_table
    thresholds = Thresholds.from_table(stored_table(ds))
    regime, confidence = classify(ds, thresholds)
    return {"regime": regime, "regime_confidence": confidence,
            "regime:attrs": {"thresholds": thresholds.describe()}}


def partial_path(out: Path) -> Path:
    """Where an archive is written before it is renamed into place."""
    return out.with_name(f".{out.name}.partial-{os.getpid()}")


# ---------------------------------------------------------------- reading and checking

class ArchiveError(ValueError):
    """A file that is not a readable survey archive: one line saying what it is instead."""


def open_archive(path):
    """The Dataset of a survey archive, or ArchiveError naming what is wrong with the file."""
    import xarray as xr
    path = Path(path)
    if not path.exists():
        raise ArchiveError(f"{path}: no such file")
    if not path.is_file():
        raise ArchiveError(f"{path}: not a regular file; give a survey archive (.nc)")
    try:
        ds = xr.open_dataset(path, engine="netcdf4")
    except Exception as exc:   # netCDF4 and HDF5 raise OSError, ValueError, RuntimeError
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ArchiveError(f"{path}: not a readable NetCDF file ({reason}); it may be "
                           "truncated or of another format") from None
    if "config" not in ds.attrs or "config_sha256" not in ds.attrs:
        ds.close()
        raise ArchiveError(f"{path}: a NetCDF file but not a survey archive (no stored "
                           "config)")
    return ds


def problems(ds, config) -> list[str]:
    """How an archive departs from what its stored config implies: the config's sha256,
    the grid coordinates, the set of variables, their dimensions, types and attributes."""
    found = []
    sha = hashlib.sha256(ds.attrs["config"].encode()).hexdigest()
    if sha != ds.attrs["config_sha256"]:
        found.append("config_sha256 does not match the stored config text (edited after "
                     "the run)")
    for name, (dim, values, attrs) in coordinates(config).items():
        if name not in ds.variables:
            found.append(f"coordinate {name} is missing")
            continue
        stored, values = ds[name].values, np.asarray(values)
        same = stored.shape == values.shape and (
            stored.tobytes() == values.astype(stored.dtype).tobytes() if stored.dtype.kind == "f"
            else np.array_equal(stored.astype(str), values.astype(str)))
        if not same:
            found.append(f"coordinate {name} differs from the grid of the stored config")
    expected = {v.name: v for v in variables(config)}
    for name in sorted(set(ds.data_vars) - set(expected)):
        found.append(f"variable {name} is not part of this config's archive")
    dims = tuple(a.name for a in config.axes)
    for name, v in expected.items():
        if name not in ds.data_vars:
            found.append(f"variable {name} is missing")
            continue
        var = ds[name]
        want_dims = dims + v.extra
        if var.dims != want_dims:
            found.append(f"variable {name} has dimensions {var.dims}, expected {want_dims}")
        if np.dtype(var.dtype).kind != np.dtype(v.dtype).kind:
            found.append(f"variable {name} has type {var.dtype}, expected {v.dtype}")
        want = v.attrs()
        for key in sorted(set(want) | (set(var.attrs) & DECLARED_ATTRS)):
            got = var.attrs.get(key)
            if got is None or not np.array_equal(np.asarray(got), np.asarray(want.get(key))):
                found.append(f"variable {name}: attribute {key} is {got!r}, expected "
                             f"{want.get(key)!r}")
    return found


# the attributes a declaration decides; a file may add others (e.g. a user's notes)
DECLARED_ATTRS = {"long_name", "units", "flag_values", "flag_meanings", "comment",
                  "reproducible"}
