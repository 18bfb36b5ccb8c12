"""The KAM-torus detection report of a survey archive: Markdown with its figures beside it,
written for a reader who has not seen the config."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..analysis.classify import (evidence_votes, regular_share, separation_share, wilson,
                                 share_sensitivity, stored_config, stored_table,
                                 threshold_margins)
from ..analysis.findings import decorrelated, how_many, islands, regions, twists
from ..analysis.onset import budget, onset, onset_over_horizons, runs
from ..analysis.refine import as_grid, boundaries
from ..catalog import defaults
from ..catalog.regimes import IRREGULAR, REGULAR, Regime, Thresholds
from ..catalog.status import Status
from ..catalog.variables import ENSEMBLE_MIN, START_COORDINATES, V
from . import plots
from .sections import in_field


PROVENANCE_LINE = "- Code: survey "


def without_provenance(text: str) -> str:
    """A report's text without its provenance line (version, commit, date, command): what
    `reproduce` compares."""
    return "\n".join(line for line in text.splitlines()
                     if not line.startswith(PROVENANCE_LINE))


def write(ds, folder, stem: str | None = None, figures: bool = True, checks=None) -> Path:
    """Write STEM_report.md and its figures into `folder`; returns the report's path.
    checks: the archives of the survey's [check] runs by variant (defaults.CHECK_VARIANTS);
    the report states the claims of the seed run beside its own, and every run's share in
    an onset's uncertainty. The special solutions its cells start on, set beside the
    family, and the slice a section grid fixes are those the archive stores
    (plots.stored_special)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stem = stem or Path(ds.encoding.get("source", "survey")).stem
    special, slice_at = plots.stored_special(ds)
    ds = as_grid(ds)
    figs = plots.draw(ds, folder, stem, special=special, slice_at=slice_at) if figures \
        else []
    text = markdown(ds, [p.name for p in figs], checks, special)
    path = folder / f"{stem}_report.md"
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return path


def markdown(ds, figure_names=(), checks=None, special=None) -> str:
    special = plots.stored_special(ds)[0] if special is None else special
    ds, checks = as_grid(ds), {k: as_grid(c) for k, c in (checks or {}).items()}
    check = checks.get("seed")          # the second run whose claims are set beside ours
    config = stored_config(ds)
    axes = plots.map_axes(ds)
    regime = ds[V.regime].values
    th = Thresholds(**json.loads(ds[V.regime].attrs["thresholds"])) \
        if "thresholds" in ds[V.regime].attrs else Thresholds.from_table(stored_table(ds))
    n = regime.size
    out = [f"# {ds.attrs.get('title', 'survey report')}", ""]

    out += ["## What was run", ""]
    system, integ, initial = config["system"], config["integration"], config["initial"]
    grid = ", ".join(f"{a} from {float(ds[a].min()):g} to {float(ds[a].max()):g} "
                     f"({np.unique(ds[a].values).size} values)" for a in axes) or "a single cell"
    if "interactions" in system:
        potential = "the sum of " + " + ".join(
            f"{t.get('kind')} `{plots.term_label(t)}` "
            + str({k: "(grid axis)" if isinstance(v, (dict, list)) else v
                   for k, v in t.get("params", {}).items()})
            + (" times m_i m_j" if t.get("mass_weighted") else "")
            for t in system["interactions"])
    else:
        potential = (f"potential `{system['potential']}` "
                     f"{system['params'] or '(its default parameters)'}")
    out += [f"- System: {system['bodies']} bodies in "
            f"{system['dim']}-D, masses {system.get('masses', 'all 1')}, "
            f"{potential}.",
            f"- Initial conditions: family `{initial.get('family')}`"
            + "".join(f", {k} = {v:g}" if isinstance(v, float) else f", {k} = {v}"
                      for k, v in initial.items() if k != "family" and k not in axes
                      and not (k == "starts_per_cell" and v == 1))
            + f"; grid: {grid}; {n} cell{'s' * (n != 1)}.",
            f"- Integration: DOP853 to t = {integ['t_final']:g}, rtol = "
            f"{integ['rtol']:g}, atol = {integ['atol']:g}; chaos indicators "
            f"{', '.join(config['indicators']['which'])}; torus analysis every "
            f"{config['tori']['sample_interval']:g} time units.",
            *_scale_free(ds, axes),
            f"{PROVENANCE_LINE}{ds.attrs.get('version_survey', '?')}, commit "
            f"`{ds.attrs.get('git_commit', '?')}`; {ds.attrs.get('history', '')}.", ""]

    if not np.any(ds[V.status].values == Status.OK):
        out += ["**No cell finished** (see the status of each cell): there are no indicator "
                "values, and the figures show only the regimes.", ""]
    steady = ds[V.regime_stable].values == 1 if V.regime_stable in ds else \
        np.zeros(regime.shape, dtype=bool)
    out += ["## Regimes", "", "| regime | cells | share | confirmed | meaning |",
            "| --- | --- | --- | --- | --- |"]
    for r in Regime:
        k = int(np.sum(regime == r))
        if k:
            sure = int(np.sum((regime == r) & steady)) if r in REGULAR + IRREGULAR else None
            out.append(f"| {r.name.lower()} | {k} | {100 * k / n:.1f}% | "
                       f"{'—' if sure is None else sure} | {r.meaning} |")
    out += ["", "Confirmed: the verdict is of the class (regular or irregular) decided at the "
                "horizon before; the others are claimed to their horizon only. "
                + _sample_share(ds, axes, regime), ""]
    out += _horizons(ds, regime, steady, integ["t_final"])

    out += _ensembles(ds, regime)
    out += _refinement(ds, config, regime, check)
    out += _shares(ds, axes, regime, config.get("reference"))
    out += _sensitivity(ds, axes, th)
    out += _onsets(ds, axes, regime, checks, th)
    out += _islands(axes, regime)
    out += _second_run(ds, check, regime)
    out += _tori_table(ds, axes, regime)
    out += _special(ds, special, regime)
    out += _escapes(ds)
    out += _approaches(ds, regime)
    out += _agreement(ds, th)
    out += _thresholds(th)
    out += _quality(ds)
    if figure_names:
        out += ["## Figures", ""] + [f"![{name}]({name})" for name in figure_names] + [""]
        many = len(plots.shells(ds)) if plots.section_axes(ds) else 0
        if many > plots.MAX_SHELLS:
            out += [f"No section figure: the cells start on {many} different energy shells "
                    "(E, J, and the system's parameters); a section is drawn one shell a "
                    f"panel, at most {plots.MAX_SHELLS}. For a section, survey one shell: "
                    "the `section` family at one E and J.", ""]
    return "\n".join(out)


