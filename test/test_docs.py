"""The docs' lists and example outputs are the package's: what its programs print.

Known answers: setup.py's console scripts, the launch file's ``ARGUMENTS`` (read from its
source, so the check needs no ``launch`` package), ``wire.LAUNCHED_NODES`` and the node modules
of ``gripper_ros.nodes``. A doc that names a program, node or argument the package lacks, or
leaves out one it has, fails here with both lists. Every example output ``scripts/doc_examples.py``
regenerates is run again (``--check``, in the modules of ``helpers.DOC_EXAMPLE_MODULES``): a
shown line that differs from what its command prints now fails, named with both, the numbers
that vary from run to run (wall times, bag names' stamps, the checkout's path) left out.
"""
from __future__ import annotations

import ast
import re

from gripper_ros.nodes import NODE_MODULES
from gripper_ros.wire import LAUNCHED_NODES
from helpers import console_scripts, DOC_EXAMPLE_MODULES, doc_examples, REPO
import pytest

DOCS = REPO / 'docs'
NUMBER_WORDS = ('zero', 'one', 'two', 'three', 'four', 'five', 'six', 'seven', 'eight', 'nine',
                'ten', 'eleven', 'twelve')


def launch_arguments() -> dict[str, object]:
    """Return the launch file's ARGUMENTS: name -> default (None where it is not a literal)."""
    tree = ast.parse((REPO / 'launch' / 'gripper.launch.py').read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, 'id', '') == 'ARGUMENTS'
                                                for t in node.targets):
            out = {}
            for entry in node.value.elts:
                name, default = entry.elts[0], entry.elts[1]
                out[ast.literal_eval(name)] = (default.value if isinstance(default, ast.Constant)
                                               else None)
            return out
    raise AssertionError('launch/gripper.launch.py has no ARGUMENTS')


def section(doc: str, heading: str) -> str:
    """Return the text of ``doc`` under ``heading`` (a whole heading line) up to the next one."""
    text = (DOCS / doc).read_text()
    match = re.search(rf'^#+ {re.escape(heading)}\n(.*?)(?=^#+ |\Z)', text, re.M | re.S)
    assert match, f'{doc} has no heading "{heading}"'
    return match.group(1)


def table(text: str, header: str) -> list[list[str]]:
    """Return the cells of the markdown table whose header row starts with ``| header |``."""
    lines = text.splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith(f'| {header} |')), None)
    assert start is not None, f'no table with a "{header}" column'
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith('|'):
            break
        rows.append([cell.strip() for cell in line.strip().strip('|').split('|')])
    return rows


def names(cell: str) -> list[str]:
    """Return the backticked names in a cell."""
    return re.findall(r'`([^`]+)`', cell)


def test_setup_md_lists_every_executable_of_setup_py():
    rows = table(section('SETUP.md', 'Files'), 'kind')
    listed = [name for _, cell in rows for name in names(cell)]
    assert sorted(listed) == sorted(console_scripts())
    nodes = next(cell for kind, cell in rows if kind == 'nodes')
    assert sorted(names(nodes)) == sorted(NODE_MODULES)


def test_setup_md_lists_the_launch_files_arguments_and_defaults():
    arguments = launch_arguments()
    rows = table(section('SETUP.md', 'Launching on a system ROS 2'), 'argument')
    documented = {names(name)[0]: default for name, default, _ in rows}
    assert sorted(documented) == sorted(arguments)
    for name, default in arguments.items():
        if default is not None:            # a literal: the table shows it
            shown = documented[name]
            assert shown == (f'`{default}`' if default else '(empty)'), name


def test_setup_md_names_the_nodes_the_launch_file_starts():
    text = section('SETUP.md', 'Launching on a system ROS 2')
    paragraph = text[text.index('`launch/gripper.launch.py`'):text.index('| argument |')]
    listed = [n for n in names(paragraph) if n in NODE_MODULES]
    assert sorted(listed) == sorted(LAUNCHED_NODES)
    assert f'the {NUMBER_WORDS[len(LAUNCHED_NODES)]} of `wire.LAUNCHED_NODES`' in paragraph


