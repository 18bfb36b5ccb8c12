"""The benchmark's parts in miniature: they run, and print the rows the performance issue
asks for (the speed numbers themselves are never asserted: they live in the bench)."""
import math
import re
import sys

import numpy as np
import pytest

from survey import bench


def test_bench_parts_run_and_print_their_ratios(tmp_path):
    lines = []
    bench.scan_vs_heyoka(cells=3, t_final=2.0, repeats=1, folder=str(tmp_path),
                         out=lines.append)
    bench.default_cell(t_final=2.0, repeats=1, folder=str(tmp_path), out=lines.append)
    # the cold run compiles every kernel into an empty cache (half a minute on 2 cores; the
    # portability test compiles them all cold already): its timer is checked on its own below
    bench.fixed_costs(folder=str(tmp_path), repeats=1, out=lines.append, cold=False,
                      commands=[("orbit", ["orbit", "--family", "sides", "--t-final", "1"])])
    rows = bench.interaction_terms(t_final=2.0, repeats=1, out=lines.append)
    assert all(r["same"] for r in rows)     # the two paths give the same orbit
    steps, plain, limit = bench.step_costs(t_final=2.0, repeats=1, lanes=(1, 16),
                                           out=lines.append)
    assert plain > 0 and "plain scalar code" in lines[-3]
    assert limit > 0 and "the machine's limit" in lines[-2] and "16 lanes" in lines[-2]
    assert re.search(r"probe that does only that arithmetic .* \d+ ns, \d+\.\d\dx the limit "
                     r".* \d+ divisions and \d+ square roots .* survey \d+\.\d\dx the probe",
                     lines[-1]), lines[-1]
    # the plain baseline integrates the orbit survey integrates (8 relative components)
    _, _, y, ref = bench.plain_step(t_final=20.0, repeats=1)
    assert np.max(np.abs(y - ref)) < 1e-9
    assert [(r[0], r[1], r[2]) for r in steps] == [(c[0], k, L) for c in bench.CASES
                                                   for k in (0, 1) for L in (1, 16)]
    assert all(r[3] > 0 and r[5] > 0 for r in steps)      # steps taken, RHS time measured
    busy = bench.refined_map(t_final=20.0, levels=1, folder=str(tmp_path), out=lines.append)
    assert busy["cells"] >= 63 and len(busy["idle"]) == 2
    rows, saved, peak = bench.survey_scale(sizes=(4, 12), t_final=1.0, first=40_000,
                                           folder=str(tmp_path), out=lines.append)
    assert [r[0] for r in rows] == [4, 12] and saved > 0 and peak > 0
    assert "first chunk saved" in lines[-1]
    # the smallest map's orbits, 18 a cell by default, against heyoka's batch mode
    assert "heyoka is not installed" in lines[-2] or (
        "the 4-cell map's 72 orbits" in lines[-2] and "heyoka's batch mode" in lines[-2])
    newton = bench.newton_step(repeats=1, out=lines.append)
    assert [r[1] >= 2 for r in newton] == [True, True]    # converged in a few shooting runs
    text = "\n".join(lines)
    assert "compute phase" in text and "cluster" in text and "archive" in text
    assert "python -m survey run" in text and "the same with [tori]" in text
    assert "heyoka is not installed" in text or ("survey / heyoka: compute" in text and
                                                 "largest energy error" in text and
                                                 "survey's default:" in text)
    # heyoka ran in the width it recommends and in this machine's, where they differ, and
    # the bench says which was the faster
    assert bench.vector_doubles() in (2, 4, 8)
    try:
        import heyoka
        widths = {heyoka.recommended_simd_size(), bench.vector_doubles()}
        assert ("the faster of" in text) == (len(widths) > 1)
    except ImportError:
        pass
    assert "same work as heyoka" in text and "by phase (default)" in text
    # the command line's fixed costs and the torus analysis's share, each on its own
    assert all(f"{phase} " in text for phase in ("interpreter", "imports", "prepare", "rest"))
    assert "the torus analysis (same work, in process): compute" in text
    assert "the analysis of the samples" in text and "the sampling" in text
    assert text.count("x\n") >= 1 and "Default survey cell" in text and "per orbit" in text
    assert "Where a step goes" in text and "stages+norm" in text
    assert "Newton shooting: one step" in text and "largest idle share" in text
    assert "general/own" in text and "Fixed costs" in text and "shutdown" in text and "python -m survey run" in text
    assert "warm " in text and "cold (every" not in text
    assert "Every command on a terminal" in text and re.search(
        r"\n  orbit +warm +\d+\.\d\d / +\d+\.\d\d / ", text)
    assert "longest silence of any command" in text