def _refinement(ds, config, regime, check=None) -> list[str]:
    """How a refined survey's cells came about, and (one axis) the regime boundaries its
    bisection located: each with the bisection's half-width, whether the cells either side
    hold their verdict class from the horizon before, and where the [check] run (another
    seed, its own refinement) puts the nearest boundary of the same kind."""
    if "level" not in ds.coords:
        return []
    r = config["refine"]
    level = ds["level"].values
    axes = str(ds.attrs.get("grid_axes", "")).split()
    base = int(np.sum(level == 0))
    top = int(level.max())
    why = ["their verdict class (regular, irregular, neither) differs" if r["by"] == "class"
           else "their regimes differ"]
    if r.get("indicator"):
        why += [f"{r['indicator']} changes by more than " + " or by ".join(
            x for x in (f"{r['jump']:g}" if r.get("jump") else "",
                        f"a factor {r['ratio']:g}" if r.get("ratio") else "") if x)]
    limits = [f"at most {r['max_level']} levels"]
    if r.get("tolerance"):
        limits.append(f"intervals no narrower than {r['tolerance']:g}")
    if r.get("max_cells"):
        limits.append(f"at most {r['max_cells']} cells")
    counts = ", ".join(f"level {k}: {int(np.sum(level == k))}" for k in range(top + 1))
    spans = [float(ds[a].max() - ds[a].min()) for a in axes]
    steps = [np.diff(np.unique(ds[a].values)) for a in axes]
    finest = [float(s.min()) if s.size else 0.0 for s in steps]
    uniform = int(np.prod([round(span / f) + 1 if f > 0 else 1
                           for span, f in zip(spans, finest)]))
    out = ["## Refinement", "",
           f"The grid of {base} cells was refined where neighbouring cells disagree -- "
           + " or ".join(why) + f" -- splitting their interval{'s' if len(axes) == 1 else ''}"
           f" level by level ({', '.join(limits)}): {regime.size} cells in all ({counts}). "
           f"The finest spacing reached, {', '.join(f'{f:.3g}' for f in finest)} in "
           f"{', '.join(axes)}, would take {uniform} cells as a uniform grid: this survey "
           f"used {100 * regime.size / uniform:.0f}% of that.", ""]
    if r.get("indicator") in ds:
        values = ds[r["indicator"]].values
        if np.isfinite(values).any():
            labels = plots.cell_labels(ds)
            lo, hi = np.nanargmin(values), np.nanargmax(values)
            out += [f"{r['indicator']} over the cells: from {values.flat[lo]:.3g} ({labels[lo]}) "
                    f"to {values.flat[hi]:.3g} ({labels[hi]}); the grid alone gave "
                    f"{np.nanmin(values[level == 0]):.3g} to {np.nanmax(values[level == 0]):.3g}.",
                    ""]
    if len(axes) == 1:
        a = axes[0]
        found = boundaries(ds[a].values, regime, level)
        steady = ds[V.regime_stable].values == 1 if V.regime_stable in ds else None
        theirs = [] if check is None or "level" not in check.coords else boundaries(
            check[a].values, check[V.regime].values, check["level"].values)
        if found:
            x = ds[a].values
            head = f"| {a} from | to | boundary | +- | into | level |"
            rule = "| --- | --- | --- | --- | --- | --- |"
            if steady is not None:
                head += " both sides confirmed |"
                rule += " --- |"
            if check is not None:
                head += f" seed {_seed(check)}: nearest | shift |"
                rule += " --- | --- |"
            out += [f"Boundaries between regular and irregular cells along {a}, each at the "
                    "middle of the last interval the bisection left (undetermined and failed "
                    "cells skipped); confirmed: both cells beside it decided their class at "
                    "the horizon before too; the [check] run refined its own cells and its "
                    "nearest boundary of the same kind is given with its shift:", "",
                    head, rule]
            for b in found:
                row = (f"| {b['left']:.6g} | {b['right']:.6g} | {b['at']:.6g} | "
                       f"{b['error']:.2g} | {b['into']} | {b['level']} |")
                if steady is not None:
                    sides = [int(np.flatnonzero(x == b["left"])[0]),
                             int(np.flatnonzero(x == b["right"])[0])]
                    row += f" {'yes' if steady[sides].all() else 'no'} |"
                if check is not None:
                    same = [c for c in theirs if c["into"] == b["into"]]
                    near = min(same, key=lambda c: abs(c["at"] - b["at"])) if same else None
                    row += (" none | — |" if near is None else
                            f" {near['at']:.6g} | {abs(near['at'] - b['at']):.2g} |")
                out.append(row)
            out.append("")
    return out


def _sample_share(ds, axes, regime) -> str:
    """What a share of cells means: a count on a grid; on seeded random starts (the only
    axis a seed) an estimate of the regular share of the measure the family draws from
    (for `section_sample`, the section's Liouville measure on the shell)."""
    if "seed" in axes and len(axes) > 1:
        return (f"The cells are {ds.sizes['seed']} seeded starts at each point of the other "
                "axes: a share over all cells is a count, and each point's regular share "
                "(below) an estimate with its interval.")
    if list(axes) != ["seed"]:
        return ("The cells are a deterministic grid, not a random sample: a share is a "
                "count, with no sampling interval.")
    share = regular_share(ds, ds[V.status].copy(data=regime))
    n, k = int(share.decided), int(share.regular)
    if n == 0:
        return "The cells are seeded random starts, and none was decided."
    return (f"The cells are seeded random starts, a sample of the measure their family "
            f"draws from: of the {n} decided, {k} are regular, a regular share of "
            f"{100 * k / n:.0f}% (95% Wilson interval {100 * float(share.share_low):.0f}-"
            f"{100 * float(share.share_high):.0f}%; the {regime.size - n} undecided left out).")


SHARE_ROWS = 40     # grid points listed one by one in the regular-share table


def _published(reference: dict | None, p, criterion=None) -> str:
    """The [reference] table's published share at grid point p, and whether the survey's
    interval meets the published value's spread (and with the publication's own criterion
    applied to survey's orbits, `criterion`: its share, interval and agreement at p, and
    its shares at a tenth and ten times the growth): table cells, or none."""
    if not reference:
        return ""
    at = np.asarray(reference["at"], dtype=float)
    x = float(p[reference["axis"]])
    hit = np.flatnonzero(np.abs(at - x) <= 1e-9 * max(1.0, abs(x)))
    value, spread = (reference["regular_share"][hit[0]], reference["spread"]) if hit.size \
        else (None, 0.0)

    def agrees(share) -> str:
        if value is None or not int(share.decided):
            return "—"
        meets = float(share.share_low) <= value + spread \
            and float(share.share_high) >= value - spread
        return "yes" if meets else "**no**"
    cells = [agrees(p)]
    if criterion is not None:
        own, tenth, tenfold = (c.sel({reference["axis"]: x}) for c in criterion)
        cells += [f"{100 * float(own.share):.0f}% ({100 * float(own.share_low):.0f}-"
                  f"{100 * float(own.share_high):.0f}%; {100 * float(tenth.share):.0f}-"
                  f"{100 * float(tenfold.share):.0f}%)" if int(own.decided) else "—",
                  agrees(own)]
    published = "—" if value is None else \
        f"{100 * value:.0f}%" + (f" ± {100 * spread:.0f}" if spread else "")
    return f" {published} | " + " | ".join(cells) + " |"


