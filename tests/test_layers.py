"""The layers keep to their rules (README, "Architecture"): who may import whom, read from
every import statement of the package (function-level ones included) by an AST scan; no
import cycles between modules; and the read-only side loads no compiler."""
import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).parents[1] / "survey"

# layer -> the layers (or modules) of survey it may import, besides itself
ALLOWED = {
    "machine": set(),
    "catalog": set(),
    "physics": {"catalog", "machine"},
    "numerics": {"catalog", "machine", "physics"},
    "analysis": {"catalog"},
    "presentation": {"catalog", "analysis", "physics.geometry"},
    "pipeline": {"catalog", "machine", "physics", "numerics", "analysis"},
    "bench": {"catalog", "machine", "physics", "numerics", "analysis", "pipeline"},
}
# third-party packages a layer must not import at all
FORBIDDEN = {"catalog": {"numba", "xarray", "matplotlib", "dask", "distributed", "netCDF4"},
             "analysis": {"numba", "matplotlib", "dask", "distributed"},
             "physics": {"xarray", "matplotlib", "dask", "distributed", "netCDF4"},
             "numerics": {"xarray", "matplotlib", "dask", "distributed", "netCDF4"},
             "machine": {"xarray", "matplotlib", "dask", "distributed", "netCDF4"}}


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path, root: Path):
    """(imported module, line) of every import in a file, relative imports resolved."""
    here = module_name(path, root)
    package = here if path.name == "__init__.py" else here.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            if node.module is None or target == root.name:   # from . import x: modules
                for alias in node.names:
                    yield f"{target}.{alias.name}", node.lineno
            else:
                yield target, node.lineno


def layer_of(module: str, root_name: str):
    parts = module.split(".")
    return parts[1] if len(parts) > 2 and parts[0] == root_name else None


def violations(root: Path) -> list[str]:
    """Every import that breaks a layer rule, as 'file:line: module imports target'."""
    found = []
    for path in sorted(root.rglob("*.py")):
        here = module_name(path, root)
        layer = layer_of(here, root.name) if path.parent != root else None
        if layer is None:                   # top level: cli, the facade
            continue
        for target, line in imports(path, root):
            where = f"{path.relative_to(root.parent)}:{line}: {here} imports {target}"
            top = target.split(".")[0]
            if top in FORBIDDEN.get(layer, ()):
                found.append(where)
            if top != root.name:
                continue
            other = layer_of(target, root.name) or target.split(".")[1]
            allowed = ALLOWED[layer] | {layer}
            if other not in allowed and ".".join(target.split(".")[1:3]) not in allowed:
                found.append(where)
    return found


def cycles(root: Path) -> list[list[str]]:
    """Import cycles between the package's modules (every import statement counts)."""
    modules = {module_name(p, root): p for p in root.rglob("*.py")}
    graph = {m: {t for t, _ in imports(p, root) if t in modules and t != m}
             for m, p in modules.items()}
    for m in graph:                   # importing a.b.c imports a.b: packages are free
        graph[m] = {t for t in graph[m] if not m.startswith(t + ".")}
    found, state = [], {}

    def visit(m, stack):
        state[m] = 1
        stack.append(m)
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                found.append(stack[stack.index(t):] + [t])
            elif t not in state:
                visit(t, stack)
        stack.pop()
        state[m] = 2
    for m in sorted(graph):
        if m not in state:
            visit(m, [])
    return found


def test_every_layer_imports_only_what_it_may():
    assert violations(PACKAGE) == []


def test_no_module_imports_itself_in_a_circle():
    assert cycles(PACKAGE) == []


def test_the_check_fails_on_a_forbidden_import(tmp_path):
    """The scan catches what it is for: the analysis layer importing the integrator, the
    catalog importing numba, a function-level import, and a cycle."""
    root = tmp_path / "survey"
    for layer in ALLOWED:
        (root / layer).mkdir(parents=True)
        (root / layer / "__init__.py").write_text("")
    (root / "__init__.py").write_text("")
    (root / "numerics" / "integrate.py").write_text("from ..catalog import status\n")
    (root / "catalog" / "status.py").write_text("import enum\n")
    assert violations(root) == [] and cycles(root) == []
    (root / "analysis" / "classify.py").write_text(
        "def f():\n    from ..numerics.integrate import integrate\n")
    (root / "catalog" / "status.py").write_text("import numba\nfrom . import regimes\n")
    (root / "catalog" / "regimes.py").write_text("from .status import Status\n")
    found = violations(root)
    assert any("survey.analysis.classify imports survey.numerics.integrate" in f for f in found)
    assert any("survey.catalog.status imports numba" in f for f in found)
    assert cycles(root) == [["survey.catalog.regimes", "survey.catalog.status",
                             "survey.catalog.regimes"]]


