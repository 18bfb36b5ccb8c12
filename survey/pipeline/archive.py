"""The survey archive: the arrays a task returns and how a cell fills them (from the
declarations in survey.catalog.variables), the CF coordinates, attributes and provenance, the
atomic NetCDF write, and the checks `verify` runs on a file."""
from __future__ import annotations

import contextlib
import datetime
import hashlib
import importlib
import os
import subprocess
import sys
import threading
from dataclasses import replace
from importlib import metadata
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from ..analysis.classify import classify, stable, stored_table
from ..analysis.frequencies import labelled
from ..catalog import defaults
from ..catalog.errors import ArchiveError, SurveyError
from ..catalog.families import FAMILY_VARIABLES
from ..catalog.regimes import Thresholds
from ..catalog.status import Status
from ..catalog.variables import (
    BY_NAME,
    FINISHED,
    STARTED,
    VARIABLES,
    ENSEMBLE_STATISTICS,
    CellResult,
    V,
    Var,
    fundamental_names,
    in_field,
    history_grid,
    horizon_factors,
)
from .build import system_terms
from .resources import GROUP_BYTES


def variables(config) -> list[Var]:
    """The variables a config's archive holds. A variable named like a grid axis (energy, or
    the section family's angular_momentum) is left out: that axis holds its value."""
    axes = {a.name for a in config.axes}
    out = []
    for v in VARIABLES:
        if not v.when(config) or v.name in axes:
            continue
        if v.name == V.angular_momentum and config.settings.system.dim == 3:
            v = replace(v, long_name="total angular momentum at t = 0", extra=("spatial",))
        out.append(v)
    return out


def cell_shape(config, v: Var) -> tuple[int, ...]:
    """The shape of one cell's value of v (its own dimensions' sizes)."""
    s, tori = config.settings.system, config.settings.tori
    sizes = {"crossing": config.settings.section.max_crossings,
             "history_time": history_grid(config.settings.integration.t_final,
                                          config.settings.indicators.history_points,
                                          tori.extend, tori.extend_rounds).size,
             "horizon": len(horizon_factors(tori.extend, tori.extend_rounds)),
             "component": 2 * s.bodies * s.dim, "spatial": 3,
             "pair": s.bodies * (s.bodies - 1) // 2,
             "observable": len(tori.observables),
             "ensemble_statistic": len(ENSEMBLE_STATISTICS),
             "fundamental": len(fundamental_names(s.bodies, s.dim, in_field(s)))}
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


def versions() -> dict[str, str]:
    names = ["survey", "numpy", "numba", "llvmlite", "dask", "distributed", "xarray",
             "netCDF4", "sympy"]
    out = {"python": sys.version.split()[0]}
    for n in names:
        try:
            out[n] = metadata.version(n)
        except metadata.PackageNotFoundError:
            out[n] = "unknown"
    return out


# Settings that make this machine compute like another (each changes which code runs)
MACHINE_OVERRIDES = ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES", "NPY_DISABLE_CPU_FEATURES",
                     "GLIBC_TUNABLES", "OPENBLAS_CORETYPE")


def machine() -> str:
    """The CPU and the code paths chosen for it: the CPU model, the target numba compiles
    for, numpy's SIMD dispatch level, the C library, and any setting that overrides them.
    Provenance only: every x86-64 machine computes the same bits (survey.machine.portable),
    which verify, run on another machine, shows."""
    import platform

    from numba.core.registry import cpu_target
    from numpy._core import _multiarray_umath as umath
    model = ""
    try:
        with open("/proc/cpuinfo") as f:
            model = next((line.split(":", 1)[1].strip() for line in f
                          if line.startswith("model name")), "")
    except OSError:
        pass
    from ..machine.jit import VECTOR_DOUBLES
    # what numba's code generator was made with (its configuration may since have been
    # reloaded from an environment without survey.machine.jit's 256-bit setting)
    _, target, features = cpu_target.target_context.codegen().magic_tuple()
    if features.endswith("+prefer-256-bit"):
        target += " in 256-bit vectors"
    elif VECTOR_DOUBLES == 8:
        target += " in 512-bit vectors"
    dispatched = [k for k in umath.__cpu_dispatch__ if umath.__cpu_features__.get(k)]
    libc = " ".join(platform.libc_ver()).strip()
    overrides = [f"{k}={os.environ[k]}" for k in MACHINE_OVERRIDES if os.environ.get(k)]
    return "; ".join(filter(None, [
        f"{platform.machine()} {model or platform.processor() or 'unknown CPU'}",
        f"numba target {target}", f"numpy SIMD {'/'.join(dispatched) or 'baseline'}",
        libc, ", ".join(overrides)]))