def _shares(ds, axes, regime, reference=None) -> list[str]:
    """Several seeded starts per grid point: each point's regular share with its 95%
    Wilson interval (the points with every start alike summarised beyond SHARE_ROWS); with
    a [reference] table, the published share beside it and whether the two agree."""
    if "seed" not in axes or len(axes) == 1:
        return []
    share = regular_share(ds, ds[V.status].copy(data=regime))
    points = [a for a in axes if a != "seed"]
    flat = share.stack(point=points)
    out = [f"## Regular share per grid point ({ds.sizes['seed']} seeded starts each)", "",
           "Regular share: of a point's starts decided regular or irregular, the regular "
           "ones; 95% Wilson interval (the starts are a random sample of what the family "
           "draws from; undecided starts are left out).", ""]
    criterion = None
    if reference:
        out += [f"Published: {reference['source'].strip()} Agrees: the survey's interval "
                "meets the published value" + (" within its spread" if reference["spread"]
                                               else "") + ".", ""]
        if reference.get("crossings"):
            k, g = reference["crossings"], reference["growth"]
            criterion = [separation_share(ds, k, g * f) for f in (1.0, 0.1, 10.0)]
            out += [f"Their criterion on survey's orbits: a start counts as regular if its "
                    f"deviation grew by less than {g:g} by its {k}th crossing of the "
                    f"section (analysis.classify.separation_share); its share with the 95% "
                    f"interval, then its shares at a tenth and ten times that growth.", ""]
    extra = [" published | agrees |"] if reference else []
    if criterion is not None:
        extra.append(" their criterion on survey's orbits | agrees |")
    out += ["| " + " | ".join(points) + " | decided | regular | share | 95% interval |"
            + "".join(extra),
            "|" + " --- |" * (len(points) + 4 + 2 * len(extra))]
    mixed = np.flatnonzero((flat.share.values > 0) & (flat.share.values < 1))
    rows = np.arange(flat.sizes["point"]) if flat.sizes["point"] <= SHARE_ROWS else \
        mixed[:SHARE_ROWS]
    for i in rows:
        p = flat.isel(point=i)
        where = " | ".join(f"{float(p[a]):g}" for a in points)
        n, k = int(p.decided), int(p.regular)
        value = f"{100 * k / n:.0f}% | {100 * float(p.share_low):.0f}-" \
                f"{100 * float(p.share_high):.0f}%" if n else "— | —"
        out.append(f"| {where} | {n} | {k} | {value} |" + _published(reference, p, criterion))
    if flat.sizes["point"] > SHARE_ROWS:
        s = flat.share.values
        first = f", the first {SHARE_ROWS}" if mixed.size > SHARE_ROWS else ""
        out += ["", f"{flat.sizes['point']} points: listed those with a share strictly "
                    f"between 0 and 1 ({mixed.size}{first}); all regular at "
                    f"{int(np.sum(s == 1))}, none regular at {int(np.sum(s == 0))}, none "
                    f"decided at {int(np.sum(np.isnan(s)))}."]
    return out + [""]


def _sensitivity(ds, axes, th) -> list[str]:
    """How a seeded sample's regular shares move with each vote threshold and with the
    horizon (analysis.classify.share_sensitivity), one column per grid point: a share that
    holds under these is the orbits', not the thresholds'."""
    if "seed" not in axes or len(axes) != 2:
        return []
    rows = share_sensitivity(ds, th)
    point = next(a for a in axes if a != "seed")
    values = rows[0][1][point].values
    out = ["## Sensitivity of the regular share", "",
           "Each point's regular share decided again from the evidence the cells' runs "
           "stored (no orbit integrated again): with each threshold moved a quarter of the "
           "way towards its partner and as far away (in log10 for SALI), and at half each "
           "cell's horizon. In brackets, the change from the archived share in points (none: "
           "less than half a point).", "",
           "| decided with | " + " | ".join(f"{point} = {v:g}" for v in values) + " |",
           "| --- |" + " --- |" * values.size]
    base = rows[0][1].share.values
    for label, share in rows:
        cells = []
        for b, v in zip(base, share.share.values):
            moved = round(100 * (v - b)) if np.isfinite(v - b) else 0
            shift = f" ({moved:+d})" if moved else ""
            cells.append("—" if not np.isfinite(v) else f"{100 * v:.0f}%{shift}")
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    moved = np.array([[abs(s.share.values[i] - base[i]) for i in range(base.size)]
                      for _, s in rows[1:]])
    if moved.size and np.isfinite(moved).any():
        largest = round(100 * float(np.nanmax(moved)))
        out += ["", f"Largest change: {largest} point{'s' * (largest != 1)}."]
    return out + [""]


def _scale_free(ds, axes) -> list[str]:
    """For a potential homogeneous of degree k, what the energy axis means: the dynamics of
    a start depends on E and J only through E |J|^(-2k/(k+2))."""
    if V.scale_free_energy not in ds or not np.isfinite(ds[V.scale_free_energy].values).any():
        return []
    eps = ds[V.scale_free_energy].values
    line = (f"- Scale: the potential is homogeneous (degree k), so q -> s q, p -> s^(k/2) p, "
            f"t -> s^(1-k/2) t maps orbits to orbits: the energy shells (E, J) and (s^k E, "
            f"s^(1+k/2) J) have one phase portrait, rescaled, and a start's dynamics depends "
            f"on E and J only through E |J|^(-2k/(k+2)) and its place on that portrait "
            f"(`scale_free_energy`, here {np.nanmin(eps):.4g} to {np.nanmax(eps):.4g})")
    if "energy" in axes:
        line += ("; so the energy axis also stands for the starts' size (another size at "
                 "one energy gives no new orbits), and cells on one dashed line of the "
                 "regime map lie on shells with the same phase portrait (at different "
                 "starts)")
    return [line + "."]


