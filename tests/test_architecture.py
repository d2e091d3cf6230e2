"""The house plan's one-way doors, read from the source: which room may import which."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "dsfec_jax"

# room -> rooms of dsfec_jax it must never import (the "never" lines of the architecture)
NEVER = {
    "core": {"layers", "boxes", "models", "data", "metrics", "train", "profile", "deploy", "zoo", "predict",
             "evaluate", "cli"},
    "layers": {"boxes", "models", "data", "metrics", "train", "profile", "deploy", "zoo", "predict", "evaluate",
               "cli"},
    "models": {"data", "train", "deploy", "metrics", "cli"},
    "data": {"models", "train", "cli"},
    "metrics": {"models", "train", "cli"},
    # geodesy and placement sit on core alone: they know nothing of detectors or frames
    "geo": {"layers", "boxes", "models", "data", "metrics", "train", "profile", "deploy", "zoo", "predict",
            "predict_camera", "predict_depth", "evaluate", "edge", "service", "cli"},
    # the map server stays light (no JAX, no models): it starts in a second and scales by itself
    "service": {"layers", "boxes", "models", "data", "metrics", "train", "profile", "deploy", "zoo", "predict",
                "predict_camera", "predict_depth", "evaluate", "edge", "cli"},
    # an edge device and the server meet only over HTTP (the exchange format), never by import
    "edge": {"train", "service", "cli"},
}


def project_imports(path: Path) -> set[str]:
    """The dsfec_jax rooms a module imports: first component below dsfec_jax, absolute or relative."""
    module = path.relative_to(PACKAGE.parent).with_suffix("").parts
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name.split(".") for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = list(module[: len(module) - node.level]) if node.level else []
            target = base + (node.module.split(".") if node.module else [])
            targets = [target + [a.name] for a in node.names] if not node.module else [target]
        else:
            continue
        for t in targets:
            if t[:1] == ["dsfec_jax"] and len(t) > 1:
                found.add(t[1])
            if t[:1] in (["search"], ["experiments"]):
                found.add(t[0])
    return found


def modules(room: str | None = None):
    root = PACKAGE / room if room else PACKAGE
    return sorted(root.rglob("*.py")) if root.is_dir() else [root.with_suffix(".py")]


@pytest.mark.parametrize("room", sorted(NEVER))
def test_rooms_keep_their_never_rules(room):
    bad = {str(p.relative_to(PACKAGE)): sorted(project_imports(p) & NEVER[room]) for p in modules(room)}
    assert not {k: v for k, v in bad.items() if v}


def test_the_map_service_never_imports_jax():
    """The server process must not pay JAX's start-up and memory: no module of it imports jax/flax."""
    heavy = {"jax", "flax", "optax", "onnxruntime"}
    bad = {}
    for path in modules("service"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module] if isinstance(node, ast.ImportFrom) and node.module and not node.level else [])
            found = {n.split(".")[0] for n in names} & heavy
            if found:
                bad[str(path.relative_to(PACKAGE))] = sorted(found)
    assert not bad


def test_the_library_never_imports_cli_search_or_experiments():
    """cli.py is a thin command layer on top: only the `python -m dsfec_jax` entry point imports it."""
    bad = {str(p.relative_to(PACKAGE)): sorted(project_imports(p) & {"cli", "search", "experiments"})
           for p in modules() if p.name != "__main__.py" or p.parent != PACKAGE}
    assert not {k: v for k, v in bad.items() if v}


def test_the_reader_sees_relative_and_absolute_imports(tmp_path, monkeypatch):
    """The checker itself can fail: a module importing cli both ways is caught."""
    pkg = tmp_path / "dsfec_jax" / "deploy"
    pkg.mkdir(parents=True)
    mod = pkg / "x.py"
    mod.write_text("from ..cli import RUN_PILLARS\nimport dsfec_jax.train.fit\nfrom .. import models\n")
    monkeypatch.setattr(__import__(__name__), "PACKAGE", tmp_path / "dsfec_jax")
    assert project_imports(mod) == {"cli", "train", "models"}


