"""Refined surveys end to end: the cells a [refine] table adds, the same archive whatever
the workers, chunks or interruptions, verify, the report, and refused configs."""
import numpy as np
import pytest
import xarray as xr

from survey.analysis.refine import known_from, plan
from survey.catalog.errors import ConfigError
from survey.catalog.regimes import IRREGULAR, REGULAR
from survey.catalog.variables import V
from survey.pipeline.config import load_config
from survey.pipeline.sweep import run_survey, verify
from survey.presentation import report

from test_faults import interrupt_after, same_data

# the equilateral family across its onset at T = 300: tori up to 4.25, chaos from 4.3125
# (measured here: the grid's 4.0 / 4.5 pair is bisected three times)
REFINED = """
[survey]
name = "{name}"
output = "{out}"
[initial]
family = "equilateral"
delta = {{start = 3.5, stop = 5.0, num = 4}}
[integration]
t_final = 300.0
[indicators]
perturbations = 0
history_points = 8
[refine]
max_level = 3
[dask]
workers = {workers}
chunk_size = {chunk}
"""


def config(tmp_path, name="r", workers=1, chunk=0, extra=""):
    path = tmp_path / f"{name}.toml"
    path.write_text(REFINED.format(name=name, out=tmp_path / f"{name}.nc", workers=workers,
                                   chunk=chunk) + extra)
    return path


@pytest.fixture(scope="module")
def refined(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("refined")
    return run_survey(config(tmp))


def test_the_boundary_is_bisected_and_the_cells_lie_along_one_dimension(refined):
    with xr.open_dataset(refined) as ds:
        assert ds[V.regime].dims == ("cell",)
        delta, level = ds["delta"].values, ds["level"].values
        assert np.all(np.diff(delta) > 0) and np.all(np.diff(ds["cell"].values) > 0)
        assert np.array_equal(delta[level == 0], [3.5, 4.0, 4.5, 5.0])
        regular = np.isin(ds[V.regime].values, REGULAR)
        irregular = np.isin(ds[V.regime].values, IRREGULAR)
        assert regular[0] and irregular[-1]
        # one boundary, bisected to the last level: the last regular and the first
        # irregular cell are the finest step apart
        last, first = np.flatnonzero(regular)[-1], np.flatnonzero(irregular)[0]
        assert first == last + 1
        assert delta[first] - delta[last] == pytest.approx(0.5 / 2 ** 3)
        assert ds.sizes["cell"] == 4 + 3
        # the cells are the plan of their own results
        cfg = load_config(config(refined.parent, "again"))
        known = known_from(ds["cell"].values, ds[V.regime].values,
                           np.full(ds.sizes["cell"], np.nan))
        p = plan(cfg.lattice(), cfg.rule(), known)
        assert p.done and np.array_equal(p.cells, ds["cell"].values)


def test_the_same_archive_whatever_the_workers_and_chunks(refined, tmp_path):
    other = run_survey(config(tmp_path, "w2", workers=2, chunk=1))
    with xr.open_dataset(refined) as a, xr.open_dataset(other) as b:
        same_data(a, b)


def test_an_interrupted_refinement_resumes_to_the_same_archive(refined, tmp_path,
                                                               monkeypatch):
    cfg = config(tmp_path, "stop", chunk=1)
    interrupt_after(monkeypatch, 5)      # the grid's 4 cells and the first bisection
    with pytest.raises(KeyboardInterrupt):
        run_survey(cfg)
    monkeypatch.undo()
    with xr.open_dataset(refined) as a, xr.open_dataset(run_survey(cfg)) as b:
        same_data(a, b)


def test_verify_recomputes_cells_and_the_refinement(refined, tmp_path):
    ok, lines = verify(refined, cells=3)
    assert ok, lines
    assert "by their lattice index" in lines[0]
    # an archive without one of the cells its regimes call for
    with xr.open_dataset(refined) as ds:
        keep = np.flatnonzero(ds["level"].values < 3)
        ds.isel(cell=keep).load().to_netcdf(tmp_path / "cut.nc")
    ok, lines = verify(tmp_path / "cut.nc", cells=2)
    assert not ok and any("not the refinement its regimes call for" in x for x in lines)


def test_the_report_gives_the_boundary_from_the_bisection(refined, tmp_path):
    with xr.open_dataset(refined) as ds:
        text = report.markdown(ds)
    assert "## Refinement" in text and "level 3: 1" in text
    assert "| 4.25 | 4.3125 | 4.28125 | 0.031 | irregular | 3 |" in text
    assert "half the interval the bisection ended with" in text


AXIS = "delta = {start = 3.5, stop = 5.0, num = 4}"


@pytest.mark.parametrize("extra, edit, key, message", [
    ("", (AXIS, "delta = 3.0"), "[refine]", "one or two axes"),
    ("indicator = \"megno\"\n", None, "[refine].jump", "the change that splits"),
    ("jump = 0.1\n", None, "[refine].jump", "needs an indicator"),
    ("indicator = \"sali\"\njump = 0.1\n", ("[indicators]\n", "[indicators]\nwhich = "
                                            "[\"ftle\", \"megno\"]\n"),
     "[refine].indicator", "add 'sali'"),
    ("indicator = \"ftle\"\nratio = 0.5\n", None, "[refine].ratio", "a factor above 1"),
    ("max_cells = 3\n", None, "[refine].max_cells", "below the 4 cells"),
    ("by = \"verdict\"\n", None, "[refine].by", "is not one of"),
    ("tolerance = 0.01\n", ("[initial]\n", "[initial]\nenergy = [80.0, 90.0]\n"),
     "[refine].tolerance", "applies to one axis"),
])
def test_refinement_configs_that_cannot_work_are_refused(tmp_path, extra, edit, key,
                                                         message):
    text = REFINED.format(name="bad", out=tmp_path / "bad.nc", workers=1, chunk=0)
    text = text.replace("[refine]\n", "[refine]\n" + extra)
    if edit:
        text = text.replace(*edit)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert err.value.key == key and message in str(err.value)


@pytest.mark.parametrize("axis, message", [
    ("delta = [4.0, 3.5, 5.0]", "must be increasing"),
    ("delta = [4.0]", "at least two values"),
])
def test_refined_axes_must_be_intervals(tmp_path, axis, message):
    text = REFINED.format(name="bad", out=tmp_path / "bad.nc", workers=1, chunk=0)
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(AXIS, axis))
    with pytest.raises(ConfigError, match=message):
        load_config(path)


