"""Malformed configs: each is answered before any work with one line naming the key, and
exit code 2 (no traceback)."""
import subprocess
import sys

import pytest

from survey.catalog.errors import ConfigError
from survey.cli import main
from survey.pipeline.config import load_config, parse_config

GOOD = """
[survey]
name = "t"
output = "{out}"
[system]
potential = "perimetric_power"
[initial]
family = "equilateral"
delta = {{start = 0.0, stop = 1.0, num = 2}}
[integration]
t_final = 1.0
[section]
coordinate = "phi"
"""

# (what to change, expected fragment of the error: always the key)
HH = "[system]\nbodies = 1\ninteractions = [{kind = 'external', expression = 'x**2 + y**2'}]\n[initial]\nfamily = 'field_section'\nenergy = 1.0\n"
BAD = [
    ("[outcomes]\nexits = [90.0]", "[outcomes].exits: are the exits of an external field's potential"),
    (HH + "[outcomes]\nexits = [90.0, 210.0]", "[outcomes].exits: need escape_radius"),
    (HH + "[outcomes]\nescape_radius = 3.0\nexits = []", "[outcomes].exits: give at least one direction"),
    (HH + "[outcomes]\nescape_radius = 3.0\nescape_binding = 0.1", "[outcomes].escape_binding: bounds what other bodies pull"),
    ("[outcomes]\nescape_radius = 5.0", "[outcomes].escape_binding: cannot be derived for this system"),
    ("[outcomes]\nthin = 0.0", "[outcomes].thin: must be > 0"),
    ("[outcomes]\nescape_radius = -1.0", "[outcomes].escape_radius: must be >= 0"),
    ("[check]\nseed = 0\nperturbations = 16\nnudge = 0.0\nvariants = [\"seed\"]", "[check]: the same seed, perturbations and nudge as [indicators] would repeat the survey"),
    ("[check]\nperturbations = -2", "[check].perturbations: must be >= -1"),
    ("[check]\nsed = 1", "[check].sed: unknown key (did you mean 'seed'?)"),
    ("[indicators]\nwhich = []\n[check]", "[check]: compares the indicators of two ensembles"),
    ("[check]\nvariants = []", "[check].variants: names each variant once and at least one of seed"),
    ("[check]\nvariants = [\"seed\", \"seed\"]", "[check].variants: names each variant once"),
    ("[check]\nvariants = [\"sed\"]", "[check].variants"),
    ("[check]\nvariants = [\"rounding\"]\nnudge = 0.0", "[check].nudge: equals [indicators].nudge, so the rounding variant"),
    ("[check]\ntolerance = 1.0", "[check].tolerance: must be >= 2"),
    ("[periodic]\nperiod = 6.0", "[periodic]: is read by `python -m survey periodic`, not by a survey"),
    ("[tori]\nextend = 1", "[tori].extend: 1 would decide a verdict in doubt again at the same horizon"),
    ("[tori]\nextend = -2", "[tori].extend: must be >= 0"),
    ("[tori]\nextend_rounds = 9", "[tori].extend_rounds: must be <= 4"),
    ("[sytem]\nbodies = 3", "[sytem]: unknown table (did you mean 'system'?)"),
    ("[system]\nmass = [1, 1, 1]", "[system].mass: unknown key (did you mean 'masses'?)"),
    ("[system]\nmasses = 'abc'", "[system].masses: expected a list of numbers"),
    ("[system]\nmasses = [1.0, -1.0, 1.0]", "[system].masses: must be >= 1e-100"),
    ("[system]\nmasses = [1.0, 0.0, 1.0]", "[system].masses: must be >= 1e-100"),
    ("[system]\nmasses = [1.0, 1.0]", "[system].masses: needs 3 values"),
    ("[system]\nbodies = 2", "[system].bodies: a system with a triplet term needs masses for N >= 3 bodies"),
    ("[system]\nbodies = 0", "[system].bodies: must be >= 1"),
    ("[tori]\nobservables = ['x']", "[tori].observables: 'x' is the centre of mass's coordinate, which moves uniformly"),
    ("[section]\ncoordinate = 'y'", "[section].coordinate: 'y' is the centre of mass's coordinate"),
    ("[system]\nbodies = 1\ninteractions = [{kind = 'external', expression = 'x**2 + y**2'}]\n[initial]\nfamily = 'field_section'\nenergy = 1.0\n[tori]\nobservables = ['inertia']", "[tori].observables: 'inertia' is a shape's, and one body has none"),
    ("[reference]\nsource = 'HH'\nat = [0.5]\nregular_share = [1.0]", "[reference]: compares published regular shares with a sample of seeded starts along one axis"),
    ("[system]\nbodies = 1\ninteractions = [{kind = 'external', expression = 'x**2 + y**2'}]\n[initial]\nfamily = 'field_section_sample'\nenergy = [0.5, 1.0]\nstarts_per_cell = 4\n[section]\ncoordinate = 'x'\n[reference]\nsource = 'HH'\nat = [0.7]\nregular_share = [1.0]", "[reference].at: 0.7 is not a value of the axis energy"),
    ("[system]\nbodies = 1\ninteractions = [{kind = 'external', expression = 'x**2 + y**2'}]\n[initial]\nfamily = 'field_section_sample'\nenergy = [0.5, 1.0]\nstarts_per_cell = 4\n[section]\ncoordinate = 'x'\n[reference]\nsource = 'HH'\nat = [0.5]\nregular_share = [1.0, 0.5]", "[reference].regular_share: needs one value per entry of at"),
    ("[system]\nbodies = 1\ninteractions = [{kind = 'external', expression = 'x**2 + y**2'}]\n[initial]\nfamily = 'field_section_sample'\nenergy = [0.5, 1.0]\nstarts_per_cell = 4\n[section]\ncoordinate = 'x'\nmax_crossings = 10\n[reference]\nsource = 'HH'\nat = [0.5]\nregular_share = [1.0]\ncrossings = 25\ngrowth = 1e5", "[reference].crossings: 25 crossings are more than [section] max_crossings = 10 keeps"),
    ("[system]\ninteractions = [{kind = 'triplet', expression = 'a**2 * b'}]", "[system].interactions[0].expression: is not symmetric in the sides: exchanging a and b"),
    ("[system]\ninteractions = [{kind = 'triplet', expression = \"P + __import__('os')\"}]", "[system].interactions[0].expression: unexpected \"'\" at character 16 (strings are not allowed)"),
    ("[system]\ninteractions = [{kind = 'triplet', expression = 'P.real'}]", "[system].interactions[0].expression: unexpected '.' at character 2 (attribute access is not allowed)"),
    ("[system]\ninteractions = [{kind = 'triplet', expression = 'system(P)'}]", "[system].interactions[0].expression: system(...) at character 1 is not a function a formula may call"),
    ("[system]\ninteractions = [{kind = 'triplet', expression = '%s'}]" % ("P+" * 1500 + "P"), "[system].interactions[0].expression: is 3001 characters long; a formula may have at most 2000"),
    ("[system]\ninteractions = [{kind = 'triplet', expression = 'k * P**2', params = {q = 1.0}}]", "[system].interactions[0].expression: unknown name 'k' at character 1"),
    ("[system]\ninteractions = [{kind = 'triplet', expression = 'P**2', mass_weighted = true}]", "[system].interactions[0].mass_weighted: mass_weighted applies to pair and external terms"),
    ("[system]\ninteractions = [{kind = 'triplet', expression = 'k * P**2', params = {k = 'two'}}]", "[system].interactions[0].params.k"),
    ("[system]\ninteractions = [{kind = 'triplet', potential = 'perimetric_power', expression = 'P**2'}]", "[system].interactions[0].potential: give potential (a built-in term) or expression (a formula), not both"),
    ("[system]\ninteractions = [{kind = 'external', potential = 'power', params = {}}]", "[system].interactions[0].kind: 'external' is not one of 'pair', 'triplet' (an external field is written as a formula"),
    ("[system]\ninteractions = [{kind = 'quartet', expression = 'P'}]", "[system].interactions[0].kind: 'quartet' is not one of 'pair', 'triplet', 'external' (the kinds a formula may be)"),
    ("[system]\nbodies = true", "[system].bodies: expected an integer"),
    ("[system]\ndim = 4", "[system].dim: 4 is not one of 2, 3"),
    ("[system]\npotential = 'perimetric_cubic'", "[system].potential: unknown triplet potential 'perimetric_cubic'"),
    ("[system]\nparams = {k = 2}", "[system.params].k: not a parameter of perimetric_power"),
    ("[system]\npotential = 'perimetric_yukawa'\nparams = {gamma = -1.0}", "[system.params].gamma: potential parameter 'gamma' must be >= 0"),
    ("[system]\npotential = 'lennard_jones'", "[system].potential: 'lennard_jones' is a pair potential; potential takes one triplet term"),
    ("[system]\npotential = 'areal_power'\ninteractions = [{kind = 'pair', potential = 'power', params = {coupling = 1.0, exponent = -1.0}}]", "[system].potential: give either potential/params (one triplet term) or interactions"),
    ("[system]\ninteractions = [{kind = 'pairs', potential = 'lennard_jones', params = {epsilon = 1.0, sigma = 1.0}}]", "[system].interactions[0].kind: 'pairs' is not one of 'pair', 'triplet' (did you mean 'pair'?)"),
    ("[system]\ninteractions = [{potential = 'lennard_jones', params = {epsilon = 1.0, sigma = 1.0}}]", "[system].interactions[0].kind: is required"),
    ("[system]\ninteractions = [{kind = 'pair', potential = 'axilrod_teller', params = {strength = 1.0}}]", "[system].interactions[0].potential: unknown pair potential 'axilrod_teller'; choose one of lennard_jones, yukawa, power, gravity ('axilrod_teller' is a triplet potential: give it kind = \"triplet\")"),
    ("[system]\ninteractions = [{kind = 'triplet', potential = 'lennard_jones', params = {epsilon = 1.0, sigma = 1.0}}]", "[system].interactions[0].potential: unknown triplet potential 'lennard_jones'"),
    ("[system]\ninteractions = [{kind = 'pair', potential = 'lenard_jones', params = {epsilon = 1.0, sigma = 1.0}}]", "(did you mean 'lennard_jones'?)"),
    ("[system]\ninteractions = [{kind = 'pair', potential = 'lennard_jones', params = {epsilon = 1.0}}]", "[system].interactions[0].params.sigma: is missing"),
    ("[system]\ninteractions = [{kind = 'pair', potential = 'lennard_jones', params = {epsilon = 1.0, sigma = -2.0}}]", "[system].interactions[0].params.sigma: potential parameter 'sigma' must be > 0"),
    ("[system]\ninteractions = [{kind = 'pair', potential = 'lennard_jones', params = {epsilon = [1.0, 0.0], sigma = 1.0}}]", "[system].interactions[0].params.epsilon: potential parameter 'epsilon' must be > 0 (a well depth), got 0 (at the grid value 0)"),
    ("[system]\ninteractions = [{kind = 'triplet', potential = 'axilrod_teller', params = {strength = 1.0}, mass_weighted = true}]", "[system].interactions[0].mass_weighted: applies to pair terms only"),
    ("[system]\ninteractions = [{kind = 'pair', potential = 'power', params = {coupling = 1.0, exponent = -1.0}, mass_weighted = 1}]", "[system].interactions[0].mass_weighted: expected true or false, got 1"),
    ("[system]\ninteractions = [{kind = 'pair', potential = 'power', params = {coupling = 1.0, exponent = -1.0}, mass_weigted = true}]", "[system].interactions[0].mass_weigted: unknown key (did you mean 'mass_weighted'?)"),
    ("[system]\ninteractions = [{kind = 'pair', potential = 'yukawa', params = {coupling = 1.0, gama = 1.0}}]", "[system].interactions[0].params.gama: not a parameter of yukawa (did you mean 'gamma'?)"),
    ("[system]\ninteractions = []", "[system].interactions: expected a list of tables"),
    ("[system]\ninteractions = [{kind = 'triplet', potential = 'axilrod_teller', params = {strength = [0.1, 0.2]}}, {kind = 'pair', potential = 'lenard_jones', params = {epsilon = 1.0, sigma = 1.0}}]", "[system].interactions[1].potential: unknown pair potential 'lenard_jones'"),
    ("[integration]\nrtol = 0.0", "[integration].rtol: must be >= 2.22e-15"),
    ("[integration]\nrtol = -1e-9", "[integration].rtol: must be >= 2.22e-15"),
    ("[integration]\nrtol = 1e-16", "double precision cannot honour"),
    ("[integration]\nrtol = 1.0", "[integration].rtol: must be <= 0.001, got 1.0"),
    ("[integration]\natol = 1.0", "[integration].atol: must be <= 0.001, got 1.0; a looser tolerance"),
    ("[indicators]\nperturbations = 1000000", "[indicators].perturbations: must be <= 1e+03"),
    ("[indicators]\ndeviations = 1000000", "[indicators].deviations: must be <= 64"),
    ("[indicators]\ndeviations = 13", "[indicators].deviations: 13 deviation vectors in a 12-dimensional phase space cannot be independent; use at most 12"),
    ("[dask]\nretries = 1000000000", "[dask].retries: must be <= 100"),
    ("[dask]\nworkers = 1000", "[dask].workers: must be <= 512, got 1000; more workers than cores only queue"),
    ("[integration]\natol = 'tight'", "[integration].atol: expected a number"),
    ("[integration]\nt_final = 0.0", "[integration].t_final: must be > 0"),
    ("[integration]\nt_final = -5.0", "[integration].t_final: must be > 0"),
    ("[integration]\nt_final = nan", "[integration].t_final: must be finite"),
    ("[integration]\nmax_steps = 0", "[integration].max_steps: must be >= 1"),
    ("[integration]\ncell_time_limit = -1.0", "[integration].cell_time_limit: must be >= 0"),
    ("[initial]\ndelta = 1.0", "[initial].family: is required"),
    ("[initial]\nfamily = 'equilateal'", "[initial].family: 'equilateal' is not one of"),
    ("[initial]\nfamily = 'equilateral'\ndelt = 1.0", "[initial].delt: not a parameter of family 'equilateral' (did you mean 'delta'?)"),
    ("[initial]\nfamily = 'equilateral'\ndelta = {start = 0, stop = 1, num = 0}", "[initial].delta.num: must be an integer >= 1"),
    ("[initial]\nfamily = 'equilateral'\ndelta = {start = 0, num = 3}", "[initial].delta: a grid axis needs num, start, stop; stop is missing"),
    ("[initial]\nfamily = 'equilateral'\ndelta = {start = 0, stop = 1, num = 3, step = 1}", "[initial].delta.step: a grid axis takes only start, stop, num"),
    ("[initial]\nfamily = 'equilateral'\ndelta = []", "[initial].delta: a grid axis list needs finite numbers"),
    ("[initial]\nfamily = 'equilateral'\ndelta = [1.0, 'x']", "[initial].delta: a grid axis list needs finite numbers"),
    ("[initial]\nfamily = 'equilateral'\ndelta = [1.0, 1.0]", "[initial].delta: grid axis values must be distinct"),
    ("[initial]\nfamily = 'equilateral'\ndelta = 'three'", "[initial].delta: expected a number, a list or {start, stop, num}"),
    ("[initial]\nfamily = 'sides'\na = 5.0", "[initial]: sides (a, b, c) = (5, 2, 1.8) do not make a non-degenerate triangle"),
    ("[initial]\nfamily = 'sides'\na = {start = 1.0, stop = 5.0, num = 3}", "[initial] at a = 5: sides"),
    # inside the grid: found by the worker building that chunk's starts
    ("[initial]\nfamily = 'sides'\na = [1.0, 5.0, 2.0]", "[initial] at a = 5: sides"),
    ("[initial]\nfamily = 'linear'\nvelocity_u = [1.0, 2.0, 3.0]", "[initial].velocity_u: expected finite numbers shaped like [1.5, -10.0711]"),
    ("[survey]\noutput = '/proc/no/such/x.nc'", "[survey].output: cannot write to /proc/no/such"),
    ("[survey]\noutput = 'tests'", "[survey].output: tests is a folder; give a file name"),
    ("[section]\ncoordinate = 'psi'", "[section].coordinate: 'psi' is not one of"),
    ("[section]\ndirection = 2", "[section].direction: 2 is not one of -1, 0, 1"),
    ("[section]\ncoordinate = 'p_sigma'\nvalue = 1.0", "[section]: section p_sigma = 1.0: only p_sigma = 0"),
    ("[section]\nmax_crossings = 0", "[section].max_crossings: must be >= 1"),
    ("[section]\ntriplet = [0, 0, 1]", "[section].triplet: needs three different bodies"),
    ("[section]\ncoordinate = 'linear'", "[section].coefficients: a 'linear' surface needs 12 coefficients"),
    ("[system]\ndim = 3\n[section]\ncoordinate = 'phi'", "[section].coordinate: 'phi' is a reduced coordinate"),
    ("[indicators]\nwhich = ['lyapunov']", "[indicators].which: 'lyapunov' is not one of"),
    ("[indicators]\ndeviations = 1", "[indicators].deviations: sali and gali2 need 2 deviation vectors"),
    ("[indicators]\nrenorm_interval = 5.0", "[indicators].renorm_interval: is longer than t_final"),
    ("[indicators]\nperturbation_size = 0.0", "[indicators].perturbation_size: must be > 0"),
    ("[dask]\nworkers = 0", "[dask].workers: must be >= 1"),
    ("[dask]\nchunk_size = -1", "[dask].chunk_size: must be >= 0"),
    ("[dask]\nchunksize = 4", "[dask].chunksize: unknown key (did you mean 'chunk_size'?)"),
    ("[tori]\ndigits_regular = 1.0\ndigits_chaotic = 9.0", "[tori].digits_regular: 1.0 must be at or above digits_chaotic = 9.0"),
    ("[tori]\nmegno_regular = 4.0", "[tori].megno_regular: 4.0 must be at or below megno_chaotic = 3.0"),
    ("[tori]\nresonance_order = 1000000", "[tori].resonance_order: 1000000 would compare every orbit with 6.67e+17 integer vectors (|m|_1 <= order over 3 shape frequencies); at most 1e+06: use at most 113"),
    ("[tori]\nresonance_width = -1e-7", "[tori].resonance_width: must be >= 0"),
    ("system = 3", "[system]: must be a table"),
    ("[system\nbodies = 3", "not valid TOML"),
]


