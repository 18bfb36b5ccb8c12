"""Families of special solutions in words and JSON: what `python -m survey equilibria` and
`periodic` print, and the report `reproduce` writes of a special-solution workflow -- from
what pipeline.families solved (its `Solved`: kind, system, table, what was found)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..analysis.findings import family_stability
from ..catalog.defaults import EXCURSION


def as_text(solved) -> str:
    """What the command prints: the equilibria found or their family, the orbit found or
    its family."""
    if solved.kind == "equilibria":
        return family_text(solved.table, solved.found) if solved.is_family else \
            equilibria_text(solved.system, solved.table, solved.found)
    return periodic_family_text(solved.system, solved.table, solved.found) \
        if solved.is_family else periodic_text(solved.system, solved.found)


def as_json(solved) -> str:
    """The same as JSON (`--json`)."""
    table, found = solved.table, solved.found
    if solved.kind == "equilibria":
        if not solved.is_family:
            return json.dumps(equilibria_json(found.equilibria, found), indent=1)
        return json.dumps({"family": equilibria_json([e for _, e in found.members])[
                               "equilibria"],
                           table["parameter"]: [float(p) for p, _ in found.members],
                           "complete": found.complete, "ended": found.ended,
                           "bifurcations": [b._asdict() for b in found.bifurcations]},
                          indent=1)
    if not solved.is_family:
        return json.dumps(periodic_json(found), indent=1)
    return json.dumps({"family": [periodic_json(o) for o in found.members],
                       table["parameter"]: found.parameters.tolist(),
                       "complete": found.complete, "ended": found.ended,
                       "bifurcations": [f._asdict() for f in found.bifurcations]}, indent=1)


def write_report(solved, folder, diagram=None) -> Path:
    """NAME.md in `folder` for a special-solution workflow: what it is (its config) and
    what was found, in the words the command prints; with a periodic family's Dataset
    (`diagram`) also NAME.png, its bifurcation diagram."""
    from .plots import family_diagram
    path = solved.path
    figure = None
    if diagram is not None:
        figure = Path(folder) / f"{path.stem}.png"
        family_diagram(diagram, _family_title(solved)).savefig(figure, dpi=130)
    command = f"python -m survey {solved.kind} {path.as_posix()}"
    out = Path(folder) / f"{path.stem}.md"
    body = (f"# {path.stem}\n\n`{command}` (written by `python -m survey reproduce`):\n\n"
            f"```\n{as_text(solved)}\n```\n\n"
            + (f"![bifurcation diagram]({figure.name})\n\n" if figure else "")
            + f"The workflow:\n\n```toml\n{solved.text.strip()}\n```\n")
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(body)
    tmp.replace(out)
    return out


def _family_title(solved) -> str:
    """What a periodic family's diagram is of: the workflow, the start, the parameter
    (and the J it is held at), the bodies and their terms."""
    system, table, family = solved.system, solved.table, solved.found
    start = f"Lyapunov family of normal mode {table['mode']}" if table["mode"] else "family"
    terms = " + ".join(f"{t.name} (" + ", ".join(f"{k} {v:g}" for k, v in zip(
        t.param_names, t.params)) + ")" for t in system.terms)
    spin = f" at J = {family.members[0].angular_momentum:.6g}" if table["rotating"] and \
        table["parameter"] == "energy" else ""
    return (f"{solved.path.stem}: {start} in {table['parameter']}{spin}; "
            f"{system.n_bodies} bodies, {terms}")


def located(b) -> str:
    """A bifurcation's parameter with the digits its accuracy supports (at most 10), and the
    accuracy itself: 0.999879112 +- 2e-09."""
    acc = b.accuracy
    if not (np.isfinite(acc) and acc > 0):
        return f"{b.parameter:.10g}"
    digits = int(np.floor(np.log10(max(abs(b.parameter), 1e-300)))
                 - np.floor(np.log10(acc))) + 1
    return f"{b.parameter:.{min(max(digits, 1), 10)}g} +- {acc:.1g}"



def family_text(table: dict, family) -> str:
    """A family of relative equilibria (continuation.EquilibriumFamily) as text."""
    name = table["parameter"]
    members, found = family.members, family.bifurcations
    lines = [f"Family along {name} ({len(members)} members, " + (
        "reaching" if family.complete else "not reaching") + f" {name} = {table['to']:g}"
             + ("" if family.complete else f": {family.ended}") + "):", "",
             f"| {name} | E | J | Omega | stable | largest growth rate |",
             "| --- | --- | --- | --- | --- | --- |"]
    for p, e in members:
        lines.append(f"| {p:.6g} | {e.energy:.8g} | {e.angular_momentum:.8g} | "
                     f"{e.rotation_rate:.8g} | {'yes' if e.stable else 'no'} | "
                     f"{max(e.rates, default=0.0):.4g} |")
    lines += [""] + ([f"At {name} = {located(b)}: a fold." if b.kind == "fold" else
                      f"Stability changes at {name} = {located(b)}: {b.kind} on the "
                      "unstable side." for b in found] or ["The stability does not change."])
    return "\n".join(lines)



def equilibria_json(found: list, search=None) -> dict:
    """The equilibria as JSON; with their `search` (physics.equilibria.Search) how it
    covered the configurations: tries, shape-sphere points, seeded starts, how many times
    each was reached and an estimate of how many none reached."""
    cover = {} if search is None else {"search": {
        "tries": search.tries, "shape_sphere_points": search.shapes,
        "seeded": search.seeded, "missed_estimate": search.missed}}
    hits = [None] * len(found) if search is None else search.hits
    return {**cover, "equilibria": [{
        "positions": e.positions.tolist(), "rotation_rate": e.rotation_rate,
        "energy": e.energy, "angular_momentum": e.angular_momentum,
        "eigenvalues": [[float(z.real), float(z.imag)] for z in e.eigenvalues],
        "frequencies": e.frequencies.tolist(),
        "krein": [int(k) for k, z in zip(e.krein, e.eigenvalues) if k],
        "stable": e.stable, "residual": e.residual, "morse_index": e.morse,
        **({} if h is None else {"reached": h})} for e, h in zip(found, hits)]}



def equilibria_text(system, table: dict, search) -> str:
    """The search's equilibria, each with how many tries reached it and its Morse index,
    and how complete the list is."""
    found = search.equilibria
    given = f"J = {table['angular_momentum']:g}" if table["angular_momentum"] is not None \
        else f"Omega = {table['rotation_rate']:g}"
    tried = (f"the start, {search.shapes} points of the shape sphere (each by Newton and "
             f"by descent) and {search.seeded} seeded configurations" if search.shapes else
             f"the start and {search.seeded} seeded configurations")
    lines = [f"Relative equilibria of {system.n_bodies} bodies ({system.describe()}) at "
             f"{given}, from {tried}: {len(found)} distinct (up to rotations, reflections "
             f"and permutations), reached {', '.join(map(str, search.hits))} times of "
             f"{search.tries} tries. " + (
                 "Every one was reached at least twice: no sign of one missed."
                 if search.missed == 0 else
                 f"Some were reached only once: about {search.missed:.1f} more may have been "
                 "missed (Chao's estimate); more starts would find them.")]
    for k, e in enumerate(found):
        i, j = np.triu_indices(system.n_bodies, 1)
        dist = np.linalg.norm(e.positions[i] - e.positions[j], axis=1)
        modes = ", ".join(f"{f:.10g} ({'+' if s > 0 else '-'})" for f, s in zip(
            e.frequencies, e.krein[e.krein != 0])) or "none"
        lines += ["", f"{k + 1}. E = {e.energy:.10g}, J = {e.angular_momentum:.10g}, "
                      f"Omega = {e.rotation_rate:.10g}: "
                      + ("linearly stable" if e.stable else "unstable")
                      + f"; Morse index {e.morse} of the amended potential"
                      + (" (a minimum)" if e.morse == 0 else ""),
                  "   mutual distances " + ", ".join(f"r{a}{b} = {r:.10g}" for a, b, r in
                                                     zip(i, j, dist)),
                  f"   normal modes in the rotating frame (cycles per unit time, Krein "
                  f"sign): {modes}"]
        if e.unstable.size:
            lines.append("   growth rates: " + ", ".join(
                f"{z.real:.10g}" + (f" +- {abs(z.imag):.6g} i" if abs(z.imag) > 1e-12 else "")
                for z in e.unstable))
    return "\n".join(lines)



def periodic_json(orbit) -> dict:
    return {"period": orbit.period, "rotation": orbit.rotation, "energy": orbit.energy,
            "angular_momentum": orbit.angular_momentum,
            "initial_state": orbit.state.tolist(), "return_error": orbit.return_error,
            "newton_residuals": orbit.residuals.tolist(),
            "multipliers": [[float(z.real), float(z.imag)] for z in orbit.multipliers],
            "stable": orbit.stable, "kind": orbit.kind, "rates": orbit.rates.tolist(),
            "excursion": orbit.motion.excursion, "turning": orbit.motion.turning,
            "residues": [[float(z.real), float(z.imag)] for z in orbit.residues]}



def _residues(orbit) -> str:
    return ", ".join(f"{z.real:.9f}" if abs(z.imag) <= 1e-9 else f"{z.real:.6f} {z.imag:+.6f}i"
                     for z in orbit.residues)



def periodic_text(system, orbit) -> str:
    turn = f", returning rotated by {orbit.rotation:.10g} rad" if orbit.rotation else ""
    spin = orbit.angular_momentum if abs(orbit.angular_momentum) > 1e-12 else 0.0
    lines = [f"Periodic orbit of {system.n_bodies} bodies ({system.describe()}): period "
             f"{orbit.period:.11g}{turn}; E = {orbit.energy:.10g}, J = {spin:.10g}.",
             "Newton shooting, return error |y(T) - y(0)| / |y(0)| before each step and "
             "after the last: " + ", ".join(f"{r:.1e}" if r >= 1e-12 else "< 1e-12"
                                            for r in orbit.residuals) + ".",
             "Non-trivial Floquet multipliers (|mu|, angle/pi): " + ", ".join(
                 f"{m:.9f} {a / np.pi:+.6f}" for m, a in zip(*orbit.polar))
             + f": {orbit.kind}" + (", linearly stable." if orbit.stable else
                                    ", unstable; nearby orbits leave at " + ", ".join(
                                        f"{r:.6g}" for r in sorted({float(f"{r:.6g}") for r in
                                                                    orbit.rates}, reverse=True))
                                    + " per unit time."),
             f"Greene's residues R = (2 - mu - 1/mu) / 4, one per pair (0 < R < 1 elliptic): "
             f"{_residues(orbit)}.",
             f"Checked to be an orbit that moves: it leaves its start by up to "
             f"{orbit.motion.excursion:.3g} of its size (at least {EXCURSION:.0e} times its "
             f"return error) and its velocity turns through {orbit.motion.turning:.4g} times "
             "a full circle over the period (a closed orbit's turns through one at least)."]
    return "\n".join(lines)



def periodic_family_text(system, table: dict, family, rows: int = 40) -> str:
    name = table["parameter"]
    first = family.members[0]
    start = (f"the Lyapunov family of normal mode {table['mode']} of the relative "
             f"equilibrium" if table["mode"] else "the family of the start's orbit")
    n = len(family.members)
    shown = np.unique(np.round(np.linspace(0, n - 1, min(rows, n))).astype(int))
    lines = [f"Periodic orbits of {system.n_bodies} bodies ({system.describe()}): {start}, "
             f"followed in {name} by pseudo-arclength continuation"
             + (f" at J = {first.angular_momentum:.10g}" if name == "energy" and
                table["rotating"] else "")
             + f": {n} members, " + ("reaching" if family.complete else "not reaching")
             + f" {name} = {table['to']:g}" + ("" if family.complete else
                                              f" ({family.ended})")
             + ("" if len(shown) == n else f" (every {n / len(shown):.1f}th shown)") + ".", "",
             f"| {name} | period | rotation | "
             + ("" if name == "energy" else "E | ") + "kind | stability indices (mu + 1/mu)/2 |",
             "| --- " * (5 if name == "energy" else 6) + "|"]
    for i in shown:
        o, p = family.members[i], family.parameters[i]
        lines.append(f"| {p:.10g} | {o.period:.10g} | {o.rotation:.8g} | "
                     + ("" if name == "energy" else f"{o.energy:.10g} | ") + f"{o.kind} | "
                     + ", ".join(
                         f"{b.real:.6f}" if abs(b.imag) <= 1e-9 else
                         f"{b.real:.4f}{b.imag:+.4f}i" for b in o.indices) + " |")
    lines += [""] + ([f"At {name} = {located(b)}: {b.kind}." for b in
                      family.bifurcations] or ["No fold, and no multiplier leaves or joins the "
                                               "unit circle between members."])
    indices = np.array([o.indices for o in family.members])
    stretches = family_stability(family.parameters, indices.real, indices.imag,
                                 [o.stable for o in family.members], name)
    if stretches:
        lines += ["", f"Stable stretches ({stretches[0].test}):"] + \
            [f"- {f.text()}." for f in stretches]
    return "\n".join(lines)