def _horizons(ds, regime, steady, T) -> list[str]:
    """How far each verdict was checked: the horizons cells were decided at, and the cells
    whose verdict is not confirmed."""
    if V.regime_history not in ds:
        return []
    factors = ds["horizon_factor"].values
    final = ds[V.regime_horizon].values
    # cells decided by their evidence (an escaped or failed cell has none to check)
    started = np.isfinite(final) & np.isin(ds[V.status].values, [Status.OK, Status.EVENT])
    if not started.any():
        return []
    out = ["## Verdicts against a longer horizon", "",
           f"Each cell's regime is decided at T/2 and T = {T:g} from its run."]
    if factors.size > 2:
        out[-1] += (" A cell whose verdict changed class between them, or whose evidence did "
                    "not all vote for it (a line between its thresholds, or against it), was "
                    "integrated again from its start to a longer horizon and decided there"
                    f" (horizons up to {factors[-1]:g} T).")
    else:
        out[-1] += " No verdict was extended to a longer horizon ([tori] extend = 0)."
    out += ["", "| horizon | cells decided there | regular | irregular | confirmed |",
            "| --- | --- | --- | --- | --- |"]
    for f in factors[1:]:
        at = started & np.isclose(final, f * T)
        if at.any():
            out.append(f"| {f:g} T = {f * T:g} | {int(at.sum())} | "
                       f"{int(np.sum(at & np.isin(regime, REGULAR)))} | "
                       f"{int(np.sum(at & np.isin(regime, IRREGULAR)))} | "
                       f"{int(np.sum(at & steady))} |")
    doubt = np.isin(regime, REGULAR + IRREGULAR) & ~steady
    if doubt.any():
        labels = plots.cell_labels(ds)
        where = [labels[i] for i in np.flatnonzero(doubt.ravel())]
        shown = "; ".join(where[:12]) + (f"; and {len(where) - 12} more" if len(where) > 12
                                         else "")
        out += ["", f"Not confirmed ({int(doubt.sum())}): {shown}. Their regime holds to its "
                    "horizon; the horizon before decided another class."]
    return out + [""]


def _ensembles(ds, regime) -> list[str]:
    """How far the indicators of nearby orbits spread: per regime, the cells' median FTLE
    and <Y> and the median over cells of their ensembles' sd and 5-95% range."""
    if V.ftle_ensemble not in ds or V.ensemble_orbits not in ds:
        return []
    config = stored_config(ds)
    size = config["indicators"]["perturbation_size"]
    orbits = ds[V.ensemble_orbits].values
    finished = orbits > 0
    if not finished.any():
        return []
    n = int(np.max(orbits[finished]))
    stats = list(ds["ensemble_statistic_name"].values.astype(str))
    out = ["## Spread over nearby orbits", "",
           f"Each cell's FTLE and <Y> are its own orbit's. Their spread comes from an ensemble "
           f"of {n} orbit{'s' * (n != 1)} per cell: the cell's and {n - 1} started {size:g} "
           "(relative) away, each with its own deviation vector; the deviation vectors of one "
           "orbit agree to ~1e-4 and are not a spread."]
    if n == 1:
        return out[:2] + ["Each cell integrated its own orbit only ([indicators] perturbations "
                          "= 0): no spread over nearby orbits was measured.", ""]
    if n < ENSEMBLE_MIN:
        out.append(f"**With {n} orbits per cell these spreads are indicative only** (fewer "
                   f"than {ENSEMBLE_MIN}; [indicators] perturbations sets it).")
    megno = V.megno_ensemble in ds and V.megno in ds      # ([indicators] which may omit it)
    out += ["", "| regime | cells | median FTLE | median sd | median 5-95% range |"
            + (" median <Y> | its median 5-95% range |" if megno else ""),
            "| --- " * (7 if megno else 5) + "|"]
    f = ds[V.ftle_ensemble].values
    q05, q95, sd = stats.index("q05"), stats.index("q95"), stats.index("sd")
    for r in Regime:
        cells = finished & (regime == r)
        if not cells.any():
            continue
        med = lambda x: float(np.nanmedian(x[cells])) if np.isfinite(x[cells]).any() \
            else np.nan
        row = (f"| {r.name.lower()} | {int(cells.sum())} | {med(ds[V.ftle].values):.3g} | "
               f"{med(f[..., sd]):.2g} | {med(f[..., q95] - f[..., q05]):.2g} |")
        if megno:
            m = ds[V.megno_ensemble].values
            row += f" {med(ds[V.megno].values):.3g} | {med(m[..., q95] - m[..., q05]):.2g} |"
        out.append(row)
    horizon = ds[V.regime_horizon].values if V.regime_horizon in ds else \
        np.full(regime.shape, float(config["integration"]["t_final"]))
    found = decorrelated(ds[V.ftle].values, horizon, size,
                         finished & np.isin(regime, IRREGULAR))
    return out + ["", f"{found.text()}.", ""]


def _why_no_onset(ds, axis) -> str:
    """Why an onset along `axis` would mean nothing ("" if it means something)."""
    if axis == "seed":
        return "the cells are seeded random starts, in no order"
    if axis in START_COORDINATES:
        return (f"{axis} is a coordinate of the starts on one energy shell, not a parameter "
                "of a family of orbits: regular and chaotic cells interleave there")
    if "term" in ds[axis].attrs.get("long_name", ""):
        return (f"{axis} is a parameter of the potential: each value is another system, "
                "compared at " + (f"{ds.sizes['seed']} seeded starts each" if "seed" in ds.dims
                                  else "one start each"))
    return ""


def _onsets(ds, axes, regime, checks=None, th=None) -> list[str]:
    out = []
    checks = checks or {}
    check = checks.get("seed")
    meaningful = [a for a in axes if not _why_no_onset(ds, a)]
    skipped = [f"No onset is given along {a}: {_why_no_onset(ds, a)}." for a in axes
               if a not in meaningful]
    if len(axes) == 2 and meaningful and meaningful[0] != axes[0]:
        axes, regime = axes[::-1], regime.T          # the onset along the meaningful axis
    if "seed" in axes:           # seeded starts: their shares above say it
        return skipped + [""]
    if len(axes) == 1 and not meaningful:
        x = ds[axes[0]].values
        return [f"## Regimes along {axes[0]}", ""] + [
            f"- {axes[0]} = {x[i]:g}" + (f" to {x[j]:g}" if j > i else "") +
            f": {Regime(regime[i]).name.lower()} ({j - i + 1} cell{'s' * (j > i)})"
            for i, j in runs(regime)] + ["", *skipped, ""]
    if len(axes) == 2 and not meaningful:
        return ["## Where chaos sets in", "", *skipped, ""]
    if len(axes) == 2 and not np.isin(regime, REGULAR + IRREGULAR).any():
        return ["## Where chaos sets in", "", "No cell is regular or irregular (see the "
                "regimes above): there is no onset.", ""]
    if skipped:
        out += ["## Axes without an onset", "", *skipped, ""]
    if len(axes) == 1:
        x = ds[axes[0]].values
        out += [f"## Regimes along {axes[0]}", ""] + [
            f"- {axes[0]} = {x[i]:g}" + (f" to {x[j]:g}" if j > i else "") +
            f": {Regime(regime[i]).name.lower()} ({j - i + 1} cell{'s' * (j > i)})"
            for i, j in runs(regime)] + [""]
        found = onset(x, regime)
        out += ["## Where chaos sets in", ""]
        if found is None:
            out.append(f"The regime does not change from regular to chaotic along {axes[0]}.")
        else:
            out.append(f"Along {axes[0]} the orbits are regular up to {found['last_regular']:g}; "
                       f"the first irregular cell is at {found['first_irregular']:g}.")
            out += _onset_budget(ds, x, regime, found, axes[0], checks, th)
            if found["all_irregular_from"] is not None:
                out.append(_irregular_from(x, regime, found, axes[0]))
        out.append("")
    elif len(axes) == 2:
        a, b = axes
        seed = "" if check is None else f" (seed {_seed(check)})"
        out += [f"## Where chaos sets in along {a}, for each {b}", "",
                f"| {b} | regular cells | irregular cells | onset along {a} |"
                + (f" the same{seed} |" if check is not None else ""),
                "| --- | --- | --- | --- |" + (" --- |" if check is not None else "")]
        theirs = {} if check is None else dict(_lines(check, a, b))
        ds = ds.assign({V.regime: ((a, b) if a in ds.dims else ("cell",), regime)})
        for yb, line in _lines(ds, a, b):
            col = line[V.regime].values
            where = ["none" if found is None else
                     plus_minus(found['estimate'], found['error'])
                     for found in [_onset_1d(other, other[a].values) for other in
                                   [line] + ([theirs[yb]] if yb in theirs else [])]]
            if check is not None and yb not in theirs:
                where.append("—")
            out.append(f"| {yb:g} | {int(np.isin(col, REGULAR).sum())} | "
                       f"{int(np.isin(col, IRREGULAR).sum())} | {' | '.join(where)} |")
        step = "half the grid step" if "level" not in ds.coords else \
            "half the interval between neighbouring cells"
        out += ["", f"Each onset's uncertainty: {step}, or its shift over the last step of the "
                    "horizon of the verdicts, whichever is larger." if V.regime_history in ds
                else f"Each onset's uncertainty: {step}.", ""]
        if "level" in ds.coords:
            out[-2] += (f" Rows of the refined map at the grid's values of {b} only (the "
                        "others hold cells near a boundary alone).")
    return out


