"""The package's layers, read from its imports: each layer imports only the layers below it.

Every ``import`` and ``from ... import`` of a ``gripper_ros`` module, at any depth of a file
(imports inside functions count too), is read with ``ast``. A module that imports one of a
layer above its own or beside it, an app that imports another app, or an import cycle fails
here with the modules named. docs/ARCHITECTURE.md draws the same layers.
"""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / 'gripper_ros'

LAYERS = (
    ('gripper_ros.wire', 'gripper_ros.text', 'gripper_ros.progress', 'gripper_ros.native'),
    ('gripper_ros.core',),
    ('gripper_ros.core.physics',),
    ('gripper_ros.core.control',),
    ('gripper_ros.core.supervision',),
    ('gripper_ros.core.runtime',),
    ('gripper_ros.studies', 'gripper_ros.identify'),
    ('gripper_ros.bags',),
    ('gripper_ros.nodes',),
    ('gripper_ros.apps', 'gripper_ros.bench'),
    ('gripper_ros.executables',),
)
"""The layers, lowest first: a module may import its own folder and the layers below it; the
folders of one layer do not import each other. ``gripper_ros.core`` is the shared modules
directly in core/ (config, linalg, records, description, series), below every subpackage of it.
``gripper_ros.executables`` starts every program (by name, once the fix is preloaded)."""

APP_SHARED = 'gripper_ros.apps.common'
"""What the console programs share; no program imports another."""


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def import_graph() -> dict[str, set[str]]:
    """Return each package module and the package modules it imports."""
    modules = {_module_name(p): p for p in PACKAGE.rglob('*.py')}
    graph = {}
    for name, path in modules.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f'{node.module}.{a.name}' for a in node.names]
            else:
                continue
            found |= {t for t in targets if t in modules and t != name}
        graph[name] = found
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str]:
    """Return one import cycle as a list of modules (first == last), or [] when there is none."""
    state, stack = {}, []

    def visit(name):
        state[name] = 'open'
        stack.append(name)
        for nxt in sorted(graph[name]):
            if state.get(nxt) == 'open':
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        stack.pop()
        state[name] = 'done'
        return []

    for name in sorted(graph):
        if name not in state:
            cycle = visit(name)
            if cycle:
                return cycle
    return []


def folder_of(module: str) -> tuple[int, str]:
    """Return the layer (index into LAYERS) and the folder of ``module``; (-1, '') if none."""
    best = (-1, '')
    for level, folders in enumerate(LAYERS):
        for folder in folders:
            inside = module == folder or module.startswith(folder + '.')
            if inside and len(folder) > len(best[1]):
                best = (level, folder)
    return best


def layer_breaches(graph: dict[str, set[str]]) -> list[str]:
    """Return each import against the layers, as 'importer -> imported (why)'."""
    breaches = []
    for name, targets in sorted(graph.items()):
        level, folder = folder_of(name)
        for target in sorted(targets):
            t_level, t_folder = folder_of(target)
            if t_folder == folder or t_level < level:
                continue
            where = 'above' if t_level > level else 'beside'
            breaches.append(f'{name} -> {target} ({t_folder} is {where} {folder})')
    return breaches


def app_imports(graph: dict[str, set[str]]) -> list[str]:
    """Return each import of a console program's module (anything in apps/ but common.py)."""
    return [f'{name} -> {target}' for name, targets in sorted(graph.items())
            for target in sorted(targets)
            if target.startswith('gripper_ros.apps.') and target != APP_SHARED]


def test_the_finder_finds_a_cycle():
    assert find_cycle({'a': {'b'}, 'b': {'c'}, 'c': {'a'}}) == ['a', 'b', 'c', 'a']
    assert find_cycle({'a': {'b'}, 'b': set()}) == []


def test_the_package_has_no_import_cycle():
    assert find_cycle(import_graph()) == []


def test_the_checks_find_a_breach_of_each_rule():
    graph = {
        'gripper_ros.core.physics.plant': {'gripper_ros.core.control.pid'},         # up
        'gripper_ros.core.control.pid': {'gripper_ros.core.records',                # down: ok
                                         'gripper_ros.core.runtime.headless'},      # up
        'gripper_ros.core.config': {'gripper_ros.core.physics.pad_sensor'},         # up
        'gripper_ros.studies.sweep_runs': {'gripper_ros.identify.fit'},             # beside
        'gripper_ros.bags.replay': {'gripper_ros.nodes.graph'},                     # up
        'gripper_ros.core.runtime.headless': {'gripper_ros.core.control.stages'},   # down: ok
        'gripper_ros.apps.tune': {'gripper_ros.apps.contact_sweep',                 # an app
                                  'gripper_ros.apps.common'},                       # shared: ok
    }
    assert layer_breaches(graph) == [
        'gripper_ros.bags.replay -> gripper_ros.nodes.graph '
        '(gripper_ros.nodes is above gripper_ros.bags)',
        'gripper_ros.core.config -> gripper_ros.core.physics.pad_sensor '
        '(gripper_ros.core.physics is above gripper_ros.core)',
        'gripper_ros.core.control.pid -> gripper_ros.core.runtime.headless '
        '(gripper_ros.core.runtime is above gripper_ros.core.control)',
        'gripper_ros.core.physics.plant -> gripper_ros.core.control.pid '
        '(gripper_ros.core.control is above gripper_ros.core.physics)',
        'gripper_ros.studies.sweep_runs -> gripper_ros.identify.fit '
        '(gripper_ros.identify is beside gripper_ros.studies)',
    ]
    assert app_imports(graph) == ['gripper_ros.apps.tune -> gripper_ros.apps.contact_sweep']


def test_every_module_has_a_layer():
    assert [name for name in import_graph() if folder_of(name)[0] < 0] == ['gripper_ros']


def test_each_layer_imports_only_the_layers_below_it():
    """Physics never reaches for a control law, the core for a node, a bag tool for the graph.

    bags/ reads, writes and re-runs bags; driving the ROS graph belongs to nodes/ and apps/.
    """
    assert layer_breaches(import_graph()) == []


def test_no_module_imports_a_console_program():
    """A program shares through apps/common.py or a layer below, never through another program."""
    assert app_imports(import_graph()) == []
