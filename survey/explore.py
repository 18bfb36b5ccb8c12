"""The explorer (`python -m survey explore ARCHIVE`): a survey archive's maps (or its scan,
or the section of its one energy shell), or a family archive's diagram, in a browser, each cell's parameters and evidence
under the pointer; a click integrates that cell's orbit with survey's own kernels -- the
`orbit` command's run, so the same numbers -- and draws its paths, its section crossings
and its indicators' convergence beside the archive's frequencies, with the config and the
command that reproduce it. Served by Bokeh on 127.0.0.1 (docs/guide/explorer.md says why
Bokeh: the tornado server it runs on is dask's own, and a map is sent as one raster).

`CellView` and `FamilyView` hold what a page shows and computes -- no Bokeh -- so that the
numbers a page prints are tested without a browser; `document` and `family_document` lay
them out; `serve` runs the server."""
from __future__ import annotations

import socket
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from .catalog.errors import ArchiveError, ConfigError, SurveyError
from .catalog.families import EQUILIBRIA, PERIODIC
from .catalog.indicators import REGISTRY
from .catalog.regimes import Regime
from .catalog.status import Status
from .catalog.variables import V, label
from .machine import linalg
from .numerics.integrate import integrate
from .numerics.periodic import rotation
from .physics.jacobi import reduced
from .pipeline import archive, orbits
from .pipeline.config import _to_toml, load_config, parse_config
from .pipeline.families import family_systems, is_family
from .presentation.sections import SLAB, section_axes, shells
from .presentation.style import REGIME_COLOURS

# a turning wheel before a busy line (its style in the line: each Bokeh Div is a shadow root)
SPINNER = ("<style>.spin{display:inline-block;animation:spin 1s linear infinite}"
           "@keyframes spin{to{transform:rotate(360deg)}}</style><span class='spin'>&#9696;"
           "</span> ")
HOST = "127.0.0.1"
PORT = 5006              # Bokeh's own default
DRAWN = 4001             # orbit samples drawn (the orbit's run samples it more densely)
# the evidence a pointer over a cell shows, where the archive holds it
HOVERED = (V.regime_confidence, V.regime_horizon, V.megno, V.ftle, V.fli, V.birkhoff_digits,
           "regular_share")


class Layer(NamedTuple):
    """A map's colouring: a variable per cell, the colours (a matplotlib colour map's, or
    the regimes' own) and the range they span."""

    name: str
    values: np.ndarray       # flat, per cell
    palette: tuple
    low: float
    high: float
    log: bool = False


class CellOrbit(NamedTuple):
    """A clicked cell's orbit as the page draws it."""

    cell: int
    lines: list              # what `survey orbit ... --cell K` prints for it
    t: np.ndarray            # sample times drawn
    positions: np.ndarray    # (samples, N, d)
    megno: np.ndarray        # MEGNO <Y>(t) at those times
    ftle: np.ndarray         # ln(|w|/|w0|) / t
    crossings: tuple         # (x, y, x name, y name): its section crossings, or ()
    frequencies: list        # (name, value) of the archive's labelled frequencies


def _palette(cmap: str, n: int = 256) -> tuple:
    from matplotlib import colormaps
    from matplotlib.colors import to_hex
    return tuple(to_hex(c) for c in colormaps[cmap](np.linspace(0.0, 1.0, n)))


