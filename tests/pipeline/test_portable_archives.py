"""An archive verifies on a machine that is not the one that wrote it. The other machine is
made here by switching the code paths a CPU selects: numba compiling for the generic x86-64
target, numpy without its AVX2/AVX-512 loops, glibc without its FMA/AVX2 libm, OpenBLAS's
oldest kernels. The orbit, the variational indicators and the sections must come out the
same bits; the torus analysis within its declared rounding."""
import os
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from survey.catalog.variables import BY_NAME, V
from survey.pipeline import archive
from survey.pipeline.sweep import run_survey, verify

FOREIGN = {"NUMBA_CPU_NAME": "generic",
           "NPY_DISABLE_CPU_FEATURES": "X86_V3,X86_V4,AVX512_ICL,AVX512_SPR",
           "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F",
           "OPENBLAS_CORETYPE": "Prescott"}

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
def made_here(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("portable")
    cfg = tmp / "portable.toml"
    cfg.write_text(CONFIG.format(out=tmp / "portable.nc"))
    return run_survey(cfg, progress=False)


def test_an_archive_verifies_under_another_cpu_target_and_libraries(made_here, tmp_path):
    env = {**os.environ, **FOREIGN, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    proc = subprocess.run([sys.executable, "-m", "survey", "verify", str(made_here)],
                          env=env, capture_output=True, text=True, timeout=1200)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "MISMATCH" not in out and "numba target generic" in out, out
    # what may differ is only the torus analysis
    assert "match bit for bit" in out, out
    if "within rounding" in out:
        named = out.split("except that ")[1].split(" agree within")[0].split(", ")
        assert all(BY_NAME[n].rounding for n in named), out


def test_verify_is_strict_on_the_same_machine_and_allows_only_declared_rounding_elsewhere(
        made_here, tmp_path, monkeypatch):
    with xr.open_dataset(made_here) as src:
        ds = src.load()
    for name, nudged in ((V.frequency, True), (V.ftle, False)):
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
        assert ok == nudged, lines
        if nudged:
            assert "agree within rounding on a different machine" in lines[0], lines
            assert any("this is another machine" in line for line in lines), lines