def test_point_column_layouts_are_defined_once():
    """A tuple literal of point columns (x, y, z first) lives only in core/columns.py; the
    nuScenes PCD's 18 file fields are a file format, not a column layout."""
    defined = {}
    for path in modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Tuple) and len(node.elts) > 3 and all(
                    isinstance(e, ast.Constant) for e in node.elts) and [e.value for e in node.elts[:3]] == ["x", "y", "z"]:
                defined.setdefault(tuple(e.value for e in node.elts), []).append(str(path.relative_to(PACKAGE)))
    defined = {k: v for k, v in defined.items() if "dyn_prop" not in k}
    assert all(places == ["core/columns.py"] for places in defined.values()), defined


def family_branches(source: str) -> list[str]:
    """Places in `source` that ask which family they have instead of asking its record:
    comparing a `family` (name or attribute) with a string, isinstance(..., <Something>Config),
    and DSFEC's HEAD_NAMES."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            named = any(isinstance(s, ast.Name) and s.id == "family" or isinstance(s, ast.Attribute)
                        and s.attr in ("family", "name") and "family" in ast.unparse(s) for s in sides)
            if named and any(isinstance(s, ast.Constant) and isinstance(s.value, str) for s in sides):
                found.append(f"line {node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.Call) and ast.unparse(node.func) == "isinstance" and len(node.args) == 2:
            if ast.unparse(node.args[1]).split(".")[-1].endswith("Config"):
                found.append(f"line {node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, (ast.Name, ast.Attribute, ast.alias)):
            name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else node.name
            if name == "HEAD_NAMES":
                found.append(f"line {node.lineno}: HEAD_NAMES")
    return found


def test_no_code_outside_models_branches_on_a_family():
    """Shared code asks the family's record (zoo.family_of(cfg)); only models/ knows families."""
    roots = [PACKAGE, PACKAGE.parent / "search", PACKAGE.parent / "experiments"]
    bad = {str(p.relative_to(PACKAGE.parent)): family_branches(p.read_text())
           for root in roots for p in sorted(root.rglob("*.py")) if "models" not in p.relative_to(root).parts}
    assert not {k: v for k, v in bad.items() if v}


def test_the_family_branch_finder_can_fail():
    source = ("if cfg.family == 'radarnext':\n    pass\nx = isinstance(c, radarnext.RadarNeXtConfig)\n"
              "from dsfec_jax.models.dsfec.net import HEAD_NAMES\nok = zoo.family_of(cfg).name != 'dsfec'\n"
              "fine = zoo.family_of(cfg).metric.name")
    assert len(family_branches(source)) == 4


# rooms of machinery that take a Modality record from their caller, and the rooms below modalities/
MODALITY_FREE = ("train", "deploy", "profile", "models", "data", "metrics")


def modality_importers(room: str) -> list[str]:
    """The modules of `room` that import modalities/, entry points (`__main__.py`) left out."""
    return [str(p.relative_to(PACKAGE)) for p in modules(room)
            if p.name != "__main__.py" and "modalities" in project_imports(p)]


@pytest.mark.parametrize("room", MODALITY_FREE)
def test_the_modality_free_rooms_never_import_modalities(room):
    """train/, deploy/ and profile/ are modality-free: they take a Modality record (or its verbs)
    from their caller and never import modalities/. Entry points are the exception: a `__main__.py`
    (`python -m dsfec_jax.profile`, `python -m dsfec_jax.deploy.bench`) looks the records up and
    passes them in, as cli.py does."""
    assert modality_importers(room) == []


def test_the_modality_import_finder_can_fail(tmp_path, monkeypatch):
    """A profile module importing modalities is found; the room's entry point is not."""
    room = tmp_path / "dsfec_jax" / "profile"
    room.mkdir(parents=True)
    (room / "latency.py").write_text("from ..modalities.rd import profile as rd\n")
    (room / "__main__.py").write_text("from ..modalities.registry import modality_of\n")
    monkeypatch.setattr(__import__(__name__), "PACKAGE", tmp_path / "dsfec_jax")
    assert modality_importers("profile") == ["profile/latency.py"]


