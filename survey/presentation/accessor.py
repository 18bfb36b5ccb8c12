"""`ds.survey`: the read-only side of survey on any Dataset of a survey archive --
its regimes, figures and report -- registered as an xarray accessor when xarray is imported
after survey (or at once, if it was imported before)."""
from __future__ import annotations

from pathlib import Path

import xarray as xr


@xr.register_dataset_accessor("survey")
class SurveyAccessor:
    """`ds.survey.classify()`, `ds.survey.figures(folder)`, `ds.survey.report(folder)`."""

    def __init__(self, ds: xr.Dataset):
        self._ds = ds

    def classify(self, thresholds=None):
        """(regime, confidence) of every cell from the evidence stored, with the archive's
        thresholds unless others (catalog.regimes.Thresholds) are given."""
        from ..analysis.classify import classify
        return classify(self._ds, thresholds)

    def figures(self, folder=None, variables=None):
        """The figures that fit the grid; written as PNGs into `folder` if given (returns
        their paths), else returned as matplotlib Figures by name."""
        from . import plots
        if folder is None:
            return plots.figures(self._ds, variables)
        return plots.draw(self._ds, folder, self._stem(), variables)

    def report(self, folder) -> Path:
        """Write the Markdown report and its figures into `folder`; returns its path: the
        report `python -m survey report` writes, with the [check] runs' archives found
        beside the Dataset's file."""
        import contextlib

        from ..catalog.defaults import CHECK_VARIANTS, check_archive
        from . import report
        source = self._ds.encoding.get("source")
        with contextlib.ExitStack() as stack:
            checks = {} if source is None else {
                v: stack.enter_context(xr.open_dataset(f)) for v in CHECK_VARIANTS
                if (f := check_archive(source, v)).exists()}
            return report.write(self._ds, folder, self._stem(), checks=checks)

    def _stem(self) -> str:
        return Path(self._ds.encoding.get("source", "survey")).stem
