"""results/README.md from its template, workflows/results_readme.md: the template's prose
holds no measured number. Each is a placeholder, {{kind name | argument | ...}}, filled
from an archive in results/ (through the same analysis the reports use) or quoted from a
file the code generated there (a report, a family's page), so the text cannot drift from
what the archives say. A number typed in the template must be the paper's or a workflow's
(tests/test_results.py finds the source of every number).

Placeholders:
- {{file NAME | REGEX}}: the first group of REGEX in results/NAME (a generated file);
- {{cell NAME | VAR | AXIS=VALUE | FORMAT}}: VAR of one cell of NAME.nc (FORMAT, a
  format spec, default .4g);
- {{ensemble NAME | VAR | AXIS=VALUE}}: its ensemble's mean +- sd and 5/50/95% quantiles;
- {{range NAME | VAR}}: [min, max] of VAR over the cells that finished;
- {{count NAME | REGIME}}: cells of that regime (or `cells`: all of them);
- {{onset NAME}}: the onset along the archive's one axis with its total uncertainty (and
  the [check] variants not run, whose share it lacks), and {{onset NAME | PART}} one
  contribution of it (step, seed, rounding, horizon, tolerance);
- {{within NAME | VAR | AXIS=VALUE | X}}: whether a published X lies within the 5-95%
  quantiles of the cell's ensemble: the verdict a comparison with the paper prints;
- {{onset NAME | verdict X}}: whether a published onset X lies within twice the onset's
  total uncertainty;
- {{manifolds NAME}}: a manifold archive (an isosceles plane's NAME.nc): its hyperbolic
  orbits, how far their branches were grown and their first homoclinic crossings, each
  to the digits its accuracy supports."""
from __future__ import annotations

import contextlib
import re
from pathlib import Path

import numpy as np

from ..analysis.refine import as_grid
from ..catalog import defaults
from ..catalog.regimes import Regime
from ..catalog.status import Status
from ..catalog.variables import ENSEMBLE_STATISTICS, V
from .report import onset_budget, plus_minus

PLACEHOLDER = re.compile(r"\{\{(.*?)\}\}", re.S)


def render(template: str, *folders: Path) -> str:
    """The template with every placeholder filled from the files in `folders` (a file is
    read from the first folder that has it: `reproduce` renders from its staging folder
    over results/)."""
    archives = {}

    def find(name: str) -> Path:
        for folder in folders:
            if (Path(folder) / name).exists():
                return Path(folder) / name
        raise FileNotFoundError(f"{name}: in none of {', '.join(map(str, folders))}")
    try:
        return PLACEHOLDER.sub(lambda m: _fill(m.group(1), find, archives), template)
    finally:
        for ds in archives.values():
            ds.close()


def _fill(body: str, find, archives: dict) -> str:
    kind, _, rest = body.strip().partition(" ")
    if kind == "file":
        name, _, pattern = (a.strip() for a in rest.partition("|"))
        found = re.search(pattern, find(name).read_text())
        if found is None:
            raise ValueError(f"{{{{{body}}}}}: {pattern!r} not found in {find(name)}")
        return found.group(1)
    args = [a.strip() for a in rest.split("|")]
    if kind == "manifolds":
        import xarray as xr
        with xr.open_dataset(find(f"{args[0]}.nc")) as ds:
            return _manifolds(ds)
    if args[0] not in archives:
        import xarray as xr
        archives[args[0]] = xr.open_dataset(find(f"{args[0]}.nc"))
    ds = as_grid(archives[args[0]])
    fill = {"cell": _cell, "ensemble": _ensemble, "range": _range, "count": _count,
            "onset": _onset, "within": _within}.get(kind)
    if fill is None:
        raise ValueError(f"{{{{{body}}}}}: unknown placeholder kind {kind!r}")
    return fill(ds, (find, args[0]), *args[1:])


def _at(ds, where: str):
    axis, _, value = where.partition("=")
    return ds.sel({axis.strip(): float(value)}, method="nearest")


def _cell(ds, results, var, where, spec=".4g"):
    return format(float(_at(ds, where)[var]), spec)


def _quantiles(ds, var, where):
    values = _at(ds, where)[var].values
    return dict(zip(ENSEMBLE_STATISTICS, values)), int(_at(ds, where)[V.ensemble_orbits])