def test_the_cold_runs_timer_hears_a_terminals_first_word():
    """bench's `_timed_command` (the cold run's clock) gives the command a terminal for its
    stderr and times its first word there; a command that fails raises."""
    speak = [sys.executable, "-c", "import os, sys\nif os.isatty(2): sys.stderr.write('x')"]
    first, total, silence = bench.timed_command(speak)
    assert 0.0 < first <= total             # NaN (never spoke) fails
    assert first <= silence <= total
    quiet = bench.timed_command([sys.executable, "-c", "pass"])
    assert math.isnan(quiet[0]) and quiet[1] > 0.0
    fails = [sys.executable, "-c", "import sys; sys.stderr.write('why'); raise SystemExit(3)"]
    with pytest.raises(RuntimeError, match="exited with 3(.|\n)*why"):
        bench.timed_command(fails)


def test_a_command_the_bench_runs_that_fails_says_why():
    """A CI log then shows the command's own error, not only its exit code."""
    assert bench.common.checked([sys.executable, "-c", "print('out')"]) == "out\n"
    fails = [sys.executable, "-c", "import sys; sys.stderr.write('why'); raise SystemExit(3)"]
    with pytest.raises(RuntimeError, match="exited with 3(.|\n)*why"):
        bench.common.checked(fails)


def test_the_step_flop_count_counts_arithmetic_not_sign_flips():
    """step_flops counts by running code on numbers that count their arithmetic: a product,
    a quotient, a sum and a difference are four; a negation none; the paper's right-hand
    side with a tangent costs tens of operations an evaluation, a step's stage sums
    thousands (2m + 1 a component for a row of m terms)."""
    from survey.bench.steps import _Counted
    x = [_Counted(v) for v in (2.0, 3.0, 4.0)]
    _Counted.ops = 0
    y = x[0] * x[1] + x[2] / 3.0 - (-x[0])
    assert _Counted.ops == 4 and float(y) == 2.0 * 3.0 + 4.0 / 3.0 + 2.0
    rhs, sums = bench.step_flops()
    assert rhs % 12 == 0 and 40 < rhs // 12 < 200 and 1000 < sums < 5000
    # of them the divider's: the paper's right-hand side takes three side lengths (square
    # roots) and one reciprocal, of their product (physics.forces.reciprocals); the error
    # norm a division a component and one of each
    assert bench.divider_ops() == (12 * 1 + 8 + 1, 12 * 3 + 1)


def test_the_arithmetic_probe_takes_the_plain_step_in_every_lane():
    """The probe of a step's arithmetic alone (what the printed limit is checked against)
    computes the step: each of its lanes ends one step where the plain scalar DOP853 does,
    bit for bit; a probe that skipped a stage, a term or a lane would not."""
    from survey.bench.steps import _chaotic_start, _plain_dop853, arithmetic_probe
    ns, after = arithmetic_probe(lanes=16, repeats=1, h=1e-3, reps=1)
    _, _, z, _ = _chaotic_start()
    attempts, _, y = _plain_dop853(z, 1e-3, 1e-12, 1e-3)
    assert attempts == 1 and ns > 0 and after.shape == (16, 16)
    assert not np.array_equal(y, z)                         # the step moved the state
    for lane in after:
        assert np.array_equal(lane, y)


def test_the_memory_part_measures_a_survey_in_a_process_of_its_own(tmp_path):
    lines = []
    bench.survey_memory(sizes=(4,), folder=str(tmp_path), out=lines.append)
    assert re.match(r" +4 cells: peak RSS +\d+\.\d MiB, +\d+\.\d s, of which writing the "
                    r"archive +\d+\.\d s", lines[-1]), lines[-1]
