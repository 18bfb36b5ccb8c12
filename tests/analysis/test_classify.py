"""A verdict against its horizon: the regime decided at half a cell's horizon from its
histories, and whether the last verdict of a cell's history confirms the one before."""
import numpy as np

from survey.analysis.classify import Table, classify, stable, verdict_class
from survey.catalog.regimes import Regime, Thresholds
from survey.catalog.variables import V

R = Regime


def test_a_verdict_is_stable_when_its_class_is_that_of_the_horizon_before():
    history = np.array([[R.TORUS, R.TORUS, -1],          # regular at T/2 and T
                        [R.TORUS, R.RESONANT, -1],       # still regular: a detail changed
                        [R.TORUS, R.UNDETERMINED, R.CHAOTIC],   # decided at 4T: not yet
                        [R.UNDETERMINED, R.CHAOTIC, R.CHAOTIC],
                        [R.TORUS, R.STICKY, R.CHAOTIC],  # irregular both times
                        [R.COLLISION, R.COLLISION, -1]])
    np.testing.assert_array_equal(stable(history), [1, 1, 0, 1, 1, 1])
    assert list(verdict_class([R.PERIODIC, R.STICKY, R.UNDETERMINED, R.INACCESSIBLE])) \
        == [1, 2, 0, 0]


def test_the_verdict_at_half_the_horizon_comes_from_the_histories():
    """A cell regular by T/2 on every line and chaotic by T on every line is a torus at T/2
    and chaotic at T (a verdict that changed: the survey runs it longer); one chaotic at
    both is chaotic at both; a torus stays a torus."""
    T, th = 1000.0, Thresholds()
    times = np.linspace(T / 8, T, 8)
    lnT = lambda t: np.log(t) / t
    # per cell: (FTLE, <Y>, SALI, digits) at T/2, then at T
    cells = [((0.5 * lnT(T / 2), 1.9, 0.3, 8.0), (0.6 * lnT(T), 1.95, 0.2, 8.5)),
             ((0.5 * lnT(T / 2), 1.9, 0.3, 8.0), (9.0 * lnT(T), 12.0, 1e-10, 2.0)),
             ((9.0 * lnT(T / 2), 9.0, 1e-10, 2.0), (9.0 * lnT(T), 20.0, 1e-12, 2.0))]
    half, end = (np.array([c[k] for c in cells]) for k in (0, 1))
    histories = {name: np.full((3, times.size), np.nan) for name in
                 (V.ftle_history, V.megno_history, V.sali_history)}
    for column, name in enumerate(histories):
        histories[name][:, 3] = half[:, column]      # times[3] = T/2
        histories[name][:, -1] = end[:, column]
    table = Table({V.ftle: end[:, 0], V.megno: end[:, 1], V.sali: end[:, 2],
                   V.birkhoff_digits: end[:, 3], V.birkhoff_digits_half: half[:, 3],
                   V.t_end: np.full(3, T), V.regime_horizon: np.full(3, T),
                   V.status: np.zeros(3, np.int8), **histories}, history_time=times)
    at_half, confidence_half = classify(table, th, half=True)
    at_end, _ = classify(table, th)
    assert list(at_half) == [R.TORUS, R.TORUS, R.CHAOTIC]
    assert list(at_end) == [R.TORUS, R.CHAOTIC, R.CHAOTIC]
    np.testing.assert_array_equal(confidence_half, [1.0, 1.0, 1.0])


def test_the_onset_carries_its_shift_with_the_horizon():
    """Verdicts at T/2, T, 4T (-1: not run longer): the onset of the final verdicts, from
    each cell's verdict at each horizon, with an error covering its last shift."""
    from survey.analysis.onset import onset_over_horizons, verdicts_at
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    T, C, U = R.TORUS, R.CHAOTIC, R.UNDETERMINED
    history = np.array([[T, T, -1], [T, T, -1], [T, T, C], [U, C, C], [C, C, -1]])
    np.testing.assert_array_equal(verdicts_at(history, 1), [T, T, T, C, C])
    np.testing.assert_array_equal(verdicts_at(history, 2), [T, T, C, C, C])
    final = verdicts_at(history, 2)
    found = onset_over_horizons(x, final, history, [0.5, 1.0, 4.0])
    assert found["estimate"] == 2.5
    assert found["by_horizon"] == [(0.5, 4.0), (1.0, 3.5), (4.0, 2.5)]   # U is not chaos
    assert found["error"] == 1.0            # moved by 1 from T to 4T; half a step is 0.5