def _ensemble(ds, results, var, where):
    q, n = _quantiles(ds, var, where)
    return (f"{q['mean']:.3g} +- {q['sd']:.2g}, 5/50/95% {q['q05']:.3g}/{q['q50']:.3g}/"
            f"{q['q95']:.3g} ({n} orbits)")


def _within(ds, results, var, where, published):
    q, n = _quantiles(ds, var, where)
    x = float(published)
    if q["q05"] <= x <= q["q95"]:
        return (f"agrees within the spread: {published} lies between the 5% and 95% "
                f"quantiles of the {n} nearby orbits")
    side = "below the 5%" if x < q["q05"] else "above the 95%"
    return f"differs: {published} lies {side} quantile of the {n} nearby orbits"


def _range(ds, results, var):
    done = ds[V.status].values == Status.OK
    values = ds[var].values[done]
    return f"[{np.min(values):.3g}, {np.max(values):.3g}]"


def _count(ds, results, regime):
    if regime == "cells":
        return str(ds[V.status].size)
    return str(int(np.sum(ds[V.regime].values == Regime[regime.upper()])))


def _onset(ds, where, part=None):
    """The onset's budget over the [check] runs found beside the archive (as its report
    gives it)."""
    import xarray as xr
    (axis,) = ds[V.status].dims
    find, name = where
    with contextlib.ExitStack() as stack:
        checks = {}
        for variant in defaults.CHECK_VARIANTS:
            try:
                path = find(defaults.check_archive(name + ".nc", variant).name)
            except FileNotFoundError:
                continue
            checks[variant] = as_grid(stack.enter_context(xr.open_dataset(path)))
        b = onset_budget(ds, axis, checks)
    if b is None:
        raise ValueError(f"{name}: no onset along {axis}")
    if part is None:
        missing = [v for v in defaults.CHECK_VARIANTS if v not in checks]
        return (plus_minus(b.estimate, b.total) if np.isfinite(b.total) else
                f"{b.estimate:.6g} (not established)") + (
            f" (not measured: {', '.join(missing)})" if missing else "")
    if part.startswith("verdict"):
        x = float(part.split()[1])
        off = abs(x - b.estimate) / b.total if b.total > 0 else np.inf
        return (f"agrees: {x:g} lies within twice the onset's uncertainty" if off <= 2 else
                f"differs: the onset lies {'below' if b.estimate < x else 'above'} {x:g} "
                f"by {off:.0f} times its uncertainty")
    sizes = {what: size for what, size, _ in b.parts}
    if part not in sizes:
        raise ValueError(f"{name}: no {part!r} in its onset's budget (no such [check] run)")
    return "no onset" if not np.isfinite(sizes[part]) else f"{sizes[part]:.2g}"


def _manifolds(ds) -> str:
    from ..analysis.findings import to_accuracy
    parts = []
    for k in range(ds.sizes["orbit"]):
        if not (ds["branch_orbit"].values == k).any():
            continue
        on = np.isin(ds["point_branch"].values, np.flatnonzero(ds["branch_orbit"].values == k))
        text = (f"the {ds['orbit_kind'].values[k]} orbit at b = {ds['orbit_b'].values[k]:.8f}"
                f" (multiplier {ds['orbit_multiplier'].values[k]:.6g}): its four branches "
                f"to arclength {ds['arclength'].values[on].max():.3g} ({int(on.sum())} "
                f"points)")
        crossings = []
        for h in np.flatnonzero(ds["branch_orbit"].values[ds["homoclinic_unstable"].values]
                                == k):
            acc = float(ds["homoclinic_accuracy"].values[h])
            side = ["-", "+"]
            u, s = (int(ds[f"homoclinic_{x}"].values[h]) for x in ("unstable", "stable"))
            crossings.append(
                f"unstable {side[int(ds['branch_side'].values[u] > 0)]} with stable "
                f"{side[int(ds['branch_side'].values[s] > 0)]} at "
                f"({to_accuracy(float(ds['homoclinic_b'].values[h]), acc)}, "
                f"{to_accuracy(float(ds['homoclinic_p_b'].values[h]), acc)}) +- {acc:.0e}")
        parts.append(text + ("; first crossings (homoclinic): " + "; ".join(crossings)
                             if crossings else "; no homoclinic crossing within it"))
    return "; ".join(parts) or "no hyperbolic orbit"