GRAPH_ROOTS = ("dsfec_jax", "search", "experiments")


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(path: Path, known: set[str], root: Path) -> set[str]:
    """The project modules `path` imports anywhere in it (at the top or inside a function: a lazy
    import still makes the two modules depend on each other), absolute or relative, each resolved
    to the longest module name in `known`."""
    name = module_name(path, root).split(".")
    package = name if path.name == "__init__.py" else name[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[: len(package) - node.level + 1] + ([node.module] if node.module else []))
            targets = [base] + [f"{base}.{a.name}" for a in node.names]  # `from pkg import submodule`
        else:
            continue
        for target in targets:
            parts = target.split(".")
            while parts and ".".join(parts) not in known:
                parts.pop()
            if parts:
                found.add(".".join(parts))
    return found


def import_graph(root: Path, tops=GRAPH_ROOTS) -> dict[str, set[str]]:
    """module -> the project modules it imports. A submodule's import of a package it sits in is
    no edge: Python runs that package's __init__ before the submodule anyway."""
    paths = [p for top in tops for p in sorted((root / top).rglob("*.py"))]
    known = {module_name(p, root): p for p in paths}
    return {name: {m for m in imported_modules(p, set(known), root) - {name}
                   if not (known[m].name == "__init__.py" and name.startswith(m + "."))}
            for name, p in known.items()}


def import_circles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """The graph's strongly connected parts of more than one module: modules that import each
    other, directly or through others."""
    reach = {}
    for start in graph:
        seen, todo = set(), [start]
        while todo:
            for target in graph.get(todo.pop(), ()):
                if target not in seen:
                    seen.add(target)
                    todo.append(target)
        reach[start] = seen
    circles = {frozenset({start} | {m for m in reach[start] if start in reach.get(m, ())}) for start in graph}
    return sorted((c for c in circles if len(c) > 1), key=sorted)


def test_no_module_imports_itself_through_others():
    """dsfec_jax, search and experiments have no import circle, lazy imports included: a circle
    makes two modules one (neither can change or load alone), and a lazy import only hides it."""
    circles = [sorted(c) for c in import_circles(import_graph(PACKAGE.parent))]
    assert not circles


def test_the_circle_finder_can_fail(tmp_path):
    """A tiny package whose config builds its net lazily while the net imports the config (the
    circle models/camera had), one relative and one absolute, plus an innocent bystander."""
    pkg = tmp_path / "toy"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from . import config\n")  # a package importing its child: no circle
    (pkg / "config.py").write_text("def build():\n    from .net import Net\n    return Net()\n")
    (pkg / "net.py").write_text("import toy.config\nfrom toy.layout import STAGES\nclass Net:\n    pass\n")
    (pkg / "layout.py").write_text("STAGES = 5\n")
    graph = import_graph(tmp_path, ("toy",))
    assert graph["toy.net"] == {"toy.config", "toy.layout"} and graph["toy.config"] == {"toy.net"}
    assert import_circles(graph) == [frozenset({"toy.config", "toy.net"})]
    (pkg / "net.py").write_text("from .layout import STAGES\nclass Net:\n    pass\n")  # the fix: a leaf
    assert import_circles(import_graph(tmp_path, ("toy",))) == []


def private_jax_imports(source: str) -> list[str]:
    """Imports of JAX's private modules (`jax._src...`): they change without notice between releases."""
    found = []
    for node in ast.walk(ast.parse(source)):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
            [f"{node.module}.{a.name}" for a in node.names] if isinstance(node, ast.ImportFrom) and node.module else [])
        found += [f"line {node.lineno}: {n}" for n in names if n == "jax._src" or n.startswith("jax._src.")]
    return found


def test_nothing_imports_private_jax():
    bad = {str(p.relative_to(PACKAGE.parent)): private_jax_imports(p.read_text())
           for top in GRAPH_ROOTS for p in sorted((PACKAGE.parent / top).rglob("*.py"))}
    assert not {k: v for k, v in bad.items() if v}


def test_the_private_jax_finder_can_fail():
    source = ("from jax._src import xla_bridge\nimport jax._src.lib\nfrom jax import _src\n"
              "from jax.profiler import ProfileData\nimport jax\n")
    assert len(private_jax_imports(source)) == 3


# ---- floors: imports flow downward only (docs/layout.md) ----

