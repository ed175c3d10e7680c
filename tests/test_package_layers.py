"""Package boundaries: no import cycle, no package importing one above it, dependencies declared.

The layers, bottom to top (docs/architecture.md): the run-time core every node imports, the offline
data import and evaluation packages, then the node packages in the order a frame flows through the
graph, the bringup/offline-processing package, which may import every node's library, and on top the
evaluation and experiment tools (kinect_experiments), which may also use the bringup's graph.
Every import counts, including those inside functions.
"""
import ast
from pathlib import Path
from xml.dom import minidom

import pytest

ROOT = Path(__file__).resolve().parents[1]
# performance_control sits between the reconstruction and the physics in the graph but builds its
# feature world with physics_sim's MJCF helpers and frames, so it ranks above physics_sim
LAYERS = ['skeleton_core', 'skeleton_data', 'skeleton_eval', 'kinect_driver', 'pose_reconstruction',
          'physics_sim', 'performance_control', 'viz', 'kinect_bringup', 'kinect_experiments']
RANK = {p: i for i, p in enumerate(LAYERS)}
PYTHON_PACKAGES = sorted(p.parent.name for p in (ROOT / 'src').glob('*/setup.py'))


def _module_name(pkg_root: Path, path: Path) -> str:
    parts = list(path.relative_to(pkg_root).with_suffix('').parts)
    if parts[-1] == '__init__':
        parts = parts[:-1]
    return '.'.join(parts)


def _imports(path: Path, module: str):
    """Absolute names of the workspace modules ``path`` imports (anywhere in the file)."""
    is_pkg = path.name == '__init__.py'
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split('.')
                base = base[:len(base) - node.level + (1 if is_pkg else 0)]
                prefix = '.'.join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ''
            # ``from pkg import mod`` imports the module pkg.mod when it is one
            names = [prefix] + [f'{prefix}.{a.name}' for a in node.names]
        else:
            continue
        for name in names:
            if name.split('.')[0] in RANK:
                yield name


def import_graph(src: Path = ROOT / 'src'):
    """{module: set of workspace modules it imports}, over every Python package in ``src``."""
    modules = {}
    for pkg in PYTHON_PACKAGES:
        pkg_root = src / pkg
        for path in sorted((pkg_root / pkg).rglob('*.py')):
            modules[_module_name(pkg_root, path)] = path
    graph = {}
    for mod, path in modules.items():
        graph[mod] = {n for n in _imports(path, mod) if n in modules and n != mod}
    return graph


def find_cycle(graph):
    """One import cycle as a list of modules, or None (iterative DFS, colours)."""
    colour = dict.fromkeys(graph, 0)
    for start in graph:
        if colour[start]:
            continue
        stack = [(start, iter(sorted(graph[start])))]
        path = [start]
        colour[start] = 1
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                colour[node] = 2
                stack.pop()
                path.pop()
            elif colour[nxt] == 1:
                return path[path.index(nxt):] + [nxt]
            elif colour[nxt] == 0:
                colour[nxt] = 1
                stack.append((nxt, iter(sorted(graph[nxt]))))
                path.append(nxt)
    return None


def test_every_python_package_has_a_layer():
    assert set(PYTHON_PACKAGES) == set(LAYERS)


def test_no_import_cycle_between_modules():
    cycle = find_cycle(import_graph())
    assert cycle is None, 'import cycle: ' + ' -> '.join(cycle)


def test_no_package_imports_one_above_it():
    upward = sorted(f'{mod} imports {dep}' for mod, deps in import_graph().items() for dep in deps
                    if RANK[dep.split('.')[0]] > RANK[mod.split('.')[0]])
    assert not upward, '\n'.join(upward)


@pytest.mark.parametrize('pkg', PYTHON_PACKAGES)
def test_imported_workspace_packages_are_declared_in_package_xml(pkg):
    doc = minidom.parse(str(ROOT / 'src' / pkg / 'package.xml'))
    declared = {e.firstChild.data.strip() for tag in ('depend', 'exec_depend')
                for e in doc.getElementsByTagName(tag)}
    used = {dep.split('.')[0] for mod, deps in import_graph().items() if mod.split('.')[0] == pkg
            for dep in deps} - {pkg}
    assert used <= declared, f'{pkg} imports {sorted(used - declared)} without an exec_depend'


def test_the_checks_catch_a_cycle_and_an_upward_import(tmp_path):
    """The walker itself: a planted cycle and a planted upward import are found."""
    graph = {'skeleton_core.a': {'skeleton_core.b'}, 'skeleton_core.b': {'skeleton_core.a'},
             'skeleton_core.c': set()}
    assert find_cycle(graph) == ['skeleton_core.a', 'skeleton_core.b', 'skeleton_core.a']
    pkg = tmp_path / 'skeleton_core' / 'skeleton_core'
    pkg.mkdir(parents=True)
    (pkg / '__init__.py').write_text('')
    (pkg / 'x.py').write_text('def f():\n    from viz.markers import m\n    from . import y\n')
    (pkg / 'y.py').write_text('')
    names = set(_imports(pkg / 'x.py', 'skeleton_core.x'))
    assert {'viz.markers', 'skeleton_core.y'} <= names


@pytest.mark.parametrize('pkg', PYTHON_PACKAGES)
def test_entry_points_run_the_packages_own_modules(pkg):
    """An executable of package P runs a module of P (``ros2 run P exe``), never one of another."""
    import re
    targets = re.findall(r"'\w+ = ([\w.]+):\w+'", (ROOT / 'src' / pkg / 'setup.py').read_text())
    foreign = [t for t in targets if t.split('.')[0] != pkg]
    assert not foreign, f'{pkg}/setup.py runs {foreign}'
