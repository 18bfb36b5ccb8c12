"""Declarations every layer shares -- outcome codes, exceptions, defaults, the archive's
variables, the registries of indicators and regimes. Standard library and numpy only: reading
or describing an archive never compiles anything."""
