"""The package's layers, read from its imports: no module imports itself through others.

Every ``import`` and ``from ... import`` of a ``gripper_ros`` module, at any depth of a file
(imports inside functions count too), is read with ``ast``; a cycle among them, or a bag tool
that reaches for the ROS graph, fails here with the modules named.
"""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / 'gripper_ros'


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


def test_the_finder_finds_a_cycle():
    assert find_cycle({'a': {'b'}, 'b': {'c'}, 'c': {'a'}}) == ['a', 'b', 'c', 'a']
    assert find_cycle({'a': {'b'}, 'b': set()}) == []


def test_the_package_has_no_import_cycle():
    assert find_cycle(import_graph()) == []


def test_bag_tools_do_not_drive_the_graph():
    """bags/ reads, writes and analyses bags; driving the ROS graph belongs to apps/ and nodes/."""
    graph = import_graph()
    reaching = {name: sorted(t for t in targets if t.startswith('gripper_ros.nodes'))
                for name, targets in graph.items() if name.startswith('gripper_ros.bags')}
    assert {name: t for name, t in reaching.items() if t} == {}