def git_commit() -> str:
    here = Path(__file__).resolve().parents[1]
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
    s = config.settings.system
    axes = "xyz"[:s.dim]
    q = [f"{c}{b}" for b in range(s.bodies) for c in axes]
    return q + [f"p{c}" for c in q]


def coordinates(config, cells=None) -> dict:
    """Coordinate variables (numeric, monotone: CF section 1.3) and the string labels of the
    component and spatial dimensions as auxiliary coordinates (CF section 6.1). A refined
    survey's cells (sorted lattice ids) lie along a `cell` dimension, each grid parameter
    and the cell's refinement level an auxiliary coordinate along it."""
    terms = system_terms(config.system_table)
    dims = grid_dims(config)
    if cells is not None:
        lattice = config.lattice()
        at = lattice.indices(cells)
    coords = {a.name: (dims[0] if cells is not None else a.name,
                       a.values if cells is None else lattice.axis_values(k)[at[k]], {
        "long_name": f"parameter {a.param} of the {terms[a.term][0]} term {terms[a.term][1]}"
        if a.term >= 0 else f"initial-condition parameter {a.name}", "units": "1"})
        for k, a in enumerate(config.axes)}
    if cells is not None:
        coords["cell"] = ("cell", np.asarray(cells, dtype=np.int64), {
            "long_name": "index of the cell on the refinement lattice (C order over the grid "
                         "axes, each interval of the grid halved max_level times)",
            "units": "1", "lattice_shape": np.array(lattice.shape, dtype=np.int64),
            "max_level": np.int64(lattice.levels)})
        coords["level"] = ("cell", lattice.level(cells), {
            "long_name": "refinement level of the cell (0: the grid; each level halves the "
                         "spacing of the cells it splits)", "units": "1"})
    tori = config.settings.tori
    coords["history_time"] = ("history_time", history_grid(
        config.settings.integration.t_final, config.settings.indicators.history_points,
        tori.extend, tori.extend_rounds),
        {"long_name": "time of the convergence history points (a cell's history ends at "
                      "its regime_horizon)", "units": "1"})
    if V.regime_history in {v.name for v in variables(config)}:
        coords["horizon_factor"] = ("horizon", horizon_factors(tori.extend,
                                                               tori.extend_rounds),
                                    {"long_name": "horizon of each verdict of "
                                                  "regime_history, in units of t_final",
                                     "units": "1"})
    coords["component_name"] = ("component", _component_labels(config),
                                {"long_name": "phase-space component (positions, then "
                                              "momenta)"})
    s = config.settings.system
    if s.bodies >= 2:
        coords["pair_name"] = ("pair", [f"{i}-{j}" for i in range(s.bodies)
                                        for j in range(i + 1, s.bodies)],
                               {"long_name": "pair of bodies i-j"})
    if config.settings.section_enabled:
        n = config.settings.section.max_crossings
        coords["crossing"] = ("crossing", np.arange(n), {"long_name": "index of the kept "
                                                                      "section crossing",
                                                         "units": "1"})
    if config.settings.indicators.which:
        coords["ensemble_statistic_name"] = ("ensemble_statistic", list(ENSEMBLE_STATISTICS), {
            "long_name": "statistic over the ensemble of the cell's orbit and its perturbed "
                         "starts (q05: the 5% quantile)"})
    if config.settings.system.dim == 3:
        coords["spatial_axis"] = ("spatial", ["x", "y", "z"], {"long_name": "spatial axis"})
    if config.settings.tori.analyse:
        s = config.settings.system
        coords["observable_name"] = ("observable", config.settings.tori.observables,
                                     {"long_name": "observable of the Birkhoff averages"})
        coords["fundamental_name"] = ("fundamental", fundamental_names(s.bodies, s.dim,
                                                                         in_field(s)),
                                      {"long_name": "fundamental frequency: a basis of shape "
                                                    "frequencies, then the rotation"})
    return coords


def attributes(config, command: str) -> dict:
    ver = versions()
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    family = config.settings.initial.family
    return {
        "Conventions": "CF-1.10",
        "title": f"survey '{config.name}': chaos indicators of the {family} family under "
                 f"{' + '.join(name for _, name, _ in system_terms(config.system_table))}",
        "history": f"{now}: {command} (survey {ver['survey']})",
        "source": f"survey {ver['survey']}: numba DOP853 (rtol "
                  f"{config.settings.integration.rtol:g}) with variational equations",
        "references": "J.D. Meiss, Hamiltonian Triplet Interactions: Areal and Perimetric "
                      "Forces",
        "config": config.text,
        "config_resolved": config.resolved_text,
        "config_sha256": config.sha256,
        "result_key": config.result_key(),
        "grid_axes": " ".join(a.name for a in config.axes),
        "git_commit": git_commit(),
        "machine": machine(),
        **{f"version_{k}": v for k, v in ver.items()},
    }