def _islands(axes, regime) -> list[str]:
    """A map's regular regions that the grid encloses (analysis.findings.islands): the
    only ones a report calls islands. Not along seeded starts, which have no order."""
    if len(axes) != 2 or "seed" in axes or regime.ndim != 2:
        return []
    return ["## Regular islands", "", islands(regime).text() + ".", ""]


def plus_minus(x: float, error: float) -> str:
    """'4.175 +- 0.025': a value with its uncertainty, to 4 digits or as many as the
    uncertainty needs (a bisection's 4.17312 +- 0.00062)."""
    digits = 4
    if x != 0 and error > 0 and np.isfinite(error):
        digits = max(4, int(np.floor(np.log10(abs(x)))) - int(np.floor(np.log10(error))) + 2)
    return f"{x:.{digits}g} +- {error:.2g}"


def _seed(ds) -> int:
    config = stored_config(ds)
    return int(config["indicators"]["seed"])


def _lines(ds, a, b):
    """(value of b, the cells at it as a Dataset along a) for each value of b: a map's
    rows; of a refined map only those at the grid's values of b (holding cells of level
    0), with every cell the refinement put there."""
    if b in ds.dims:
        return [(float(y), ds.isel({b: j})) for j, y in enumerate(ds[b].values)]
    out = []
    for y in np.unique(ds[b].values):
        row = ds.isel(cell=np.flatnonzero(ds[b].values == y))
        if (row["level"].values == 0).any():
            out.append((float(y), row.sortby(a).swap_dims({"cell": a})))
    return out


def _onset_1d(ds, x):
    """The onset along the one axis of an archive, over its horizons where stored."""
    regime = ds[V.regime].values
    if V.regime_history not in ds:
        return onset(x, regime)
    return onset_over_horizons(x, regime, ds[V.regime_history].values,
                               [float(f) for f in ds["horizon_factor"].values])


def onset_budget(ds, axis, checks, regime=None):
    """The Budget (analysis.onset.budget) of the onset along a one-axis archive: the step,
    the shift from the verdicts at the horizon before the last (where cells in doubt were
    decided again longer), and each [check] run's shift (`checks`: archives by variant).
    None where the regime does not change from regular to chaotic. `regime`: the cells'
    regimes where the caller has them, else the archive's."""
    found = onset(ds[axis].values, ds[V.regime].values if regime is None else regime)
    if found is None:
        return None
    others = {k: _onset_1d(c, c[axis].values) for k, c in checks.items()}
    if V.regime_history in ds:
        by = _onset_1d(ds, ds[axis].values)["by_horizon"]
        if len(by) > 1 and by[-2][1] is not None:
            others = {"extension": {"estimate": by[-2][1]}, **others}
    return budget(found, others)


def _onset_budget(ds, x, regime, found, axis, checks, th) -> list[str]:
    """The onset with its uncertainty contribution by contribution (analysis.onset.budget):
    the step the grid or bisection left, and each [check] variant's shift; the cells on
    either side of it whose votes lie near a threshold; how it moved over the horizons of
    the verdicts."""
    out = []
    if V.regime_history in ds:
        over = _onset_1d(ds, x)
        T = float(ds[V.regime_horizon].min())
        out.append("The onset from each cell's verdict at each of its horizons: " + "; ".join(
            f"at {f:g} T = {f * T:g}: " + ("none" if e is None else f"{e:.6g}")
            for f, e in over["by_horizon"]) + ".")
    b = onset_budget(ds, axis, checks, regime)
    step = ("half the interval the bisection ended with" if "level" in ds.coords
            else "half the grid step")
    what = {"step": step, "extension": "the verdicts at the horizon before the last "
                                       "(cells in doubt were decided again longer)",
            **{k: _change(k, c) for k, c in checks.items()}}
    out += ["", "| contribution | onset | shift |", "| --- | --- | --- |"]
    for name, size, there in b.parts:
        at = "—" if name == "step" else "none" if there is None else f"{there:.6g}"
        out.append(f"| {what[name]} | {at} | "
                   f"{'no onset' if not np.isfinite(size) else f'{size:.2g}'} |")
    if np.isfinite(b.total):
        out += ["", f"Onset {axis} = {plus_minus(b.estimate, b.total)} (the root sum of squares "
                    "of the contributions above)."]
    else:
        lost = [what[n] for n, size, _ in b.parts if not np.isfinite(size)]
        out += ["", f"Onset {axis} = {b.estimate:.6g} is **not established**: with "
                    f"{' and with '.join(lost)} the regime does not change from regular to "
                    f"chaotic along {axis}."]
    missing = [f"{k} ({v})" for k, v in defaults.CHECK_VARIANTS.items() if k not in checks]
    if missing:
        out.append("Not measured, so not in this uncertainty: " + "; ".join(missing)
                   + " -- [check] variants would measure them.")
    if th is not None:
        out += _near_thresholds(ds, x, [found["last_regular"], found["first_irregular"]],
                                axis, th)
    return out


