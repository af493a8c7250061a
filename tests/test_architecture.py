"""Imports go one way (DESIGN.md): import-linter's contracts from pyproject.toml, run inside the suite."""
import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_hold() -> None:
    exe = Path(sys.executable).with_name("lint-imports")
    res = subprocess.run([str(exe), "--no-cache"], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def _loaded_after(statement: str, modules: tuple[str, ...]) -> list[str]:
    """Which of `modules` a fresh interpreter has loaded after running `statement`."""
    code = f"import sys; {statement}; print([m for m in {modules!r} if m in sys.modules])"
    res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return ast.literal_eval(res.stdout.strip())


def test_api_process_does_not_import_heavy_modules() -> None:
    heavy = ("torch", "cv2", "worker", "evo", "matplotlib")
    assert _loaded_after("from backend.app import create_app", heavy) == []


def test_the_pipeline_imports_matplotlib_only_to_draw() -> None:
    """The figures' plotting library is imported when a run draws them, not by importing the pipeline."""
    statement = "import worker.slam.pipeline, worker.slam.evaluation.plots, worker.tasks"
    assert _loaded_after(statement, ("matplotlib",)) == []


def test_pure_pipeline_imports_only_itself() -> None:
    """worker/slam imports none of ours but itself and formats (import-linter cannot name not-yet-existing
    siblings, so every top-level package of the repository counts as ours)."""

    ours = {p.name for p in ROOT.iterdir() if (p / "__init__.py").is_file()}
    offenders = []
    for path in (ROOT / "worker" / "slam").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            for name in names:
                top = name.split(".")[0]
                if top in ours and top != "formats" and not (name == "worker.slam" or name.startswith("worker.slam.")):
                    offenders.append(f"{path.relative_to(ROOT)}: {name}")
    assert not offenders, offenders


def test_no_folder_imports_a_folder_that_imports_it_back() -> None:
    """Folders (packages) form no import cycle, lazy imports included. The files directly in worker/ and
    worker/slam/ are floors of their own (DESIGN.md), so there each file counts alone; a package and its own
    sub-packages are one family and not compared."""
    import grimp  # import-linter's graph builder

    graph = grimp.build_graph("formats", "storage", "worker", "backend", "webui", "cli", cache_dir=None)

    def unit(module: str) -> str:
        parent = module.rpartition(".")[0]
        if (ROOT / module.replace(".", "/")).is_dir() or parent in ("worker", "worker.slam"):
            return module
        return parent

    edges: dict[str, set[str]] = {}
    for module in graph.modules:
        for imported in graph.find_modules_directly_imported_by(module):
            a, b = unit(module), unit(imported)
            if a != b and not b.startswith(a + ".") and not a.startswith(b + "."):
                edges.setdefault(a, set()).add(b)

    def reaches(start: str, goal: str) -> bool:
        seen, todo = set(), [start]
        while todo:
            node = todo.pop()
            if node == goal:
                return True
            if node not in seen:
                seen.add(node)
                todo.extend(edges.get(node, ()))
        return False

    cycles = sorted(f"{a} -> {b} -> ... -> {a}" for a, targets in edges.items() for b in targets if reaches(b, a))
    assert len(edges) > 20, "the graph lost the repository's packages"
    assert not cycles, cycles
