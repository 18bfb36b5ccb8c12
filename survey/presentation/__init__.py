"""Figures (matplotlib, no pyplot state) and the Markdown report of a survey archive, and
the figures of single orbits. Labels come from the catalog."""