def _irregular_from(x, regime, found, axis) -> str:
    """From where on every cell is irregular, with the count, and what lies between the
    first irregular cell and there: the regular runs bounded by other regimes on both
    sides (islands along the axis), and the other cells by regime."""
    tail = x >= found["all_irregular_from"]
    text = (f"From {axis} = {found['all_irregular_from']:g} on, "
            f"{how_many(int(np.isin(regime[tail], IRREGULAR).sum()), int(tail.sum()))} cells "
            "are irregular.")
    between = (x > found["first_irregular"]) & (x < found["all_irregular_from"])
    if between.any():
        runs_inside = regions(between & np.isin(regime, REGULAR))
        others = ", ".join(f"{int(np.sum(between & (regime == r)))} {r.name.lower()}"
                           for r in Regime if r not in REGULAR and
                           np.any(between & (regime == r)))
        text += f" Between {found['first_irregular']:g} and {found['all_irregular_from']:g}: "
        text += (f"{len(runs_inside)} run{'s' * (len(runs_inside) != 1)} of regular cells "
                 f"({int(np.sum(between & np.isin(regime, REGULAR)))} cells), each bounded "
                 f"by other regimes on both sides -- islands along {axis} -- and {others}."
                 if runs_inside else f"no regular cell; {others}.")
    return text


NEAR = 0.1      # a vote this close to its threshold (relative) is named beside an onset


def _change(variant: str, check) -> str:
    """A [check] run's change, from the config its archive stores."""
    config = stored_config(check)
    return defaults.check_change(variant, config["indicators"], config["integration"])


def _near_thresholds(ds, x, where, axis, th) -> list[str]:
    """The cells at `where` whose votes lie within NEAR (relative) of a threshold: their
    verdict would change with a small change of their evidence."""
    margins = threshold_margins(ds, th)
    out = []
    for value in where:
        i = int(np.argmin(np.abs(x - value)))
        close = [f"{k} ({margins[k][i]:.2g})" for k in margins if margins[k][i] < NEAR]
        if close:
            out.append(f"The cell at {axis} = {value:g} votes within {NEAR:g} (relative) of "
                       f"a threshold: {', '.join(close)}.")
    return [" ".join(out)] if out else []


def _second_run(ds, check, regime) -> list[str]:
    """The survey's claims beside those of its [check] run (another seed and ensemble
    size): the regime counts, the cells whose verdict changed class, the spreads."""
    if check is None:
        return []
    shared = ""
    axes = list(ds[V.status].dims)
    if "level" in ds.coords and "level" in check.coords and len(axes) == 1:
        a = axes[0]
        common = np.intersect1d(ds[a].values, check[a].values)
        shared = (f" Each run refined the grid by its own verdicts: they share {common.size} "
                  f"of their {ds.sizes[a]} and {check.sizes[a]} cells, compared here.")
        ds, check = ds.sel({a: common}), check.sel({a: common})
        regime = ds[V.regime].values
    elif check[V.regime].shape != regime.shape:
        return ["## The same survey with another seed and ensemble", "",
                "The [check] archive has another grid: nothing is compared.", ""]
    orbits = [int(np.max(x[V.ensemble_orbits].values, initial=0)) if V.ensemble_orbits in x
              else 1 for x in (ds, check)]
    other = check[V.regime].values
    nudge = float(stored_config(check)["indicators"]["nudge"])
    nominal = (f", and each cell's nominal orbit started {nudge:g} (relative) away -- other "
               "last bits, so that every line of evidence can move, the Birkhoff digits and "
               "frequencies too" if nudge else ", the same nominal orbits (only the deviation "
               "vectors and the ensemble differ: the Birkhoff digits and frequencies cannot "
               "move)")
    out = ["## The same survey with another seed and ensemble", "",
           f"Every cell run again with seed {_seed(check)} (here {_seed(ds)}) and {orbits[1]} "
           f"orbits per cell (here {orbits[0]}): its own deviation vectors and perturbed "
           f"starts{nominal}; the same {'base ' if shared else ''}grid, thresholds and "
           "horizons." + shared, "",
           "| regime | cells here | cells there |", "| --- | --- | --- |"]
    for r in Regime:
        a, b = int(np.sum(regime == r)), int(np.sum(other == r))
        if a or b:
            out.append(f"| {r.name.lower()} | {a} | {b} |")

    def kind(x):
        return np.where(np.isin(x, REGULAR), 1, np.where(np.isin(x, IRREGULAR), -1, 0))
    moved = kind(regime) != kind(other)
    labels = plots.cell_labels(ds)
    where = [labels[i] + f" ({Regime(regime.ravel()[i]).name.lower()} -> "
                         f"{Regime(other.ravel()[i]).name.lower()})"
             for i in np.flatnonzero(moved.ravel())]
    out += ["", f"Verdicts of another class (regular, irregular, undetermined) with the other "
                f"seed: {int(moved.sum())} of {regime.size} cells" + (
                    ": " + "; ".join(where[:12]) + ("; ..." if len(where) > 12 else "") + "."
                    if where else ".")]
    if min(orbits) > 1 and V.ftle_ensemble in ds and V.ftle_ensemble in check:
        sd = list(ds["ensemble_statistic_name"].values.astype(str)).index("sd")
        rows = []
        for r in Regime:
            cells = (regime == r) & (other == r) & (ds[V.ensemble_orbits].values > 1) & \
                (check[V.ensemble_orbits].values > 1)
            if cells.any():
                here = float(np.nanmedian(ds[V.ftle_ensemble].values[..., sd][cells]))
                there = float(np.nanmedian(check[V.ftle_ensemble].values[..., sd][cells]))
                rows.append(f"| {r.name.lower()} | {int(cells.sum())} | {here:.2g} | "
                            f"{there:.2g} |")
        if rows:
            out += ["", f"The FTLE's spread over nearby orbits ({orbits[0]} and {orbits[1]} "
                        "orbits per cell), in the cells of the same regime in both runs:", "",
                    "| regime | cells | median sd here | median sd there |",
                    "| --- | --- | --- | --- |", *rows]
    return out + [""]