# the floor of each room of dsfec_jax: a module may import rooms on its own floor or below
FLOORS = {
    "core": 0, "argtypes": 0,
    "layers": 1, "boxes": 1, "geo": 1,
    "models": 2, "data": 2, "metrics": 2,
    "zoo": 3,
    "train": 4, "profile": 4, "deploy": 4,
    "modalities": 5,
    "api": 6, "edge": 6, "service": 6,
    "cli_edge": 7, "cli_report": 7, "cli": 8,
    "__main__": 9,
}
MODALITY_NAMES = ("points", "rd", "image")
# the only places that may say which modality they hold
MODALITY_HOMES = ("dsfec_jax/modalities/", "dsfec_jax/models/family.py")


def room_of(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__main__"


def imports_back_up(graph: dict[str, set[str]]) -> list[str]:
    """Imports from a room into a room on a higher floor (entry points' __main__ modules excepted:
    they are the command layer of their room)."""
    bad = []
    for module, targets in graph.items():
        if not module.startswith("dsfec_jax.") or module.endswith("__main__"):
            continue
        floor = FLOORS.get(room_of(module))
        for target in targets:
            if target.startswith("dsfec_jax.") and FLOORS.get(room_of(target), 99) > floor:
                bad.append(f"{module} -> {target}")
    return sorted(bad)


def test_every_room_has_a_floor():
    rooms = {room_of(m) for m in import_graph(PACKAGE.parent) if m.startswith("dsfec_jax.")}
    assert not rooms - set(FLOORS), f"rooms without a floor in FLOORS: {sorted(rooms - set(FLOORS))}"


def test_imports_never_climb_back_up():
    assert not imports_back_up(import_graph(PACKAGE.parent))


def test_the_climb_finder_can_fail():
    graph = {"dsfec_jax.train.loop": {"dsfec_jax.modalities.points.fit", "dsfec_jax.core.atomic"},
             "dsfec_jax.modalities.points.fit": {"dsfec_jax.train.loop"},
             "dsfec_jax.profile.__main__": {"dsfec_jax.modalities.registry"}}
    assert imports_back_up(graph) == ["dsfec_jax.train.loop -> dsfec_jax.modalities.points.fit"]


def modality_branches(source: str) -> list[str]:
    """Places that ask which modality they hold instead of asking its record: a comparison of
    anything with a modality's name ('points', 'rd', 'image', or a collection holding one), and a
    comparison of a `.modality` attribute with anything but None."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Compare):
            continue
        sides = [node.left, *node.comparators]
        named = any(isinstance(s, ast.Constant) and s.value in MODALITY_NAMES or isinstance(s, (ast.Tuple, ast.List, ast.Set))
                    and any(isinstance(e, ast.Constant) and e.value in MODALITY_NAMES for e in s.elts) for s in sides)
        attribute = any(isinstance(s, ast.Attribute) and s.attr == "modality" for s in sides) and not any(
            isinstance(s, ast.Constant) and s.value is None for s in sides)
        if named or attribute:
            found.append(f"line {node.lineno}: {ast.unparse(node)}")
    return found


def test_only_modalities_know_their_names():
    bad = {}
    for top in ("dsfec_jax", "search", "experiments"):
        for path in sorted((PACKAGE.parent / top).rglob("*.py")):
            rel = path.relative_to(PACKAGE.parent).as_posix()
            if not rel.startswith(MODALITY_HOMES):
                found = modality_branches(path.read_text())
                if found:
                    bad[rel] = found
    assert not bad


def test_the_modality_branch_finder_can_fail():
    source = ("if family.modality == 'rd':\n    pass\nx = zoo.family_of(c).modality != wanted\n"
              "y = kind in ('points', 'image')\nok = modality_of(cfg).predictor\nfine = m.modality is None\n"
              "also = found != expected\n")
    assert len(modality_branches(source)) == 3


def test_modality_files_live_in_their_rooms():
    """A `*_rd.py` or `*_camera.py` belongs in data/, models/ or modalities/ (a modality's part
    elsewhere is a branch that moved into a file name)."""
    allowed = {"data", "models", "modalities"}
    bad = [p.relative_to(PACKAGE.parent).as_posix() for top in ("dsfec_jax",) for p in (PACKAGE.parent / top).rglob("*.py")
           if p.stem.endswith(("_rd", "_camera")) and p.relative_to(PACKAGE).parts[0] not in allowed]
    assert not bad