def test_seeded_starts_are_not_refined(tmp_path):
    path = tmp_path / "seeds.toml"
    path.write_text("[initial]\nfamily = \"microcanonical\"\nenergy = {start = -2.0, stop = "
                    "-1.0, num = 3}\nstarts_per_cell = 4\n[refine]\n")
    with pytest.raises(ConfigError, match="a sample, not a place to bisect"):
        load_config(path, check_output=False)


@pytest.mark.parametrize("lanes", [4, 8, 16, 32])
@pytest.mark.parametrize("cells, workers, per_cell", [(63, 2, 1), (5, 2, 1), (148, 2, 1),
                                                       (7, 2, 17), (1, 2, 17), (400, 8, 3)])
def test_refinement_batches_keep_every_worker_fed(monkeypatch, cells, workers, per_cell,
                                                   lanes):
    """A batch of new cells goes out in at least one task per worker (where it has as many
    cells), each holding a round of SIMD lanes of orbits where the batch has them, for
    every lane width."""
    from survey.pipeline import sweep
    monkeypatch.setattr(sweep, "SIMD_LANES", lanes)
    tasks = sweep._chunks(np.arange(cells), sweep.refined_chunk_count(cells, workers,
                                                                      per_cell))
    assert len(tasks) >= min(cells, workers)
    assert sum(t.size for t in tasks) == cells
    if cells * per_cell >= lanes * workers:
        assert min(t.size for t in tasks) * per_cell >= lanes


@pytest.mark.parametrize("lanes", [4, 8, 16, 32])
@pytest.mark.parametrize("cells, workers, per_cell", [(300, 2, 1), (401, 2, 1), (1001, 2, 1),
                                                       (9, 2, 18), (20, 3, 18), (5000, 2, 3),
                                                       (5, 4, 1), (3, 2, 18)])
def test_a_grid_goes_out_in_full_waves_of_tasks(monkeypatch, cells, workers, per_cell, lanes):
    """A grid of a few tasks a worker goes out in a multiple of the workers (where it has
    as many cells), tasks alike in size (no last wave where some workers idle), each of at
    least two rounds of SIMD lanes of orbits where the grid has four for every worker --
    for every SIMD lane width the code supports (16 lanes once gave 9 cells 3 tasks on 2
    workers)."""
    from survey.pipeline import sweep
    monkeypatch.setattr(sweep, "SIMD_LANES", lanes)
    tasks = sweep._chunks(np.arange(cells), sweep.chunk_count(cells, workers, per_cell))
    assert sum(t.size for t in tasks) == cells
    assert max(t.size for t in tasks) - min(t.size for t in tasks) <= 1
    if len(tasks) < 8 * workers and cells >= workers:
        assert len(tasks) % workers == 0
    if cells * per_cell >= 4 * lanes * workers:     # at least two rounds a task
        assert min(t.size for t in tasks) * per_cell >= 2 * lanes