@pytest.mark.parametrize("modules", [
    ["survey"],
    ["survey.catalog.errors", "survey.catalog.indicators", "survey.catalog.regimes",
     "survey.catalog.status", "survey.catalog.variables", "survey.analysis.classify",
     "survey.analysis.onset", "survey.presentation.plots", "survey.presentation.report",
     "survey.presentation.orbit_plots", "survey.presentation.accessor"]])
def test_the_read_only_side_loads_no_compiler(modules):
    """Reading, classifying and drawing archives never imports numba; `import survey`
    imports neither numba nor xarray."""
    code = (f"import sys, {', '.join(modules)}; "
            "print(sorted(m for m in ('numba', 'xarray', 'dask') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    loaded = eval(out)
    assert "numba" not in loaded and "dask" not in loaded
    if modules == ["survey"]:
        assert loaded == []


def test_the_accessor_is_registered_whichever_is_imported_first():
    for order in ("import survey, xarray", "import xarray, survey"):
        code = (f"{order}; ds = xarray.Dataset(); "
                "print(type(ds.survey).__module__)")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True).stdout.strip()
        assert out == "survey.presentation.accessor", order


# string literals spelled like an archive variable that do not name it
NOT_VARIABLES = {
    ("__init__.py", "initial_state"): "the public function",
    ("physics/families.py", "energy"): "a family's target-energy parameter",
    ("pipeline/config.py", "energy"): "the [initial] key of the target energy",
    ("pipeline/schema.py", "energy"): "the [initial] key of the target energy",
    ("pipeline/config.py", "resonance_order"): "the [tori] threshold",
    ("pipeline/schema.py", "resonance_order"): "the [tori] threshold",
    ("pipeline/cells.py", "resonance_order"): "the [tori] threshold",
    ("pipeline/archive.py", "status"): "the git command",
    ("presentation/plots.py", "energy"): "the [initial] energy axis of a map",
    ("bench/surveys.py", "energy"): "the [initial] energy axis of the scale bench's maps",
    ("presentation/report.py", "energy"): "the [initial] energy axis of a map",
    ("pipeline/families.py", "energy"): "an [equilibria] / [periodic] key, a family variable",
    ("pipeline/families.py", "angular_momentum"): "an [equilibria] key, a family variable",
    ("pipeline/families.py", "initial_state"): "a family variable",
    ("presentation/families.py", "energy"): "a JSON field of `periodic --json`",
    ("presentation/families.py", "angular_momentum"): "the same",
    ("presentation/families.py", "initial_state"): "the same",
    ("numerics/tangents.py", "fli"): "the Outcome field of a step-end indicator",
    ("numerics/tangents.py", "ftle_wba"): "the same",
    ("numerics/periodic.py", "energy"): "the quantity a periodic family runs in (`pinned`)",
    ("numerics/periodic.py", "angular_momentum"): "the same",
}


def named_variables(root: Path) -> list[str]:
    """String literals (not docstrings, not parts of f-strings) equal to a declared archive
    variable's name, outside the catalog: 'file:line: name'."""
    from survey.catalog.variables import VARIABLES
    names = {v.name for v in VARIABLES}
    found = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if rel.startswith("catalog/"):
            continue
        tree = ast.parse(path.read_text())
        skip = set()
        for node in ast.walk(tree):
            body = getattr(node, "body", None)
            if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
                skip.add(id(body[0].value))            # docstrings
            if isinstance(node, ast.JoinedStr):
                skip.update(id(v) for v in node.values)
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and node.value in names and id(node) not in skip \
                    and (rel, node.value) not in NOT_VARIABLES:
                found.append(f"{rel}:{node.lineno}: {node.value!r}")
    return found


def test_archive_variables_are_named_through_the_catalog(tmp_path):
    """Code outside the catalog names archive variables as catalog.variables.V.<name>, so a
    renamed or removed variable fails at once; the scan catches a retyped name."""
    assert named_variables(PACKAGE) == []
    (tmp_path / "plots.py").write_text('def f(ds):\n    """ftle"""\n    return ds["ftle"]\n')
    assert named_variables(tmp_path) == ["plots.py:3: 'ftle'"]


def test_config_tables_are_read_through_typed_records_outside_the_config_module():
    """Code outside pipeline/config.py reads the validated config through its typed records
    (config.settings.integration.rtol: pipeline.records, generated from the schema), never
    `config.tables[...]`, so a reader and a tool can follow a key from the TOML to its use;
    and records.py is what the schema generates."""
    from survey.pipeline.schema import records_source
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.relative_to(PACKAGE).as_posix() == "pipeline/config.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Attribute) \
                    and node.value.attr == "tables":
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}")
    assert found == [], found
    assert (PACKAGE / "pipeline" / "records.py").read_text() == records_source(), \
        "pipeline/records.py is stale: python -m survey.pipeline.schema regenerates it"