def test_using_md_describes_every_node_and_counts_the_launched_ones():
    text = section('USING.md', 'The node graph, in more detail')
    rows = table(text, 'node')
    described = [name for cell, _ in rows for name in names(cell)]
    assert sorted(described) == sorted(NODE_MODULES)
    assert text.lstrip().startswith(f'{NUMBER_WORDS[len(NODE_MODULES)].capitalize()} nodes')
    assert f'The launch file starts {NUMBER_WORDS[len(LAUNCHED_NODES)]} of them' in text


def test_every_doc_with_examples_is_checked_by_one_module():
    """Each doc doc_examples.py regenerates (its --list) is checked by one test module.

    The checks run in :data:`helpers.DOC_EXAMPLE_MODULES`'s modules, so that the suite's two
    workers share them; a doc added to doc_examples.py and to none of them fails here.
    """
    listed = doc_examples('--list').stdout
    regenerated = re.findall(r'^docs/(\S+):', listed, re.MULTILINE)
    checked = [doc for docs in DOC_EXAMPLE_MODULES.values() for doc in docs]
    assert sorted(checked) == sorted(regenerated)
    for module, docs in DOC_EXAMPLE_MODULES.items():
        source = (REPO / 'test' / module).read_text()
        assert 'assert_doc_examples_printed' in source and 'DOC_EXAMPLE_MODULES[' in source, module


def test_a_drift_in_a_shown_figure_is_found(tmp_path, monkeypatch):
    """A figure changed in a copy of RESULTS.md's position floor is named, with both lines."""
    import importlib.util
    spec = importlib.util.spec_from_file_location('doc_examples', REPO / 'scripts' /
                                                  'doc_examples.py')
    doc_examples = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(doc_examples)
    text = (DOCS / 'RESULTS.md').read_text()
    shown = re.search(r'minimum RMS error over 20 s \(samples 0\.\.2000\): (\S+) m', text)
    planted = text.replace(shown.group(0), shown.group(0).replace(shown.group(1), '9.87654'))
    lines = doc_examples.differences('RESULTS.md', planted, text)
    assert len(lines) == 2 and '9.87654' in lines[0] and shown.group(1) in lines[1], lines
    assert doc_examples.differences('RESULTS.md', text, text) == []


def test_what_varies_from_run_to_run_is_left_out():
    import importlib.util
    spec = importlib.util.spec_from_file_location('doc_examples', REPO / 'scripts' /
                                                  'doc_examples.py')
    doc_examples = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(doc_examples)
    a = [' width m  mass kg     outcome  wall s', '   0.010    1.270     HOLDING    0.18',
         'bag: bags/grasp_20261206_054616_1_w10mm_m1.27kg_26105',
         'contact_sweep: 760 grasps in 24 s wall', 'excite: 7 moves in 20.01 s (wall 3.3 s)']
    b = [' width m  mass kg     outcome  wall s', '   0.010    1.270     HOLDING    0.45',
         'bag: bags/grasp_20261201_203919_1_w10mm_m1.27kg_25213',
         'contact_sweep: 760 grasps in 33 s wall', 'excite: 7 moves in 20.01 s (wall 0.8 s)']
    assert doc_examples.masked(a) == doc_examples.masked(b)
    c = list(b)
    c[1] = '   0.010    1.271     HOLDING    0.45'           # a simulated figure: never masked
    c[4] = 'excite: 7 moves in 20.02 s (wall 0.8 s)'
    assert [i for i, (x, y) in enumerate(zip(doc_examples.masked(a), doc_examples.masked(c)))
            if x != y] == [1, 4]


@pytest.mark.parametrize('doc', sorted(p.name for p in DOCS.glob('*.md')) + ['../README.md'])
def test_no_heading_splits_a_sentence(doc):
    """A heading follows a paragraph that ends a sentence (or a block), never one cut mid-way."""
    lines = (DOCS / doc).read_text().splitlines()
    fenced = False
    for i, line in enumerate(lines):
        if line.startswith('```'):
            fenced = not fenced
        if fenced or not line.startswith('#') or i < 2 or lines[i - 1].strip():
            continue
        before = lines[i - 2].rstrip()
        if before and not before.startswith(('#', '|', '```', '<', '!', '-', '*', '    ')):
            assert before.endswith(('.', ':', ')', '!', '?', '`', '>', '*', '|')), \
                f'{doc}:{i + 1}: "{line}" follows "{before}"'
