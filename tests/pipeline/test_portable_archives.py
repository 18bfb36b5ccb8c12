"""An archive verifies on a machine that is not the one that wrote it. The other machine is
made here by switching the code paths a CPU selects: numba compiling for the generic x86-64
target with FMA (which every x86-64 CPU since 2013 has; without it the integrator's fused
multiply-adds are libm's exact emulation: the same bits, ~100x slower), numpy without its AVX2/AVX-512 loops, glibc without its FMA/AVX2 libm, OpenBLAS's
oldest kernels. The orbit, the variational indicators, the sections and the torus analysis
must come out the same bits. So must the starts the families build (the N-body ones
descend to an equilibrium and remove rigid motions with linear algebra that LAPACK and
BLAS would round by the CPU), the reduced coordinates of section crossings (an arctan2),
and the families of periodic orbits and of relative equilibria."""
import os
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr
from foreign import FOREIGN, RUN, STARTS, WORKFLOWS, ForeignRun

from survey.catalog.variables import V
from survey.pipeline import archive
from survey.pipeline.sweep import run_survey, verify

CONFIG = """
[survey]
name = "portable"
output = "{out}"
[initial]
family = "equilateral"
delta = [1.5, 4.5]
[integration]
t_final = 300.0
[indicators]
perturbations = 1
[section]
max_crossings = 20
[dask]
workers = 1
"""


@pytest.fixture(scope="module")
def foreign(request):
    """The run on the other machine (tests/foreign.py), which the session started in the
    background at collection; started here if it did not."""
    run = request.config.stash.get(RUN, None)
    if run is None:
        run = request.config.stash[RUN] = ForeignRun()
    code, stderr = run.wait()
    assert code == 0, stderr
    return run


@pytest.mark.foreign
def test_starts_reduced_coordinates_and_periodic_families_are_the_same_bits_elsewhere(
        tmp_path, foreign):
    """Also the periodic families and a family of relative equilibria: their Newton
    corrections stop at the integrator's noise and their continuation steps by it, so a
    last bit of LAPACK's would change the members and where they bifurcate."""
    here = tmp_path / "here.npz"
    proc = subprocess.run([sys.executable, "-c", STARTS, str(here), str(WORKFLOWS)],
                          capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr
    with np.load(here) as a, np.load(foreign.result) as b:
        for name in a.files:
            x, y = a[name], b[name]
            assert np.isfinite(x).all() and x.tobytes() == y.tobytes(), \
                (name, np.max(np.abs(x - y)) if x.shape == y.shape else (x.shape, y.shape))


@pytest.fixture(scope="module")
def made_here(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("portable")
    cfg = tmp / "portable.toml"
    cfg.write_text(CONFIG.format(out=tmp / "portable.nc"))
    return run_survey(cfg, progress=False)


@pytest.mark.foreign
def test_an_archive_verifies_under_another_cpu_target_and_libraries(made_here, foreign):
    env = {**os.environ, **FOREIGN, "NUMBA_CACHE_DIR": str(foreign.cache)}
    proc = subprocess.run([sys.executable, "-m", "survey", "verify", str(made_here)],
                          env=env, capture_output=True, text=True, timeout=1200)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "numba target generic" in out, out
    assert "all reproducible variables match bit for bit\n" in out, out


def test_verify_is_strict_on_any_machine(made_here, tmp_path, monkeypatch):
    """One ulp in a frequency (the torus analysis) or in the FTLE is a mismatch, also when
    the archive says another machine made it: every machine computes the same bits."""
    with xr.open_dataset(made_here) as src:
        ds = src.load()
    for name in (V.frequency, V.ftle):
        t = ds.copy(deep=True)
        values = t[name].values
        index = tuple(np.argwhere(np.isfinite(values))[0])
        values[index] = np.nextafter(values[index], np.inf)
        path = tmp_path / f"{name}.nc"
        t.to_netcdf(path)
        ok, lines = verify(path, cells=2)
        assert not ok and any(line.startswith(name) for line in lines), lines
        monkeypatch.setattr(archive, "machine", lambda: "another machine")
        ok, lines = verify(path, cells=2)
        monkeypatch.undo()
        assert not ok and "MISMATCH" in lines[0], lines
        assert any("this is another machine" in line for line in lines), lines


TARGET = """
import survey.machine.jit
from numba.core.registry import cpu_target
from survey.pipeline.archive import machine
print(repr((cpu_target.target_context.codegen().magic_tuple()[1:], machine())))
"""


def test_kernels_vectorise_in_the_real_vector_width_unless_the_user_set_the_target():
    """On an AVX-512 host survey's kernels are compiled for 256-bit vectors (Zen 4 splits
    512-bit operations), but on one known to run them in full (Zen 5) for 512 (either way
    the archives here, verified under the generic target above, hold the same bits), and
    the archive's machine says so; a target the user sets is kept as set."""
    from llvmlite import binding

    from survey.machine.jit import FULL_512
    got = {}
    # the host's own target first, whatever target this test suite itself runs under
    host = {k: v for k, v in os.environ.items()
            if k not in ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES")}
    for env in ({}, {"NUMBA_CPU_NAME": "generic"}):
        proc = subprocess.run([sys.executable, "-c", TARGET], capture_output=True, text=True,
                              env={**host, **env}, timeout=300)
        assert proc.returncode == 0, proc.stderr
        got[bool(env)] = eval(proc.stdout)
    avx512 = bool(binding.get_host_cpu_features().get("avx512f"))
    name = binding.get_host_cpu_name()
    (_, features), made_on = got[False]
    split = avx512 and name not in FULL_512
    assert features.endswith(",+prefer-256-bit") == split
    assert ("in 256-bit vectors" in made_on) == split, made_on
    assert ("in 512-bit vectors" in made_on) == (avx512 and name in FULL_512), made_on
    assert got[True][0] == ("generic", "")
    assert "numba target generic;" in got[True][1], got[True][1]