def grid_dims(config) -> tuple[str, ...]:
    """The dimensions of a cell's values: the grid axes, or `cell` for a refined survey."""
    return ("cell",) if config.refined else tuple(a.name for a in config.axes)


_prefetching: list[threading.Thread] = []


def prefetch(modules=()):
    """Import what writing an archive needs (xarray, netCDF4, and the dask.array that
    xarray loads on its first Variable) and the given modules in a thread, while the
    workers compute: a noticeable part of a fresh process. `write` waits for it. The
    caller's thread must not import anything new meanwhile: CPython's imports in two
    threads at once once failed to find a module that was there (a CI run of `survey run`:
    "No module named 'tqdm.version'"). A module that fails to import is left to its
    importer to report."""
    def imports():
        import netCDF4  # noqa: F401
        import xarray as xr
        xr.Variable(("x",), np.zeros(1))
        for name in modules:
            with contextlib.suppress(ImportError):
                importlib.import_module(name)
    _prefetching.append(threading.Thread(target=imports, name="prefetch", daemon=True))
    _prefetching[-1].start()


def write(config, load: Callable[[list[str]], dict], command: str, cells=None,
          annotate: Callable | None = None) -> Path:
    """Write the archive atomically: to a temporary file beside the output, in groups of
    variables of at most GROUP_BYTES together (peak memory: a group, or one variable if
    larger), then renamed into place. `load(names)` returns those variables over all cells
    in flat C order (a refined survey: over its `cells`, sorted lattice ids), each of shape
    (cells, ...). annotate(ds) -> attributes (text) computed from the finished Dataset,
    added before the rename (what the report needs that only a solver can compute:
    pipeline.special.report_attributes)."""
    while _prefetching:
        _prefetching.pop().join()
    import xarray as xr
    out = config.output
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = partial_path(out)
    dims = grid_dims(config)
    shape = config.shape if cells is None else (len(cells),)
    try:
        coords = coordinates(config, cells)
        base = xr.Dataset(coords={k: xr.Variable(*v) for k, v in coords.items()},
                          attrs=attributes(config, command))
        base.to_netcdf(tmp, mode="w", engine="netcdf4",
                       encoding={k: {"_FillValue": None} for k in coords})
        count = int(np.prod(shape))
        for group in _groups(config, [v for v in variables(config) if not v.derived], count):
            data = load([v.name for v in group])
            _append(tmp, [(v, data.pop(v.name).reshape(shape + cell_shape(config, v)),
                           dims + v.extra, _settings_of(config, v)) for v in group])
        with xr.open_dataset(tmp, engine="netcdf4") as ds:    # reads only what it needs
            derived = derive(ds)
        _append(tmp, [(v, derived[v.name], dims + v.extra, derived.get(v.name + ":attrs", {}))
                      for v in variables(config) if v.derived])
        if annotate is not None:
            import netCDF4
            with xr.open_dataset(tmp, engine="netcdf4") as ds:
                extra = annotate(ds.load())
            with netCDF4.Dataset(tmp, "a") as nc:
                nc.setncatts(extra)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, out)
    finally:
        if tmp.exists():
            tmp.unlink()
    return out


def _settings_of(config, v: Var) -> dict:
    """What a variable's values were measured with beyond the config's text: the escape
    radius and binding energy derived from the potential (build.escape_for; those of the
    first cell's System where a term parameter is a grid axis)."""
    if v.name == V.escape_time:
        radius, binding = config.escape
        return {"escape_radius": radius, "escape_binding": binding}
    return {}