def test_a_moment_without_workers_still_chunks():
    """Every worker restarting at once (the scheduler then lists none) is not a division by
    zero: the batch goes out as for one worker."""
    from survey.pipeline.sweep import chunk_count, refined_chunk_count
    assert refined_chunk_count(40, 0, 1) == refined_chunk_count(40, 1, 1)
    assert chunk_count(40, 0, 1) == chunk_count(40, 1, 1)


def test_a_refined_map_is_written_verified_drawn_and_reported(tmp_path):
    """Two axes: the squares whose corners disagree are split; the archive holds the cells
    along `cell` with both parameters, verify passes, the regime map is drawn (painted by
    level) and the report gives the onset along delta for the grid's energies."""
    from survey.analysis.classify import summary
    from survey.presentation import plots
    text = REFINED.format(name="map", out=tmp_path / "map.nc", workers=2, chunk=0)
    text = text.replace(AXIS, AXIS + "\nenergy = [80.0, 100.0]").replace(
        "max_level = 3", "max_level = 2")
    path = tmp_path / "map.toml"
    path.write_text(text)
    out = run_survey(path)
    with xr.open_dataset(out) as ds:
        assert ds[V.regime].dims == ("cell",) and ds["energy"].dims == ("cell",)
        assert ds.sizes["cell"] > 8 and ds["level"].max() == 2
        figs = plots.figures(ds)
        assert "map_regime" in figs and "scan" not in figs
        rows, _ = np.unique(ds["energy"].values, return_counts=True)
        text = report.markdown(ds)
        assert len(summary(ds)) == 1          # counts only: no boundaries along `cell`
    assert "## Where chaos sets in along delta, for each energy" in text
    assert "| 80 |" in text and "| 100 |" in text and rows.size > 2
    ok, lines = verify(out, cells=3)
    assert ok, lines


def test_cells_in_doubt_are_dealt_so_no_worker_ends_alone():
    """deal_doubts: while chunks wait, the cells in doubt are held until they make a round
    of lanes (or 2 chunks a worker wait for theirs), then go out together; at the end a
    free worker takes its share, the rest waits for the worker still running a chunk;
    once nothing runs, every worker gets a share -- costliest first, each cell once."""
    from survey.pipeline.sweep import deal_doubts
    held = [(10, 0, 1), (30, 0, 4), (20, 5, 2)]        # (cost, chunk, row)
    never = lambda: pytest.fail("free workers asked for while chunks wait")   # noqa: E731
    # chunks wait: too few cells, from too few chunks, to go out yet
    assert deal_doubts(held, 8, 2, 2, 5, False, never) == ([], sorted(held, reverse=True))
    # a round of lanes' worth: all, in tasks of about one round each, ahead of the chunks
    many = [(c, c % 4, c) for c in range(20)]
    tasks, kept = deal_doubts(many, 8, 2, 2, 5, False, never)
    assert kept == [] and len(tasks) == 3 and all(w is None for _, w in tasks)
    dealt = sorted(x for cells, _ in tasks for x in cells)
    assert dealt == sorted((c % 4, c) for c in range(20))
    assert tasks[0][0][0] == (19 % 4, 19)                # the costliest first
    # 2 chunks a worker wait for theirs: out, though fewer than a round
    spread = [(c, c, 0) for c in range(4)]
    assert deal_doubts(spread, 8, 2, 2, 5, False, never)[1] == []
    # the end: one worker free, another running the last chunk -- half now, half kept
    tasks, kept = deal_doubts(held, 8, 2, 2, 1, False, lambda: ["a"])
    assert [w for _, w in tasks] == ["a"] and tasks[0][0] == [(0, 4), (0, 1)]
    assert kept == [(20, 5, 2)]
    # that worker's chunk returns: it takes all that is left (no lone last cell)
    tasks, kept = deal_doubts(kept + [(5, 7, 3)], 8, 2, 2, 0, False, lambda: ["b"])
    assert tasks == [([(5, 2), (7, 3)], "b")] and kept == []
    # nothing runs: a share for each thread
    tasks, kept = deal_doubts(held, 8, 2, 2, 0, True, never)
    assert kept == [] and [len(cells) for cells, _ in tasks] == [2, 1]
