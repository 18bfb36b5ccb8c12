"""survey: order and chaos in Hamiltonian systems of particles interacting in triplets.

The public API, loaded on first use (PEP 562): importing survey itself compiles nothing and
imports neither numba nor xarray. Layers, each a subpackage (README, "Architecture"):
catalog (declarations), physics (the model), numerics (one orbit), pipeline (a survey as a
job), analysis (reading archives), presentation (figures and reports).
"""
import importlib
import importlib.abc
import importlib.util
import sys
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("survey")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0+unknown"

# public name -> the module that defines it
_API = {
    "System": "physics.system", "make_potential": "physics.terms",
    "initial_state": "physics.families", "FAMILIES": "physics.families",
    "reduced": "physics.jacobi", "jacobi": "physics.jacobi", "to_cartesian": "physics.jacobi",
    "integrate": "numerics.integrate", "Outcome": "numerics.integrate",
    "Event": "numerics.events", "Linear": "numerics.events", "Quadratic": "numerics.events",
    "Sides": "numerics.events", "SidesRate": "numerics.events", "Area": "numerics.events",
    "section_event": "numerics.sections", "chaos_indicators": "numerics.indicators",
    "deviation_vectors": "numerics.indicators", "IndicatorOptions": "catalog.indicators",
    "Status": "catalog.status", "Regime": "catalog.regimes", "Thresholds": "catalog.regimes",
    "ConfigError": "catalog.errors", "ArchiveError": "catalog.errors",
    "SurveyError": "catalog.errors",
    "load_config": "pipeline.config", "run": "pipeline.sweep", "run_survey": "pipeline.sweep",
    "verify": "pipeline.sweep", "open_archive": "pipeline.archive",
    "classify": "analysis.classify", "summary": "analysis.classify",
}
__all__ = sorted(_API) + ["__version__"]


def __getattr__(name):
    if name in _API:
        value = getattr(importlib.import_module(f"{__name__}.{_API[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return __all__


class _AccessorOnXarrayImport(importlib.abc.MetaPathFinder):
    """Registers the `ds.survey` accessor (survey.presentation.accessor) the moment xarray is
    imported, so that `import survey` does not pay for xarray (0.4 s) in processes that
    never see a Dataset (dask workers, `orbit`)."""

    def find_spec(self, name, path=None, target=None):
        if name != "xarray":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.loader is not None:
            execute = spec.loader.exec_module

            def exec_module(module):
                execute(module)
                importlib.import_module(f"{__name__}.presentation.accessor")
            spec.loader.exec_module = exec_module
        return spec


if "xarray" in sys.modules:
    importlib.import_module(f"{__name__}.presentation.accessor")
else:
    sys.meta_path.insert(0, _AccessorOnXarrayImport())