def _tori_table(ds, axes, regime, rows: int = 15) -> list[str]:
    if V.frequency not in ds:
        return []
    cells = np.flatnonzero(np.isin(regime.ravel(), REGULAR))
    if not cells.size:
        return ["## Tori", "", "No regular cell.", ""]
    names = [str(v) for v in ds["fundamental_name"].values]
    raw = ds[V.frequency].values.reshape(-1, len(names))
    freq = ds[V.frequency_labelled].values.reshape(-1, len(names)) \
        if V.frequency_labelled in ds else raw
    m = _relabel(ds[V.resonance].values.reshape(-1, len(names)), raw, freq)
    dist = ds[V.resonance_distance].values.ravel()
    digits = ds[V.birkhoff_digits].values.ravel()
    coords = plots.cell_labels(ds)
    pick = cells if cells.size <= rows else cells[np.linspace(0, cells.size - 1, rows).astype(int)]
    out = ["## Tori found", "",
           f"{cells.size} regular cells; {'all' if cells.size <= rows else f'{rows} evenly chosen'} "
           "shown. Frequencies in cycles per unit time, magnitudes: the shape frequencies "
           "labelled across the grid (a column follows one frequency from cell to cell), "
           "then the rotation, which is a phase of the reconstruction and takes part in no "
           "resonance; the nearest resonance m . nu = 0 among the shape frequencies and its "
           "relative distance.", "",
           f"| cell | regime | digits | {' | '.join(names)} | nearest resonance m | distance |",
           "| --- | --- | --- | " + " | ".join("---" for _ in names) + " | --- | --- |"]
    for c in pick:
        f = " | ".join("—" if not np.isfinite(v) else f"{abs(v):.7f}" for v in freq[c])
        near = (f"{tuple(int(v) for v in m[c])} | {dist[c]:.1e}" if np.isfinite(dist[c])
                else "— (fewer than two shape frequencies) | —")
        out.append(f"| {coords[c]} | {Regime(regime.ravel()[c]).name.lower()} | "
                   f"{digits[c]:.1f} | {f} | {near} |")
    out.append("")
    if len(axes) == 1:
        # each cell's largest drift, for every column: the labelling permutes the columns
        drift = np.nanmax(np.abs(ds[V.frequency_change].values.reshape(-1, len(names))),
                          axis=1, initial=0.0) if V.frequency_change in ds else \
            np.zeros(len(freq))
        found = twists(ds[axes[0]].values, freq, np.repeat(drift[:, None], len(names), 1),
                       regime.ravel(), axes[0], names)
        if len(found) == 1 and found[0].key == f"twist.{axes[0]}":      # no order
            out += [f"{found[0].text()}.", ""]
        elif found:
            out += [f"Twist along {axes[0]} ({found[0].test}):", ""] + \
                [f"- {f.text()}." for f in found] + [""]
    return out


def _special(ds, special, regime) -> list[str]:
    """The special solutions the family's cells start on: relative equilibria at its
    equilibrium cells with their normal modes, beside the labelled shape frequencies of the
    nearest regular cell along a single axis (where the family's tori start); relative
    periodic orbits at its homographic cells with the rate nearby orbits leave them, beside
    the cell's FTLE."""
    if not special:
        return []
    out = ["## Special solutions in this family", ""]
    equilibria = [s for s in special if s["kind"] == "equilibrium"]
    periodic = [s for s in special if s["kind"] == "periodic"]
    if equilibria:
        out.append("Each equilibrium cell solved again as a relative equilibrium at its J "
                   "(`python -m survey equilibria`): its stability in the reduced space and "
                   "its normal modes in the rotating frame (cycles per unit time; Krein "
                   "sign).")
    axes = plots.map_axes(ds)
    for s in equilibria:
        modes = ", ".join(f"{f:.6g} ({'+' if k > 0 else '-'})"
                          for f, k in zip(s["frequencies"], s["krein"])) or "none"
        line = (f"- {s['cell']}: rotating at Omega = {s['rotation_rate']:.6g}, "
                + ("linearly stable" if s["stable"] else "unstable (growth rates "
                   + ", ".join(f"{r:.4g}" for r in s["rates"]) + ")")
                + f"; normal modes {modes}")
        if len(axes) == 1 and V.frequency_labelled in ds:
            names = [str(n) for n in ds["fundamental_name"].values]
            shape = [c for c, n in enumerate(names) if n.startswith("shape")]
            nu_all = np.abs(ds[V.frequency_labelled].values[:, shape])
            regular = np.flatnonzero(np.isin(regime, REGULAR)
                                     & np.all(np.isfinite(nu_all), axis=1))
            if regular.size:
                near = regular[np.argmin(np.abs(regular - s["index"][0]))]
                nu = nu_all[near]
                line += (f". The nearest regular cell, {axes[0]} = "
                         f"{float(ds[axes[0]].values[near]):g}, has shape frequencies "
                         + ", ".join(f"{v:.6g}" for v in sorted(nu)))
        out.append(line + ".")
    if periodic:
        out += ([""] if equilibria else []) + [
            "Each homographic cell (its triangle keeps its shape while it breathes and "
            "turns) shot as a relative periodic orbit at its energy (`python -m survey "
            "periodic`): its multipliers say how fast nearby orbits leave it; the cell's "
            "FTLE, measured over the whole run, is that of the sea its orbit joins once "
            "it has left."]
    for s in periodic:
        rates = sorted({float(f"{r:.4g}") for r in s["rates"]}, reverse=True)  # a quartet: one
        out.append(f"- {s['cell']}: period {s['period']:.6g}, turning {s['rotation']:.6g} "
                   f"rad, {s['orbit_kind']}" + (", linearly stable" if s["stable"] else
                                                 ": nearby orbits leave at " + ", ".join(
                                                     f"{r:.4g}" for r in rates)
                                                 + " per unit time")
                   + (f"; the cell's FTLE {s[V.ftle]:.3g}." if np.isfinite(s[V.ftle]) else
                      "; the cell has no FTLE (its run did not finish)."))
    return out + [""]


def _relabel(m, raw, labelled):
    """The resonance vectors m (cells, fundamental) in the labelled columns' order."""
    out = m.copy()
    for c in range(m.shape[0]):
        for j in range(m.shape[1]):
            same = np.flatnonzero(raw[c] == labelled[c, j])
            if same.size and np.isfinite(labelled[c, j]):
                out[c, j] = m[c, same[0]]
    return out


def _agreement(ds, th) -> list[str]:
    votes = evidence_votes(ds, th)
    keys = list(votes)
    if len(keys) < 2 or not any(np.any(np.abs(v) == 1) for v in votes.values()):
        return []       # (no cell was decided: every one escaped, say)
    out = ["## Where the indicators agree", "",
           "Share of the cells where both lines of evidence vote (regular or chaotic) in "
           "which they vote the same way; in brackets, how many cells both voted in.", "",
           "| | " + " | ".join(keys) + " |", "| --- |" + " --- |" * len(keys)]
    for a in keys:
        row = []
        for b in keys:
            both = (np.abs(votes[a]) == 1) & (np.abs(votes[b]) == 1)
            k = int(both.sum())
            row.append("—" if not k else f"{100 * np.mean(votes[a][both] == votes[b][both]):.0f}% ({k})")
        out.append(f"| **{a}** | " + " | ".join(row) + " |")
    mixed = sum(int(np.sum((votes[a] * votes[b]) == -1)) for i, a in enumerate(keys)
                for b in keys[i + 1:])
    out += ["", f"Pairs of opposite votes in all: {mixed}. A cell with opposite votes is "
                "never called torus or chaotic: it is sticky (regular first, chaotic by T) "
                "or undetermined.", ""]
    return out


def _thresholds(th) -> list[str]:
    from dataclasses import fields
    out = ["## Thresholds used, and why", "", "| threshold | value | why |",
           "| --- | --- | --- |"]
    for f in fields(th):
        out.append(f"| {f.name} | {getattr(th, f.name):g} | "
                   f"{f.metadata['doc'].replace('|', chr(92) + '|')} |")
    out += ["", "Each line of evidence votes regular, chaotic or not at all; tori and chaos "
                "need every vote cast to agree (survey.analysis.classify).", ""]
    return out