def merged(change: str, out: str) -> str:
    """GOOD with the tables in `change` replacing or extending those in GOOD."""
    import tomllib
    base = tomllib.loads(GOOD.format(out=out))
    try:
        extra = tomllib.loads(change)
    except tomllib.TOMLDecodeError:
        return GOOD.format(out=out) + "\n" + change
    scalars = {k: v for k, v in extra.items() if not isinstance(v, dict)}
    if scalars:   # a top-level value where a table belongs: write it raw, drop the table
        for k in scalars:
            base.pop(k, None)
        from survey.pipeline.config import _to_toml
        return "\n".join(f"{k} = {v!r}" for k, v in scalars.items()) + "\n" + _to_toml(base)
    for table, body in extra.items():
        if table == "initial":
            base[table] = body
        elif isinstance(body, dict) and isinstance(base.get(table), dict):
            if "interactions" in body and "potential" not in body:   # the one or the other
                base[table].pop("potential", None)
            base[table].update(body)
        else:
            base[table] = body
    from survey.pipeline.config import _to_toml
    return _to_toml(base)


def test_there_are_at_least_thirty_malformed_configs():
    assert len(BAD) >= 30


def test_the_good_config_is_good(tmp_path):
    cfg = tmp_path / "good.toml"
    cfg.write_text(GOOD.format(out=tmp_path / "x.nc"))
    assert load_config(cfg).n_cells == 2