@dataclass
class CellView:
    """A survey archive as the explorer shows it: the grid's axes, the layers a map can
    colour by, each cell's description, and a cell's orbit on demand."""

    path: Path
    ds: object               # the archive, read (but its convergence histories)
    config: object           # its stored config

    @classmethod
    def open(cls, path) -> "CellView":
        """The archive at `path`; ArchiveError saying what is wrong with any other file."""
        path = Path(path)
        with archive.open_archive(path) as ds:
            if "family" in ds.attrs:
                raise ArchiveError(f"{path}: a family archive ({ds.attrs['family']}): "
                                   "FamilyView shows it")
            # read now, the convergence histories left (the bulk of a large archive, and
            # not drawn): HDF5 is not to be read from the server's thread and another
            histories = [v for v in ds.data_vars if "history_time" in ds[v].dims]
            data = ds.drop_vars(histories).load()
        try:
            config = parse_config(data.attrs["config"], f"{path} (stored config)",
                                  check_output=False)
        except ConfigError as exc:
            raise ArchiveError(f"{path}: its stored config is not valid ({exc})") from None
        if config.refined:
            raise ArchiveError(f"{path}: a refined survey (its cells lie on a lattice, not "
                               "a grid); the explorer shows grid archives")
        if len(config.axes) > 2:
            raise ArchiveError(f"{path}: a grid of {len(config.axes)} axes; the explorer "
                               "draws grids of one or two (plot draws the others' maps)")
        return cls(path, data, config)

    # ---- the grid
    @property
    def axes(self) -> list[str]:
        return list(self.ds[V.status].dims)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.ds[V.status].shape

    def axis_values(self, name) -> np.ndarray:
        return self.ds[name].values.astype(float)

    def flat(self, name) -> np.ndarray:
        """A variable per cell, flat in the grid's order (computed once)."""
        cache = self.__dict__.setdefault("_flat", {})
        if name not in cache:
            status = self.ds[V.status]
            cache[name] = self.ds[name].broadcast_like(status).transpose(
                *status.dims).values.ravel()
        return cache[name]

    def hover_columns(self) -> dict[str, np.ndarray]:
        """What the pointer over each cell shows -- its grid values, index, regime and
        status (by name) and the evidence the archive holds -- for every cell at once (what
        the page sends for its tooltips; computed once)."""
        if "_hover" in self.__dict__:
            return self.__dict__["_hover"]
        cells = np.arange(self.config.n_cells)
        at = np.unravel_index(cells, self.shape) if self.axes else ()
        out = {a: self.axis_values(a)[i] for a, i in zip(self.axes, at)}
        out["cell"] = cells
        for name, kind in ((V.regime, Regime), (V.status, Status)):
            names = {int(k): k.name.lower() for k in kind}
            out[name] = np.array([names[int(c)] for c in self.flat(name)])
        for name in HOVERED:
            if name in self.ds:
                out[name] = self.flat(name).astype(float)
        self.__dict__["_hover"] = out
        return out

    def layers(self) -> dict[str, Layer]:
        """The regime, then every indicator maps draw (the registry's colour maps and
        ranges), then the regular share where the archive holds it."""
        out = {V.regime: Layer(V.regime, self.flat(V.regime).astype(float),
                               tuple(REGIME_COLOURS[r] for r in Regime), -0.5,
                               len(Regime) - 0.5)}
        unfinished = self.flat(V.status) != int(Status.OK)
        for ind in REGISTRY:
            if ind.map is None or ind.headline not in self.ds:
                continue
            v = np.where(unfinished, np.nan, self.flat(ind.headline).astype(float))
            finite = v[np.isfinite(v) & ((v > 0) if ind.map.log else True)]
            lo, hi = ind.map.clip or ((finite.min(), finite.max()) if finite.size else (0, 1))
            out[ind.headline] = Layer(ind.headline, v, _palette(ind.map.cmap), float(lo),
                                      float(hi), ind.map.log)
        if "regular_share" in self.ds:
            out["regular_share"] = Layer("regular_share", self.flat("regular_share"),
                                         _palette("viridis"), 0.0, 1.0)
        return out

    def describe(self, cell: int) -> dict[str, str]:
        """What the pointer over a cell shows (`hover_columns`), as text."""
        return {k: f"{v[cell]:.6g}" if k in self.axes else
                f"{v[cell]:.4g}" if v.dtype.kind == "f" else str(v[cell])
                for k, v in self.hover_columns().items()}

    # ---- one-shell sections
    def shell_crossings(self):
        """(x, y, regime per point, x name, y name) of every crossing of a one-shell
        archive (a section is of one energy shell: `sections.shells`), or None."""
        names = section_axes(self.ds)
        if names is None or len(shells(self.ds)) != 1:
            return None
        x, y = (self.ds[f"crossing_{n}"].values.reshape(-1, self.ds.sizes["crossing"])
                for n in names)
        regime = np.repeat(self.flat(V.regime), x.shape[1]).reshape(x.shape)
        cell = np.repeat(np.arange(x.shape[0]), x.shape[1]).reshape(x.shape)
        keep = np.isfinite(x) & np.isfinite(y)
        return x[keep], y[keep], regime[keep], cell[keep], names

    def slice_points(self):
        """(sigma, p_sigma, eta, cell, regime, slab text) of the crossings of a one-shell
        archive of three bodies in the plane in the 3-D slice |p_eta| <= SLAB (its range)
        of the 4-D section -- where a torus draws closed curves, as in the report's figure
        (`sections.section_slice`) -- or None."""
        if V.crossing_sigma not in self.ds or len(shells(self.ds)) != 1:
            return None
        k = self.ds.sizes["crossing"]
        cols = [self.ds[f"crossing_{n}"].values.reshape(-1, k)
                for n in ("sigma", "p_sigma", "eta", "p_eta")]
        cell = np.repeat(np.arange(cols[0].shape[0]), k).reshape(cols[0].shape)
        width = SLAB * float(np.nanmax(cols[3]) - np.nanmin(cols[3]))
        keep = np.all([np.isfinite(c) for c in cols], axis=0) & (np.abs(cols[3]) <= width)
        if not keep.any():
            return None
        regime = self.flat(V.regime)[cell[keep]]
        text = f"|p_eta| <= {width:.3g}: {int(keep.sum())} crossings"
        return cols[0][keep], cols[1][keep], cols[2][keep], cell[keep], regime, text

    # ---- a cell's orbit
    @property
    def section(self):
        return orbits.section_of(self.config)

    def section_title(self) -> str:
        if self.section is None:
            return "no surface of section (the config has no [section])"
        return "crossings of " + orbits.section_text(self.section)

    def spec(self, cell: int, t_final: float | None = None) -> orbits.OrbitSpec:
        return orbits.from_config(self.config, [cell], t_final)

    def orbit(self, cell: int, t_final: float | None = None) -> CellOrbit:
        """Cell `cell`'s orbit as `python -m survey orbit CONFIG --cell K` runs it (the
        archive's stored config), with its section crossings."""
        if not 0 <= cell < self.config.n_cells:
            raise ConfigError("cell", f"{cell} is not a cell of the grid (0.."
                                      f"{self.config.n_cells - 1})")
        spec = self.spec(cell, t_final)
        runs = orbits.run_orbits(spec)
        if not runs:
            raise ConfigError("cell", f"cell {cell} has no start (inaccessible)")
        run = runs[0]
        out, system = run.outcome, run.system
        done = ~np.isnan(out.samples[:, 0])
        step = max(1, int(done.sum()) // (DRAWN - 1))
        t = out.t_eval[done][::step]
        s = out.samples[done][::step]
        q, _ = system.split(s[:, :system.n])
        with np.errstate(invalid="ignore", divide="ignore"):
            megno = out.sample_megno[done][::step, 1] / t
            ftle = out.sample_log_growth[done][::step, 0] / t
        return CellOrbit(cell, orbits.describe(spec, run), t, q, megno, ftle,
                         self._crossings(system, out.crossings.y), self._frequencies(cell))

    def section_names(self) -> tuple[str, str]:
        """The two coordinates crossings are drawn in (`sections.section_axes`; sigma,
        p_sigma for three bodies in the plane whatever the archive stored)."""
        system = self.config.system(0)
        if system.n_bodies == 3 and system.dim == 2:
            return "sigma", "p_sigma"
        return section_axes(self.ds) or ("x", "p_x")

    def _crossings(self, system, states):
        """The crossings in `section_names`' coordinates."""
        names = self.section_names()
        if self.section is None or not len(states):
            return ()
        if names[0] == "sigma":
            r = reduced(system, states)
            return r.sigma, r.p_sigma, *names
        axis = "xyz".index(names[0])
        return (system.centre_of_mass(states)[:, axis], system.momentum(states)[:, axis],
                *names)

    def _frequencies(self, cell: int) -> list:
        """(name, value) of the cell's labelled fundamental frequencies in the archive."""
        if V.frequency_labelled not in self.ds:
            return []
        at = np.unravel_index(cell, self.shape) if self.axes else ()
        rows = self.ds[V.frequency_labelled][at].values
        names = self.ds["fundamental_name"].values if "fundamental_name" in self.ds.coords \
            else [f"f{k}" for k in range(rows.size)]
        return [(str(n), float(f)) for n, f in zip(names, rows)]

    # ---- exports
    def export(self, cell: int) -> str:
        """A survey config of the one cell: the archive's stored config with [initial] the
        cell's start as an explicit family (its momenta exactly: `_velocities`), term
        parameters at the cell's values, no [check] or [refine]."""
        raw = tomllib.loads(self.config.text)
        for table in ("check", "refine"):
            raw.pop(table, None)
        axes = self.config.axes
        at = np.unravel_index(cell, self.config.shape) if axes else ()
        system = raw.setdefault("system", {})
        for axis, i in zip(axes, at):
            if axis.term >= 0:
                entry = system["interactions"][axis.term] if system.get("interactions") \
                    else system
                entry.setdefault("params", {})[axis.param] = float(axis.values[i])
        sys_ = self.config.system(cell)
        y0 = self.flat_state(cell)
        q, p = sys_.split(y0)
        v = _velocities(p, sys_.masses)
        where = ", ".join(f"{k} = {val}" for k, val in self.describe(cell).items()
                          if k in self.axes)
        raw["survey"] = {"name": f"{self.config.name}_cell_{cell}"}
        raw["initial"] = {"family": "explicit", "positions": q.tolist(),
                          "velocities": v.tolist()}
        head = (f"# cell {cell} of {self.path.name}" + (f" ({where})" if where else "")
                + ": its start, exported by python -m survey explore\n")
        return head + _to_toml(raw)

    def flat_state(self, cell: int) -> np.ndarray:
        v = self.ds[V.initial_state]
        at = np.unravel_index(cell, self.shape) if self.axes else ()
        return v[at].values.astype(float)

    def command(self, cell: int) -> str:
        """The `orbit` command that integrates the cell from its exported config."""
        return (f"python -m survey orbit {self.config.name}_cell_{cell}.toml"
                f" --plot {self.config.name}_cell_{cell}")


def _velocities(p, masses) -> np.ndarray:
    """Velocities v with masses * v == p in floating point where such a v exists (p / m,
    moved by an ulp where that does not round back; with unit masses p itself), so that
    an exported start is the archived one bit for bit."""
    m = np.broadcast_to(np.asarray(masses, dtype=float)[:, None], p.shape)
    v = p / m
    for idx in zip(*np.nonzero(m * v != p)):
        for cand in (np.nextafter(v[idx], np.inf), np.nextafter(v[idx], -np.inf)):
            if m[idx] * cand == p[idx]:
                v[idx] = cand
                break
    return v


@dataclass
class FamilyView:
    """A family archive (`periodic` or `equilibria --output`) as the explorer shows it: its
    diagram along the parameter, and a member's orbit on demand."""

    path: Path
    ds: object               # the archive, read
    system_at: Callable      # the parameter's value -> the member's System

    @classmethod
    def open(cls, path) -> "FamilyView":
        path = Path(path)
        with archive.open_archive(path) as ds:
            kind = ds.attrs.get("family")
            if kind not in (PERIODIC, EQUILIBRIA):
                raise ArchiveError(f"{path}: a {kind} archive; the explorer shows survey "
                                   "archives and families of periodic orbits or equilibria")
            data = ds.load()
        tables = tomllib.loads(data.attrs["config"])
        tables.pop(kind)        # (the command's table: the rest is a survey config)
        config = load_config(tables, check_output=False)
        name = next(iter(data.coords))
        if name in (V.energy, V.angular_momentum):     # one Hamiltonian along the family
            system = config.system()
            return cls(path, data, lambda p: system)
        return cls(path, data, family_systems(config.system_table, name, kind)[1])

    @property
    def kind(self) -> str:
        return self.ds.attrs["family"]

    @property
    def parameter(self) -> str:
        return next(iter(self.ds.coords))

    @property
    def values(self) -> np.ndarray:
        return self.ds[self.parameter].values.astype(float)

    def measure(self) -> tuple[str, np.ndarray]:
        """What the diagram draws against the parameter: the period, or the energy."""
        name = "period" if self.kind == PERIODIC else V.energy
        return name, self.ds[name].values.astype(float)

    def describe(self, member: int) -> list[str]:
        """A member's numbers as the archive holds them."""
        d, p = self.ds.isel(member=member), self.values[member]
        lines = [f"member {member}: {self.parameter} = {p:.10g}, E = "
                 f"{float(d[V.energy]):.10g}, J = {float(d[V.angular_momentum]):.10g}"]
        if self.kind == PERIODIC:
            mu = d["multiplier_real"].values + 1j * d["multiplier_imag"].values
            mu = mu[np.isfinite(mu)]
            lines += [f"period {float(d['period']):.10g}, returning rotated by "
                      f"{float(d['rotation']):.10g} rad: {str(d['kind'].values)}, "
                      + ("linearly stable" if bool(d["stable"]) else "unstable"),
                      "non-trivial Floquet multipliers (|mu|, angle/pi): " + ", ".join(
                          f"{abs(m):.9g} {np.angle(m) / np.pi:+.6f}" for m in mu)]
        else:
            lam = d["eigenvalue_real"].values + 1j * d["eigenvalue_imag"].values
            lam = lam[np.isfinite(lam)]
            lines += [f"rotation rate Omega = {float(d['rotation_rate']):.10g}: "
                      + ("linearly stable" if bool(d["stable"]) else "unstable"),
                      "reduced eigenvalues: " + ", ".join(f"{z.real:+.6g}{z.imag:+.6g}i"
                                                         for z in lam)]
        return lines

    def member_orbit(self, member: int, samples: int = 2001):
        """(times, positions (samples, N, d), the relative return error) of the member
        integrated with survey's kernels over one period (an equilibrium: one turn of its
        rigid rotation, or nothing where it rests)."""
        d = self.ds.isel(member=member)
        system = self.system_at(self.values[member])
        if self.kind == PERIODIC:
            y0, T = d[V.initial_state].values.astype(float), float(d["period"])
        else:
            q = d["positions"].values.astype(float)
            omega = float(d["rotation_rate"])
            p = system.masses[:, None] * omega * np.stack([-q[:, 1], q[:, 0]], axis=-1)
            y0 = system.state(q, p)
            T = 2 * np.pi / abs(omega) if omega else 1.0
        t = np.linspace(0.0, T, samples)
        out = integrate(system, y0, T, t_eval=t, rtol=1e-12, atol=1e-12)
        q, _ = system.split(out.samples[:, :system.n])
        # a relative periodic orbit returns turned by its rotation (the shooting's R)
        turn = float(d["rotation"]) if self.kind == PERIODIC and system.dim == 2 else 0.0
        back = linalg.dot(rotation(system, turn), y0) if turn else y0
        error = float(np.linalg.norm(out.y - back) / np.linalg.norm(y0))
        return t, q, error


def open_view(path):
    """The explorer's view of the file at `path`: a survey archive's, or a family's."""
    if is_family(path):
        return FamilyView.open(path)
    return CellView.open(path)


# ---------------------------------------------------------------------------- the page

def _image_geometry(values: np.ndarray):
    """(start, width, in index units) of an image's pixels along an axis: the values'
    extent when they are evenly spaced, else the index (the hover tells the value)."""
    if values.size > 1:
        step = np.diff(values)
        if np.allclose(step, step[0], rtol=1e-6, atol=0) and step[0] > 0:
            return values[0] - step[0] / 2, values.size * step[0], False
    if values.size == 1:
        return values[0] - 0.5, 1.0, False
    return -0.5, float(values.size), True


def _nearest(x: float, values: np.ndarray, indexed: bool) -> int | None:
    """The index of the axis value nearest x (x in index units if `indexed`), or None
    off the grid."""
    if indexed:
        i = int(round(x))
    else:
        i = int(np.argmin(np.abs(values - x)))
        half = (np.diff(values).min() / 2) if values.size > 1 else 0.5
        if abs(values[i] - x) > half * 1.0001:
            return None
    return i if 0 <= i < values.size else None


def document(view: CellView, doc) -> None:
    """Lay out the page of an archive on a Bokeh document (one per browser tab)."""
    from bokeh.events import Tap
    from bokeh.layouts import column, row
    from bokeh.models import (
        BasicTicker,
        ColorBar,
        ColumnDataSource,
        Div,
        FixedTicker,
        LinearColorMapper,
        NumericInput,
        Select,
        TextAreaInput,
    )
    from bokeh.plotting import figure

    layers = view.layers()
    axes = view.axes
    title = Div(text=f"<h3 style='margin:4px 0'>{view.path.name}: "
                     f"{view.config.name}</h3><div>{view.config.n_cells} cells over "
                     f"{', '.join(axes) or 'one start'}; click a cell to integrate its "
                     f"orbit</div>")
    choose = Select(title="colour by", value=V.regime, options=list(layers), width=200)
    t_final = NumericInput(title="orbit to t =", value=view.config.settings.integration.t_final,
                           low=1e-6, mode="float", width=140, name="t_final")
    status = Div(text="", name="notice", width=900)
    lines = Div(text="", name="orbit-text", width=900)
    export = TextAreaInput(title="the cell as a config ([initial] family = \"explicit\")",
                           value="", rows=12, width=900, name="export")
    command = Div(text="", name="command", width=900)

    def shown(layer: Layer):
        """(values, low, high) as the map colours them: a log layer in log10."""
        if not layer.log:
            return layer.values, layer.low, max(layer.high, layer.low + 1e-12)
        with np.errstate(invalid="ignore", divide="ignore"):
            v = np.where(layer.values > 0, np.log10(layer.values), np.nan)
        lo = np.log10(max(layer.low, 1e-6))
        return v, lo, max(np.log10(max(layer.high, 1e-6)), lo + 1e-12)

    hovered = view.hover_columns()
    tips = [(k, f"@{{{k}}}" + ("" if v.dtype.kind in "iU" else "{%.6g}"))
            for k, v in hovered.items()]
    formats = {f"@{{{k}}}": "printf" for k, v in hovered.items() if v.dtype.kind == "f"}

    if len(axes) == 2:
        a, b = axes
        xa, xb = view.axis_values(a), view.axis_values(b)
        (x0, dw, ia), (y0, dh, ib) = _image_geometry(xa), _image_geometry(xb)
        shape = view.shape

        def image(values):
            return np.asarray(values, dtype=float).reshape(shape).T   # rows: b, columns: a

        data = {"image": [image(layers[V.regime].values)], "x": [x0], "y": [y0],
                "dw": [dw], "dh": [dh]}
        for k, v in hovered.items():
            data[k] = [v.reshape(shape).T]
        source = ColumnDataSource(data)
        plot = figure(width=640, height=520, title=V.regime,
                      x_axis_label=_tex(label(a)) + (" (index)" if ia else ""),
                      y_axis_label=_tex(label(b)) + (" (index)" if ib else ""),
                      tools="pan,wheel_zoom,box_zoom,reset,hover,save", tooltips=tips,
                      name="map")
        plot.x_range.range_padding = plot.y_range.range_padding = 0
        # one mapper, changed in place from layer to layer (BokehJS redraws an image when
        # its mapper changes, not when the mapper is replaced); the regimes' bar has its own
        first = layers[V.regime]
        colours = LinearColorMapper(palette=list(first.palette), low=first.low,
                                    high=first.high, nan_color="#bbbbbb", name="colours")
        plot.image("image", x="x", y="y", dw="dw", dh="dh", source=source,
                   color_mapper=colours)
        regime_bar = ColorBar(color_mapper=LinearColorMapper(
            palette=list(first.palette), low=first.low, high=first.high), width=12,
            ticker=FixedTicker(ticks=[int(r) for r in Regime]),
            major_label_overrides={int(r): r.name.lower() for r in Regime})
        value_bar = ColorBar(color_mapper=colours, width=12, ticker=BasicTicker(),
                             visible=False)
        plot.add_layout(regime_bar, "right")
        plot.add_layout(value_bar, "right")

        def recolour(attr, old, new):
            layer = layers[new]
            values, low, high = shown(layer)
            colours.update(palette=list(layer.palette), low=low, high=high)
            source.data["image"] = [image(values)]
            regime_bar.visible, value_bar.visible = new == V.regime, new != V.regime
            plot.title.text = f"log10 {new}" if layer.log else new
        choose.on_change("value", recolour)

        def cell_at(x, y):
            i, j = _nearest(x, xa, ia), _nearest(y, xb, ib)
            return None if i is None or j is None else int(i * shape[1] + j)
    else:
        xs = view.axis_values(axes[0]) if axes else np.zeros(1)
        regime = layers[V.regime].values.astype(int)
        source = ColumnDataSource({"x": xs, "y": layers[V.regime].values,
                                   "colour": [REGIME_COLOURS[Regime(r)] for r in regime],
                                   **hovered})
        plot = figure(width=760, height=360, title=V.regime,
                      x_axis_label=_tex(label(axes[0])) if axes else "cell",
                      tools="pan,wheel_zoom,box_zoom,reset,hover,save",
                      tooltips=tips, name="map")
        plot.line("x", "y", source=source, color="#999999")
        plot.scatter("x", "y", source=source, color="colour", size=7)
        ticks = plot.yaxis[0]
        named = dict(ticker=FixedTicker(ticks=[int(r) for r in Regime]),
                     major_label_overrides={int(r): r.name.lower() for r in Regime})
        ticks.update(**named)
        plain = dict(ticker=BasicTicker(), major_label_overrides={})

        def recolour(attr, old, new):
            values, _, _ = shown(layers[new])
            source.data["y"] = values
            ticks.update(**(named if new == V.regime else plain))
            plot.title.text = f"log10 {new}" if layers[new].log else new
        choose.on_change("value", recolour)

        def cell_at(x, y):
            if not axes:
                return 0
            return _nearest(x, xs, False)

    # the clicked cell's orbit
    paths = figure(width=420, height=400, title="paths", match_aspect=True,
                   x_axis_label="x", y_axis_label="y", name="paths")
    path_sources = [ColumnDataSource({"x": [], "y": []})
                    for _ in range(view.config.system(0).n_bodies)]
    for k, src in enumerate(path_sources):
        paths.line("x", "y", source=src, color=("#d62728", "#2ca02c", "#1f77b4",
                                                "#9467bd", "#8c564b")[k % 5], line_width=1)
    crossing_source = ColumnDataSource({"x": [], "y": []})
    names = view.section_names()
    section = figure(width=420, height=400, title=view.section_title(), name="section",
                     x_axis_label=_tex(label(names[0])), y_axis_label=_tex(label(names[1])))
    section.scatter("x", "y", source=crossing_source, size=3, color="black")
    conv_source = ColumnDataSource({"t": [], "mean_y": [], "growth_rate": []})
    convergence = figure(width=420, height=400, title="indicators' convergence",
                         x_axis_label="t", name="convergence")
    convergence.line("t", "mean_y", source=conv_source, color="#1f77b4", legend_label="MEGNO")
    convergence.line("t", "growth_rate", source=conv_source, color="#d62728",
                     legend_label="FTLE ln(|w|/|w0|)/t")
    convergence.legend.location = "top_left"

    def draw(cell):
        try:
            o = view.orbit(cell, float(t_final.value))
        except Exception as exc:       # the page's boundary: said there, the app goes on
            why = str(exc) if isinstance(exc, ValueError) else f"{type(exc).__name__}: {exc}"
            status.text = f"<b>cell {cell} could not be integrated</b>: {_html(why)}"
            return
        for k, src in enumerate(path_sources):
            src.data = {"x": o.positions[:, k, 0], "y": o.positions[:, k, 1]}
        crossing_source.data = {"x": np.asarray(o.crossings[0]) if o.crossings else [],
                                "y": np.asarray(o.crossings[1]) if o.crossings else []}
        conv_source.data = {"t": o.t, "mean_y": o.megno, "growth_rate": o.ftle}
        freq = "; ".join(f"{n} = {f:.8g}" for n, f in o.frequencies if np.isfinite(f))
        lines.text = "<pre>" + _html("\n".join(o.lines + ([f"frequencies (archive): {freq}"]
                                                        if freq else []))) + "</pre>"
        export.value = view.export(cell)
        command.text = ("save the config above as <code>" + f"{view.config.name}_cell_{cell}"
                        + ".toml</code>, then: <code>" + _html(view.command(cell)) + "</code>")
        status.text = f"cell {cell} ({_where(view, cell)}): integrated to t = {o.t[-1]:g}"

    def integrate(cell):
        if not 0 <= cell < view.config.n_cells:
            status.text = (f"<b>cell {cell} could not be integrated</b>: not a cell of the "
                           f"grid (0..{view.config.n_cells - 1})")
            return
        status.text = (f"{SPINNER}integrating cell {cell} ({_where(view, cell)}) to t = "
                       f"{float(t_final.value):g} ...")
        doc.add_timeout_callback(lambda: draw(cell), 60)   # the notice is sent first

    def clicked(event):
        cell = cell_at(event.x, event.y)
        if cell is not None:
            integrate(cell)
    plot.on_event(Tap, clicked)
    plot.hover.formatters = formats

    views = [row(plot, column(choose, t_final))]
    views += _section_views(view, integrate)
    doc.add_root(column(title, *views, status, row(paths, section, convergence), lines,
                        export, command))
    # a page's address may choose its layer, horizon and cell: ?layer=megno&t=500&cell=61
    args = doc.session_context.request.arguments if doc.session_context else {}
    given = {k: v[0].decode() for k, v in args.items() if v}
    if given.get("layer") in layers:
        choose.value = given["layer"]
    try:
        if "t" in given and float(given["t"]) > 0:
            t_final.value = float(given["t"])
        if "cell" in given:
            integrate(int(given["cell"]))
    except ValueError:
        status.text = f"<b>the address's t or cell is not a number</b>: {_html(str(given))}"
    doc.title = f"survey explore: {view.path.name}"


def family_document(view: FamilyView, doc) -> None:
    """The page of a family archive: its diagram along the parameter (stable members blue,
    unstable red, bifurcations marked) over its stability indices (a periodic family) or
    its normal-mode frequencies (equilibria); a click on a member integrates it."""
    from bokeh.events import Tap
    from bokeh.layouts import column, row
    from bokeh.models import ColumnDataSource, Div
    from bokeh.plotting import figure
    p, (name, y) = view.values, view.measure()
    stable = view.ds["stable"].values.astype(bool)
    colour = np.where(stable, REGIME_COLOURS[Regime.TORUS], REGIME_COLOURS[Regime.CHAOTIC])
    kinds = view.ds["kind"].values.astype(str) if "kind" in view.ds else \
        np.where(stable, "stable", "unstable")
    src = ColumnDataSource({"p": p, "y": y, "colour": colour, "member": np.arange(p.size),
                            "kind": kinds})
    title = Div(text=f"<h3 style='margin:4px 0'>{view.path.name}: {view.ds.attrs['title']}"
                     f"</h3><div>{p.size} members; blue linearly stable, red unstable; "
                     "click a member to integrate it</div>")
    diagram = figure(width=760, height=380, title=f"{name} along {view.parameter}",
                     x_axis_label=_tex(label(view.parameter)), y_axis_label=name,
                     tools="pan,wheel_zoom,box_zoom,reset,hover,save", name="diagram",
                     tooltips=[("member", "@member"), (view.parameter, "@p{%.10g}"),
                               (name, "@y{%.10g}"), ("kind", "@kind")])
    diagram.hover.formatters = {"@p": "printf", "@y": "printf"}
    diagram.line("p", "y", source=src, color="#999999")
    diagram.scatter("p", "y", source=src, color="colour", size=6)
    where = view.ds["bifurcation_parameter"].values.astype(float)
    if where.size:
        at = np.argsort(p)
        diagram.scatter(where, np.interp(where, p[at], y[at]), marker="x", size=14,
                        color="black", line_width=2,
                        legend_label="bifurcations: " + ", ".join(
                            view.ds["bifurcation_kind"].values.astype(str)))
    below = figure(width=760, height=260, x_range=diagram.x_range, name="stability",
                   x_axis_label=_tex(label(view.parameter)),
                   y_axis_label="stability indices (mu + 1/mu)/2" if view.kind == PERIODIC
                   else "normal-mode frequencies |Im lambda|")
    values = view.ds["index_real"].values if view.kind == PERIODIC else \
        np.abs(view.ds["eigenvalue_imag"].values)
    for k in range(values.shape[1]):
        below.line(p, values[:, k], color=("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd")[k % 4])
    status = Div(text="", name="notice", width=900)
    lines = Div(text="", name="orbit-text", width=900)
    paths = figure(width=460, height=440, title="the member over one period", name="paths",
                   match_aspect=True, x_axis_label="x", y_axis_label="y")
    n_bodies = view.system_at(p[0]).n_bodies
    path_sources = [ColumnDataSource({"x": [], "y": []}) for _ in range(n_bodies)]
    for k, source in enumerate(path_sources):
        paths.line("x", "y", source=source, line_width=1.5,
                   color=("#d62728", "#2ca02c", "#1f77b4", "#9467bd", "#8c564b")[k % 5])

    def draw(member):
        try:
            t, q, error = view.member_orbit(member)
        except Exception as exc:       # the page's boundary: said there, the app goes on
            why = str(exc) if isinstance(exc, ValueError) else f"{type(exc).__name__}: {exc}"
            status.text = f"<b>member {member} could not be integrated</b>: {_html(why)}"
            return
        for k, source in enumerate(path_sources):
            source.data = {"x": q[:, k, 0], "y": q[:, k, 1]}
        back = "its start turned by the rotation" if view.kind == PERIODIC else "its start"
        lines.text = "<pre>" + _html("\n".join(view.describe(member) + [
            f"integrated over t = {t[-1]:.10g} with survey's kernels: it returns to {back} "
            f"within {error:.2g} of its size"])) + "</pre>"
        status.text = f"member {member} ({view.parameter} = {p[member]:.10g}): integrated"

    def clicked(event):
        span = np.array([np.ptp(p) or 1.0, np.ptp(y) or 1.0])
        d = np.hypot((p - event.x) / span[0], (y - event.y) / span[1])
        member = int(np.argmin(d))
        status.text = f"{SPINNER}integrating member {member} ..."
        doc.add_timeout_callback(lambda: draw(member), 60)
    diagram.on_event(Tap, clicked)
    doc.add_root(column(title, diagram, below, status, row(paths, lines)))
    doc.title = f"survey explore: {view.path.name}"


def _section_views(view, integrate) -> list:
    """A one-shell archive's section, crossings coloured by regime (a click integrates the
    crossing's cell), and its 4-D section of three bodies in the plane in three
    coordinates, turned by two sliders (the projection computed in the browser)."""
    from bokeh.events import Tap
    from bokeh.layouts import column, row
    from bokeh.models import ColumnDataSource, CustomJS, Slider
    from bokeh.plotting import figure
    colours = np.array([REGIME_COLOURS[r] for r in Regime])
    out = []
    found = view.shell_crossings()
    if found is not None:
        x, y, regime, cell, names = found
        src = ColumnDataSource({"x": x, "y": y, "colour": colours[regime.astype(int)]})
        fig = figure(width=560, height=460, title="the shell's section, coloured by regime: "
                     "click a crossing for its cell's orbit",
                     x_axis_label=_tex(label(names[0])), y_axis_label=_tex(label(names[1])),
                     tools="pan,wheel_zoom,box_zoom,reset,save", name="shell-section",
                     output_backend="webgl")
        fig.scatter("x", "y", source=src, color="colour", size=2)
        scale = np.array([np.ptp(x) or 1.0, np.ptp(y) or 1.0])

        def tapped(event):
            d = np.hypot((x - event.x) / scale[0], (y - event.y) / scale[1])
            k = int(np.argmin(d))
            if d[k] < 0.02:
                integrate(int(cell[k]))
        fig.on_event(Tap, tapped)
        out.append(fig)
    points = view.slice_points()
    if points is not None:
        coords, regime, slab = points[:3], points[4], points[5]
        unit = [(c - (c.max() + c.min()) / 2) / ((np.ptp(c) or 1.0) / 2) for c in coords]
        data = {"u": unit[0], "v": unit[1], "w": unit[2], "x": unit[0].copy(),
                "y": unit[1].copy(), "colour": colours[regime.astype(int)]}
        src = ColumnDataSource(data)
        fig = figure(width=460, height=460, title=f"the 3-D slice {slab} in (sigma, "
                     "p_sigma, eta), each scaled to its range: turn it", name="slice3d",
                     tools="pan,wheel_zoom,reset,save", x_range=(-1.8, 1.8),
                     y_range=(-1.8, 1.8), output_backend="webgl")
        fig.axis.visible = False
        fig.scatter("x", "y", source=src, color="colour", size=2)
        azimuth = Slider(title="azimuth (degrees)", start=-180, end=180, value=0, step=1,
                         name="azimuth")
        elevation = Slider(title="elevation (degrees)", start=-90, end=90, value=0, step=1,
                           name="elevation")
        turn = CustomJS(args=dict(src=src, az=azimuth, el=elevation), code="""
            const a = az.value * Math.PI / 180, e = el.value * Math.PI / 180;
            const d = src.data, n = d.u.length, x = new Float64Array(n), y = new Float64Array(n);
            const ca = Math.cos(a), sa = Math.sin(a), ce = Math.cos(e), se = Math.sin(e);
            for (let i = 0; i < n; i++) {   // turn about the vertical, then tilt
                const u = ca * d.u[i] + sa * d.w[i], w = -sa * d.u[i] + ca * d.w[i];
                x[i] = u; y[i] = ce * d.v[i] + se * w;
            }
            src.data = {...d, x: x, y: y};
        """)
        azimuth.js_on_change("value", turn)
        elevation.js_on_change("value", turn)
        out.append(column(fig, azimuth, elevation))
    return [row(*out)] if out else []


def _where(view: CellView, cell: int) -> str:
    d = view.describe(cell)
    return ", ".join(f"{a} = {d[a]}" for a in view.axes) or "the one start"


def _tex(text: str) -> str:
    """A figure label's $...$ as Bokeh's $$...$$ (typeset in the browser)."""
    parts = text.split("$")
    return "".join(p if k % 2 == 0 else f"$${p}$$" for k, p in enumerate(parts)) \
        if len(parts) % 2 else text


def _html(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


# ---------------------------------------------------------------------------- the server

def check_port(host: str, port: int) -> None:
    """A SurveyError before anything starts if (host, port) cannot be listened on."""
    if not 0 <= port <= 65535:
        raise ConfigError("--port", f"must be 0..65535 (0: any free port), got {port}")
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        try:
            s.bind((host, port))
        except OSError as exc:
            why = "is in use (another explorer, or another server)" if exc.errno in (98, 48) \
                else f"cannot be listened on ({exc.strerror or exc})"
            raise SurveyError(f"port {port} on {host} {why}; choose another with --port N "
                              "(0: any free port)") from None


def _free_port(host: str) -> int:
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


class Running(NamedTuple):
    server: object
    url: str

    def stop(self):
        self.server.io_loop.add_callback(self.server.stop)
        self.server.io_loop.add_callback(self.server.io_loop.stop)


def serve(path, host: str = HOST, port: int = PORT) -> Running:
    """The explorer's server for the archive at `path` (opened and checked first), started
    but not yet looping: run `server.io_loop.start()` (the command does, in its thread)."""
    try:
        from bokeh.application import Application
        from bokeh.application.handlers.function import FunctionHandler
        from bokeh.server.server import Server
    except ImportError:
        raise SurveyError("the explorer needs Bokeh: pip install 'survey[explore]'") from None
    view = open_view(path)
    check_port(host, port)
    page = family_document if isinstance(view, FamilyView) else document
    app = Application(FunctionHandler(lambda doc: page(view, doc)))
    for attempt in range(5):
        # port 0: a free port found here (the page's origin must name it), taken again
        # by another process before the server binds it only by a rare chance: retried
        bound = port or _free_port(host)
        try:
            server = Server({"/": app}, address=host, port=bound, num_procs=1,
                            allow_websocket_origin=[f"{h}:{bound}" for h in
                                                    dict.fromkeys((host, "localhost",
                                                                   "127.0.0.1"))])
            break
        except OSError:
            if port or attempt == 4:
                check_port(host, bound)
                raise
    server.start()
    shown = f"[{host}]" if ":" in host else host
    return Running(server, f"http://{shown}:{bound}/")


def serve_in_thread(path, host: str = HOST, port: int = PORT) -> Running:
    """`serve` on an event loop of its own in a daemon thread, looping once this returns
    (from a notebook, a script or a test: the caller's thread stays free); `stop()` ends
    it. Errors opening the archive or the port are raised here."""
    import asyncio
    import threading
    ready, box = threading.Event(), []

    def run():
        asyncio.set_event_loop(asyncio.new_event_loop())
        try:
            box.append(serve(path, host, port))
        except BaseException as exc:        # (handed to the caller, raised there)
            box.append(exc)
            return
        finally:
            ready.set()
        box[0].server.io_loop.start()
    threading.Thread(target=run, daemon=True, name="survey-explore").start()
    ready.wait()
    if isinstance(box[0], BaseException):
        raise box[0]
    return box[0]


def main(path, host: str = HOST, port: int = PORT, browser: bool = True) -> int:
    """`python -m survey explore`: serve until interrupted."""
    running = serve(path, host, port)
    print(f"survey explore: {Path(path).name} at {running.url} (Ctrl-C stops it)"
          + ("" if host in ("127.0.0.1", "localhost", "::1") else
             f"; listening on {host}: anyone who reaches it can use it"), flush=True)
    if browser:
        import webbrowser
        try:
            webbrowser.open(running.url)
        except webbrowser.Error:
            pass
    try:
        running.server.io_loop.start()
    except KeyboardInterrupt:
        print("stopped", file=sys.stderr)
    return 0