def _escapes(ds) -> list[str]:
    """How many started cells escaped, when, and through which exit (a share of the
    started cells with its 95% Wilson interval where the cells are a seeded sample)."""
    if V.escape_time not in ds:
        return []
    status = ds[V.status].values
    started = status != Status.INACCESSIBLE
    escaped = status == Status.ESCAPED
    n, k = int(started.sum()), int(escaped.sum())
    attrs = ds[V.escape_time].attrs
    out = ["## Escapes", "",
           "A body escapes when its distance from "
           + ("the origin" if in_field(ds) else "the others' centre of mass")
           + f" rises through {attrs.get('escape_radius', float('nan')):.4g}"
           + (f" with the kinetic energy of their relative motion above "
              f"{attrs['escape_binding']:.3g}" if attrs.get("escape_binding") else "")
           + "; the cell stops there and gets no regular or chaotic verdict.", ""]
    threshold = json.loads(ds.attrs.get("dissociation_energy", "null"))
    if threshold is not None:
        out += [f"Dissociation energy {threshold:.6g}: the least potential energy of the "
                "others with one body gone, as a descent from the first start finds it; "
                "below it no body can leave.", ""]
    if not k:
        return out + [f"None of the {n} started cells escaped by its horizon.", ""]
    t = ds[V.escape_time].values[escaped]
    q = np.quantile(t, [0.0, 0.25, 0.5, 0.75, 1.0])
    out.append(f"{k} of {n} started cells escaped ({100 * k / n:.1f}%); escape time median "
               f"{q[2]:.3g} (quartiles {q[1]:.3g}-{q[3]:.3g}, range {q[0]:.3g}-{q[4]:.3g}); "
               f"the other {n - k} stayed to their horizon.")
    exits = (stored_table(ds, "outcomes") or {}).get("exits") or []
    if exits and V.escape_exit in ds:
        where = ds[V.escape_exit].values[escaped]
        low, high = wilson([int(np.sum(where == e)) for e in range(len(exits))],
                           [n] * len(exits))
        out += ["", "| exit | direction | cells | share of the started cells | 95% interval "
                    "| median escape time |", "| --- | --- | --- | --- | --- | --- |"]
        for e, angle in enumerate(exits):
            c = int(np.sum(where == e))
            med = f"{np.median(t[where == e]):.3g}" if c else "—"
            out.append(f"| {e} | {angle:g}° | {c} | {100 * c / n:.1f}% | "
                       f"{100 * float(low[e]):.1f}-{100 * float(high[e]):.1f}% | {med} |")
        out.append("")
        out.append("The interval treats the cells as a random sample of the plane; on a "
                   "regular grid it says how far a share could move with the grid's "
                   "resolution, roughly.")
    if V.escaped_body in ds:
        bodies = ds[V.escaped_body].values[escaped]
        out.append("Bodies that escaped: " + ", ".join(
            f"body {b} in {int(np.sum(bodies == b))}" for b in np.unique(bodies)) + ".")
    return out + [""]


def _approaches(ds, regime) -> list[str]:
    """Close approaches and thin triangles by regime: whether the chaotic cells are those
    whose bodies came close, or spent their run in the channels of long thin triangles."""
    if V.closest_approach not in ds:
        return []
    started = ds[V.status].values != Status.INACCESSIBLE
    closest = ds[V.closest_approach].min("pair").broadcast_like(ds[V.status]).values
    thin = ds[V.thin_share].broadcast_like(ds[V.status]).values if V.thin_share in ds \
        else None
    out = ["## Close approaches" + (" and thin triangles" if thin is not None else ""), "",
           "Per regime, over its cells: the closest approach of any pair (up to the cell's "
           "end, at step ends)" + (", and the share of the run during which a triangle was "
                                   "thin (|A|/P^2 below [outcomes] thin times the "
                                   "equilateral's)" if thin is not None else "") + ".", "",
           "| regime | cells | closest approach: median | least | "
           + ("thin share: median | largest | cells thin over half the run |"
              if thin is not None else ""),
           "| --- | --- | --- | --- |" + (" --- | --- | --- |" if thin is not None else "")]
    for r in Regime:
        on = started & (regime == r)
        if not on.any():
            continue
        row = (f"| {r.name.lower()} | {int(on.sum())} | {np.median(closest[on]):.3g} | "
               f"{np.min(closest[on]):.3g} |")
        if thin is not None:
            row += (f" {np.median(thin[on]):.3g} | {np.max(thin[on]):.3g} | "
                    f"{int(np.sum(thin[on] > 0.5))} |")
        out.append(row)
    ftle = ds[V.ftle].values if V.ftle in ds else np.full(closest.shape, np.nan)
    drawn = np.isfinite(ftle) & (ftle > 0)
    if drawn.sum() >= RANKED_CELLS:
        against = [("the closest approach", closest)] + \
            ([("the thin share", thin)] if thin is not None else [])
        out += ["", f"Rank (Spearman) correlation of the FTLE, over the {int(drawn.sum())} "
                    "cells with a positive one: " + "; ".join(
                        f"with {name} {rank_correlation(ftle[drawn], x[drawn]):+.2f}"
                        for name, x in against) + ". The figure `approach` draws them."]
    return out + [""]


RANKED_CELLS = 10       # fewer cells than this: no rank correlation is given


def rank_correlation(a, b) -> float:
    """Spearman's rank correlation of a and b (the Pearson correlation of their ranks;
    ties, rare in these floats, ranked by order)."""
    ra, rb = (np.argsort(np.argsort(x, kind="stable")).astype(float) for x in (a, b))
    ra, rb = ra - ra.mean(), rb - rb.mean()
    return float(np.sum(ra * rb) / np.sqrt(np.sum(ra * ra) * np.sum(rb * rb)))


def _quality(ds) -> list[str]:
    status = ds[V.status].values
    out = ["## Conservation and failures", ""]
    finished = np.isin(status, [Status.OK, Status.EVENT, Status.ESCAPED])    # (to the end)
    if finished.any():
        dE = ds[V.energy_error].values[finished]
        spin = "" if in_field(ds) else (      # a field conserves no angular momentum
            f"; angular momentum error largest "
            f"{np.nanmax(ds[V.angular_momentum_error].values[finished]):.1e}")
        out.append(f"Relative energy error over the finished cells (escaped ones to their "
                   f"escape): median {np.median(dE):.1e}, "
                   f"largest {np.max(dE):.1e}{spin}.")
    failed = [(s, int(np.sum(status == s))) for s in Status
              if s not in (Status.OK, Status.EVENT, Status.ESCAPED)]
    failed = [(s, k) for s, k in failed if k]
    if failed:
        out.append("")
        out += [f"- {k} cell{'s' * (k != 1)} {s.name.lower()}: {s.meaning}" for s, k in failed]
    else:
        out.append("No cell failed.")
    out.append("")
    return out
