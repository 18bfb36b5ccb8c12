"""survey's verdicts on systems whose answer is known without survey: Henon-Heiles starts
at E = 1/8 against a maximal Lyapunov exponent computed here by scipy's DOP853 from the
equations of motion and their variational equations written out by hand; Toda starts
(an integrable system) all regular; the report's published-share columns and its
sensitivity table from the same archive."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from survey.analysis.classify import separation_share, verdict_class
from survey.catalog.regimes import IRREGULAR, REGULAR
from survey.catalog.variables import V
from survey.pipeline.sweep import run
from survey.presentation.report import markdown

HENON_HEILES = "(x**2 + y**2)/2 + x**2*y - y**3/3"
TODA = "(exp(2*y + 2*sqrt(3)*x) + exp(2*y - 2*sqrt(3)*x) + exp(-4*y))/24 - 1/8"


def sample(tmp_path, name, formula, energies, starts, t_final, **extra):
    return run({"survey": {"name": name, "output": str(tmp_path / f"{name}.nc")},
                "system": {"bodies": 1,
                           "interactions": [{"kind": "external", "expression": formula}]},
                "initial": {"family": "field_section_sample", "energy": energies,
                            "starts_per_cell": starts},
                "integration": {"t_final": t_final},
                "indicators": {"perturbations": 0},
                "section": {"coordinate": "x", "max_crossings": 30},
                "dask": {"workers": 1}, **extra})


def henon_heiles_lyapunov(y0, t_final, interval=10.0):
    """The maximal Lyapunov exponent of a Henon-Heiles orbit: the orbit and one deviation
    vector integrated by scipy (DOP853, rtol 1e-11), the vector renormalised every
    `interval`, the logs of its growth summed."""
    def rhs(t, s):
        x, y, px, py, dx, dy, dpx, dpy = s
        return [px, py, -x - 2 * x * y, -y - x * x + y * y,
                dpx, dpy, -(1 + 2 * y) * dx - 2 * x * dy, -2 * x * dx + (-1 + 2 * y) * dy]
    state = np.concatenate([y0, np.ones(4) / 2.0])
    total, t = 0.0, 0.0
    while t < t_final - 1e-9:
        out = solve_ivp(rhs, (t, t + interval), state, method="DOP853", rtol=1e-11,
                        atol=1e-12)
        state = out.y[:, -1]
        norm = np.linalg.norm(state[4:])
        total += math.log(norm)
        state[4:] /= norm
        t += interval
    return total / t


def test_henon_heiles_verdicts_agree_with_an_independent_lyapunov_exponent(tmp_path):
    """At E = 1/8 (a mixed phase space), every start survey decides regular has a maximal
    Lyapunov exponent by scipy, at the horizon t survey decided it at (T = 1000, or 4 T
    for a verdict in doubt), below 2.25 ln t / t (a torus's decays like ln t / t), every
    start it decides chaotic one above; and both kinds occur."""
    ds = sample(tmp_path, "hh", HENON_HEILES, [0.125], 16, 1000.0)
    regime = ds[V.regime].values.ravel()
    starts = ds[V.initial_state].values.reshape(regime.size, -1)
    decided = verdict_class(regime) != 0
    assert decided.sum() >= 14
    horizon = ds[V.regime_horizon].values.ravel()[decided]       # T, or 4 T if in doubt
    lam = np.array([henon_heiles_lyapunov(y0, t) for y0, t in zip(starts[decided], horizon)])
    regular = np.isin(regime[decided], REGULAR)
    assert 0 < regular.sum() < regular.size
    units = lam * horizon / np.log(horizon)     # a torus's exponent is ~ ln t / t
    assert np.all(units[regular] < 2.25), units[regular]
    assert np.all(units[~regular] > 2.25), units[~regular]


def test_toda_starts_are_all_regular_and_the_report_compares_published_shares(tmp_path):
    """The Toda potential is integrable: no start is called chaotic or sticky, at the
    Henon-Heiles energies and far above (a torus near a separatrix, whose Birkhoff averages
    converge slowly, may stay undetermined); the report sets the published share (1) beside
    the sample's with its interval, says they agree, and shows the share's sensitivity to
    each threshold; the separation criterion calls every start regular too."""
    energies = [0.125, 1.0]
    ds = sample(tmp_path, "toda", TODA, energies, 12, 1000.0,
                reference={"source": "integrable: every orbit on a torus.",
                           "at": energies, "regular_share": [1.0, 1.0],
                           "crossings": 25, "growth": 1e5})
    regime = ds[V.regime].values
    assert not np.isin(regime, IRREGULAR).any(), regime        # no false chaos
    decided = np.isin(regime, REGULAR).sum(axis=1)
    assert np.all(decided >= 9), regime      # near a separatrix a torus may stay undecided
    assert np.all(separation_share(ds, 25, 1e5).share.values == 1.0)
    text = markdown(ds)
    rows = [line for line in text.splitlines() if line.startswith(("| 0.125 |", "| 1 |"))]
    assert len(rows) >= 2
    for row, n in zip(rows[:2], decided):
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert cells[1:4] == [str(n), str(n), "100%"] and cells[5] == "100%"
        assert cells[6] == "yes" and cells[8] == "yes"
    assert "## Sensitivity of the regular share" in text
    assert "| megno_regular = 2.44 |" in text and "| at half each cell's horizon |" in text


@pytest.mark.parametrize("growth,regular", [(1e30, 1.0), (1.0 + 1e-12, 0.0)])
def test_the_separation_criterion_counts_growth_by_the_given_crossing(tmp_path, growth,
                                                                     regular):
    """A growth no orbit reaches calls every start regular, one every orbit passes none."""
    ds = sample(tmp_path, "sep", HENON_HEILES, [0.125], 4, 200.0)
    share = separation_share(ds, 25, growth)
    assert share.share.values.ravel().tolist() == [regular]
    assert share.decided.values.ravel().tolist() == [4]