@pytest.mark.parametrize("change,message", BAD, ids=[m.split(":")[0] for _, m in BAD])
def test_malformed_config_is_one_line_with_the_key_and_exit_code_2(tmp_path, capsys, change,
                                                                     message):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(merged(change, str(tmp_path / "x.nc")))
    assert main([str(cfg), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("error: ")
    assert message in err, err
    assert not (tmp_path / "x.nc").exists()


def test_cli_process_exits_2_without_traceback(tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(merged("[integration]\natol = 0.0", str(tmp_path / "x.nc")))
    for argv in ([str(cfg)], ["run", str(tmp_path / "missing.toml")],
                 [str(cfg), "--workers", "0"]):
        proc = subprocess.run([sys.executable, "-m", "survey", *argv], capture_output=True,
                              text=True, timeout=120)
        assert proc.returncode == 2, proc.stderr
        assert "Traceback" not in proc.stderr and proc.stderr.startswith("error: ")


def test_config_values_are_data_not_code(tmp_path, capsys):
    cfg = tmp_path / "evil.toml"
    cfg.write_text(merged("[initial]\nfamily = \"__import__('os').system('touch pwned')\"",
                          str(tmp_path / "x.nc")))
    assert main([str(cfg)]) == 2
    assert not (tmp_path / "pwned").exists()


def test_shipped_workflows_and_the_embedded_default_validate():
    import pathlib
    root = pathlib.Path(__file__).parents[2]
    from survey.pipeline import orbits, families
    paths = sorted((root / "workflows").glob("*.toml")) + [root / "survey" / "default.toml"]
    assert len(paths) >= 4
    for path in paths:
        if families.special_table(path) == "equilibria":
            assert families.load_equilibria(path)
        elif families.special_table(path) == "periodic":
            assert families.load_periodic(path)
        elif orbits.is_orbit_workflow(path):
            assert orbits.load_workflow(path)
        else:
            assert load_config(path).n_cells >= 1


def test_more_local_workers_than_the_machine_can_run_are_refused_before_work_starts():
    import os

    from survey.pipeline.sweep import run_survey
    too_many = 4 * (os.cpu_count() or 1) + 1
    text = f'[initial]\nfamily = "equilateral"\ndelta = [1.0]\n[dask]\nworkers = {too_many}\n'
    with pytest.raises(ConfigError, match=r"\[dask\]\.workers: .* use at most"):
        parse_config(text, "t")
    with pytest.raises(ConfigError, match="workers: .* use at most"):
        run_survey({"initial": {"family": "equilateral", "delta": [1.0]}}, workers=too_many)


def test_check_variants_are_the_same_survey_with_one_thing_changed(tmp_path):
    """[check] runs four variants by default, each its own config text and archive
    <output>_check_<variant>.nc (the output a --output override gives too), none changing
    the survey's own result key: seed -- the next seed, twice the ensemble (at least 8),
    the nominal starts nudged; rounding -- the nudge alone; horizon -- twice t_final;
    tolerance -- rtol and atol times 100."""
    text = GOOD.format(out=tmp_path / "x.nc")
    plain = parse_config(text)
    config = parse_config(text + "[check]\n")
    assert config.result_key() == plain.result_key()
    checks = config.checks()
    assert list(checks) == ["seed", "rounding", "horizon", "tolerance"]
    ind = {k: c.tables["indicators"] for k, c in checks.items()}
    integ = {k: c.tables["integration"] for k, c in checks.items()}
    mine_ind, mine = plain.tables["indicators"], plain.tables["integration"]
    assert (ind["seed"]["seed"], ind["seed"]["perturbations"], ind["seed"]["nudge"]) \
        == (1, 32, 1e-13)
    assert (ind["rounding"]["seed"], ind["rounding"]["perturbations"],
            ind["rounding"]["nudge"]) == (0, 16, 1e-13)
    assert integ["horizon"]["t_final"] == 2 * mine["t_final"]
    assert (integ["tolerance"]["rtol"], integ["tolerance"]["atol"]) == \
        (100 * mine["rtol"], 100 * mine["atol"])
    for k in ("seed", "rounding"):
        assert integ[k] == mine
    for k in ("horizon", "tolerance"):
        assert ind[k] == mine_ind
    keys = {config.result_key()}
    for variant, check in checks.items():
        assert check.name == f"t_check_{variant}"
        assert check.output == tmp_path / f"x_check_{variant}.nc"
        assert check.checks() == {}
        assert parse_config(check.text).result_key() == check.result_key()
        keys.add(check.result_key())
    assert len(keys) == 5 and plain.checks() == {}
    config.tables["survey"]["output"] = str(tmp_path / "elsewhere" / "y.nc")
    moved = config.checks()["seed"]
    assert moved.output == tmp_path / "elsewhere" / "y_check_seed.nc"
    assert moved.text == checks["seed"].text   # the text names the workflow's own output
    small = parse_config(text.replace("[integration]", "[indicators]\nperturbations = 2\n"
                                      "[integration]") + "[check]\nseed = 7\n"
                         "variants = [\"seed\"]\n").checks()
    assert list(small) == ["seed"]
    assert (small["seed"].tables["indicators"]["seed"],
            small["seed"].tables["indicators"]["perturbations"]) == (7, 8)