def _groups(config, vs: list[Var], count: int):
    """Consecutive runs of variables whose arrays over all `count` cells fit in GROUP_BYTES
    together (a larger variable goes alone)."""
    group, size = [], 0
    for v in vs:
        nbytes = count * int(np.prod(cell_shape(config, v))) * np.dtype(v.dtype).itemsize
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
    regime and its confidence, with the thresholds that decided them, and whether it is
    the class of the verdict at the horizon before."""
    thresholds = Thresholds.from_table(stored_table(ds))
    regime, confidence = classify(ds, thresholds)
    steady = stable(ds[V.regime_history].values) if V.regime_history in ds else \
        np.zeros(regime.shape, dtype=np.int8)
    out = {V.regime: regime, V.regime_confidence: confidence, V.regime_stable: steady,
           "regime:attrs": {"thresholds": thresholds.describe()}}
    if V.frequency in ds:
        out[V.frequency_labelled] = labelled(ds, regime)
    return out


def family_dataset(kind: str, values: dict, parameter: str = "", coords=None,
                   attrs=None):
    """A family's Dataset (catalog.families): every variable declared for `kind`, in the
    declared order, from `values` (name -> array) -- one declared and not given, or given
    and not declared, is an error -- with its long name (`{parameter}` filled in) and
    units; labels (dtype str) as object arrays."""
    import xarray as xr
    declared = FAMILY_VARIABLES[kind]
    names = [v.name for v in declared]
    if set(values) != set(names):
        raise ValueError(f"a {kind} family's variables are {names}: "
                         f"{sorted(set(values) ^ set(names))} given or missing")
    data = {}
    for v in declared:
        if v.name in (coords or {}):       # the parameter labels the members in its place
            continue
        array = np.array(values[v.name], dtype=object if v.dtype == "str" else v.dtype)
        declared_attrs = {"long_name": v.long_name.format(parameter=parameter)} \
            if v.long_name else {}
        if v.units:
            declared_attrs["units"] = v.units
        data[v.name] = (v.dims, array, declared_attrs)
    return xr.Dataset(data, coords=coords, attrs={"family": kind, **(attrs or {})})


def write_family(ds, path, command: str) -> Path:
    """A family's Dataset in NetCDF with its provenance (command, commit, machine,
    versions) and its config's sha256, written atomically."""
    out = Path(path)
    ds = ds.assign_attrs(config_sha256=hashlib.sha256(ds.attrs["config"].encode()).hexdigest(),
                         history=command, git_commit=git_commit(), machine=machine(),
                         **{f"version_{k}": v for k, v in versions().items()})
    tmp = out.with_name(f".{out.name}.partial")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        ds.to_netcdf(tmp, engine="netcdf4")
        tmp.replace(out)
    except (OSError, RuntimeError) as exc:     # netCDF4 reports some as RuntimeError
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise SurveyError(f"cannot write {out} ({getattr(exc, 'strerror', None) or exc}); "
                          "free some space or choose another --output") from None
    return out


def partial_path(out: Path) -> Path:
    """Where an archive is written before it is renamed into place."""
    return out.with_name(f".{out.name}.partial-{os.getpid()}")


def check_archives(archive) -> list[tuple[str, Path]]:
    """(variant, path) of each [check] run's archive found beside a survey archive."""
    return [(v, f) for v in defaults.CHECK_VARIANTS
            if (f := defaults.check_archive(archive, v)).exists()]


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
    lacking = [name for name in (V.status, V.regime) if name not in ds]
    if lacking and "family" not in ds.attrs:
        ds.close()
        raise ArchiveError(f"{path}: a survey archive without its {lacking[0]} variable, "
                           "which every survey writes: it was edited or cut short; run the "
                           "survey again")
    if "family" not in ds.attrs:
        codes = np.unique(ds[V.status].values)
        unknown = codes[~np.isin(codes, [int(s) for s in Status])]
        if unknown.size:
            ds.close()
            raise ArchiveError(f"{path}: status {unknown[0]} is no status survey writes "
                               f"({', '.join(f'{int(s)} {s.name.lower()}' for s in Status)}): "
                               "the archive was edited; run the survey again")
    return ds


def problems(ds, config) -> list[str]:
    """How an archive departs from what its stored config implies: the config's sha256,
    the grid coordinates, the set of variables, their dimensions, types and attributes."""
    found = []
    sha = hashlib.sha256(ds.attrs["config"].encode()).hexdigest()
    if sha != ds.attrs["config_sha256"]:
        found.append("config_sha256 does not match the stored config text (edited after "
                     "the run)")
    cells = None
    if config.refined:
        if "cell" not in ds.coords:
            return found + ["the config refines its grid, and the archive has no cell "
                            "coordinate"]
        cells = ds["cell"].values.astype(np.int64)
        if cells.size == 0 or np.any(np.diff(cells) <= 0) or cells[0] < 0 or \
                cells[-1] >= np.prod(config.lattice().shape):
            return found + ["coordinate cell is not a sorted list of refinement-lattice "
                            "indices"]
    for name, (dim, values, attrs) in coordinates(config, cells).items():
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
    dims = grid_dims(config)
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
