"""The package's layout follows the data flow: every module imports only from its own
layer or the layers below it (module-level and function-level imports alike), and no
modules import each other in a circle.  A new module must be given a layer here."""

from __future__ import annotations

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1] / "sorjax"

#: Bottom to top: images -> outlines -> per-view homologies -> linear methods ->
#: bundle -> checks and uncertainty -> messages -> calibration -> images, reports, experiments, CLI.
LAYERS: list[tuple[str, tuple[str, ...]]] = [
    ("foundation", ("sorjax._checks", "sorjax._compile", "sorjax._files", "sorjax._curves",
                    "sorjax.core._options")),
    ("geometry", ("sorjax.core._camera", "sorjax.core._distortion", "sorjax.core._field", "sorjax.core._symmetry",
                  "sorjax.core._solvers")),
    ("outlines", ("sorjax._image_outline", "sorjax._level_trace", "sorjax._masks", "sorjax._outline",
                  "sorjax._image_files")),
    ("per-view fit", ("sorjax.core._prepare", "sorjax.core._noise", "sorjax.core._viewfit_starts",
                      "sorjax.core._viewfit")),
    ("linear methods", ("sorjax.core._linear",)),
    ("verdict helpers", ("sorjax.core._assess",)),
    ("bundle model", ("sorjax.core._model",)),
    ("bundle linearisation", ("sorjax.core._covariance",)),
    ("bundle", ("sorjax.core._bundle",)),
    ("bundle with distortion", ("sorjax.core._distorted",)),
    ("checks and uncertainty", ("sorjax.core._checks", "sorjax.core._result", "sorjax._uncertainty")),
    ("messages", ("sorjax._messages",)),
    ("calibration", ("sorjax.core._calibrate", "sorjax.core._shard", "sorjax.core", "sorjax._homology",
                     "sorjax._calibration_thresholds", "sorjax._calibration_result", "sorjax._calibration_checks",
                     "sorjax._calibration_quality", "sorjax._calibration", "sorjax.losses")),
    ("scenes and images", ("sorjax._scene_types", "sorjax._scene_camera", "sorjax._scene_trace",
                           "sorjax._scene_spheres", "sorjax._scene_distortion", "sorjax._scene_profiles",
                           "sorjax._scene_sor", "sorjax._scene_noise", "sorjax.scenes", "sorjax._segment", "sorjax._photo_style", "sorjax._photo_textures",
                           "sorjax._photo_layout", "sorjax._photo", "sorjax._render_coverage",
                           "sorjax._render_objects", "sorjax._render_shading", "sorjax.render",
                           "sorjax._detect_options", "sorjax._detect_proposals", "sorjax._symmetry_judge",
                           "sorjax._edge_refinement", "sorjax._image_input", "sorjax._unmixing",
                           "sorjax._detect", "sorjax._extract", "sorjax._outline_files", "sorjax._camera_io")),
    ("experiments", ("sorjax.experiment._config", "sorjax.experiment._trials", "sorjax.experiment._report",
                     "sorjax.experiment._runner", "sorjax.experiment")),
    ("command line and package", ("sorjax.cli", "sorjax.__main__", "sorjax")),
]


def _modules() -> dict[str, pathlib.Path]:
    mods = {}
    for p in ROOT.rglob("*.py"):
        rel = p.relative_to(ROOT.parent).with_suffix("")
        name = ".".join(rel.parts)
        mods[name[: -len(".__init__")] if name.endswith(".__init__") else name] = p
    return mods


def _imports(mods: dict[str, pathlib.Path]) -> dict[str, set[str]]:
    """Module -> the package's modules it imports (anywhere in its body).  Importing a
    submodule ``a.b.c`` counts as an import of ``a.b.c`` only: the packages here load
    their public names lazily or sit at the top."""
    graph = {}
    for m, p in mods.items():
        pkg = m if p.name == "__init__.py" else m.rsplit(".", 1)[0]
        out = set()
        for node in ast.walk(ast.parse(p.read_text())):
            targets = []
            if isinstance(node, ast.ImportFrom):
                base = pkg.split(".")
                base = base[: len(base) - (node.level - 1)] if node.level else []
                mod = ".".join(base + ([node.module] if node.module else [])) if node.level else node.module or ""
                targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in mods else mod for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            for t in targets:
                while t and t not in mods and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in mods and t != m:
                    out.add(t)
        graph[m] = out
    return graph


def _layer_of() -> dict[str, int]:
    return {m: i for i, (_, ms) in enumerate(LAYERS) for m in ms}


def test_every_module_has_a_layer():
    layer = _layer_of()
    missing = sorted(set(_modules()) - set(layer))
    stale = sorted(set(layer) - set(_modules()))
    assert not missing, f"modules with no layer in tests/test_layout.py: {missing}"
    assert not stale, f"layers name modules that do not exist: {stale}"


def test_imports_go_down_the_data_flow():
    layer, graph = _layer_of(), _imports(_modules())
    upward = [f"{m} ({LAYERS[layer[m]][0]}) imports {t} ({LAYERS[layer[t]][0]})"
              for m, ts in sorted(graph.items()) for t in sorted(ts) if layer[t] > layer[m]]
    assert not upward, "imports against the data flow:\n" + "\n".join(upward)


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, on, stack, out, n = {}, {}, set(), [], [], [0]

    def visit(v):
        index[v] = low[v] = n[0]
        n[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    assert _cycles(_imports(_modules())) == []


def test_the_checks_catch_a_cycle_and_an_upward_import():
    """The checks themselves can fail: a made-up graph with a circle and an upward edge."""
    graph = {"a": {"b"}, "b": {"a"}, "c": set()}
    assert _cycles(graph) == [["a", "b"]]
    graph = _imports(_modules())
    graph["sorjax._curves"] = graph["sorjax._curves"] | {"sorjax._calibration"}
    layer = _layer_of()
    assert any(layer[t] > layer[m] for m, ts in graph.items() for t in ts)
    with pytest.raises(AssertionError):
        assert _cycles(graph) == []
