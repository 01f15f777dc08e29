"""docs/contact_sweep.txt, contact_sweep_fingers.txt and grip_study.txt are what the studies print.

``scripts/doc_examples.py --check --rows N`` per doc: a contact_sweep table's objects, every
row, are the program's grid of them, and N of its rows, spread evenly, are grasped again alone
and printed as the doc shows them (each row is one object grasped on its own, so a row alone
is what the whole study prints for it); grip_study.txt's named cases are grasped again alone.
The whole studies (tens of minutes) are ``doc_examples.py --check`` without ``--rows``.
Known answers for the check itself: a figure edited in a copy of a doc fails it.
"""
import importlib.util
from pathlib import Path
import shutil

from helpers import assert_doc_examples_printed, DOC_EXAMPLE_MODULES, REPO, STUDY_ROWS
import pytest


@pytest.mark.parametrize('doc', DOC_EXAMPLE_MODULES[Path(__file__).name])
def test_every_shown_example_is_what_its_command_prints(doc, tmp_path):
    assert_doc_examples_printed(doc, tmp_path, '--rows', str(STUDY_ROWS))


@pytest.fixture
def doc_examples(tmp_path, monkeypatch):
    """scripts/doc_examples.py as a module, reading its docs from a copy in ``tmp_path``."""
    spec = importlib.util.spec_from_file_location('doc_examples',
                                                  REPO / 'scripts' / 'doc_examples.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    for name in ('contact_sweep.txt', 'grip_study.txt'):
        shutil.copy(REPO / 'docs' / name, tmp_path / name)
    monkeypatch.setattr(module, 'DOCS', tmp_path)
    return module


def _edit(path: Path, index: int, old: str, new: str) -> str:
    """Replace the last ``old`` in line ``index`` of ``path`` with ``new``; return the line."""
    lines = path.read_text().splitlines()
    head, _, tail = lines[index].rpartition(old)
    assert head or tail, f'no {old!r} in {lines[index]!r}'
    lines[index] = head + new + tail
    path.write_text('\n'.join(lines) + '\n')
    return lines[index]


def test_a_figure_edited_in_a_grasped_row_or_an_object_of_the_table_fails(doc_examples):
    path = doc_examples.DOCS / 'contact_sweep.txt'
    lines = path.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if line.lstrip().startswith('k N/m')) + 1
    assert doc_examples.sweep_rows_sample('contact_sweep.txt', 1) == []   # row 1, grasped
    peak = lines[first].split()[8]
    edited = _edit(path, first, peak, f'{float(peak) + 0.0001:.4f}')
    drift = doc_examples.sweep_rows_sample('contact_sweep.txt', 1)
    assert f'docs/contact_sweep.txt:{first + 1}: shown:   {edited}' in drift, drift
    shutil.copy(REPO / 'docs' / 'contact_sweep.txt', path)
    last = next(i for i, line in enumerate(lines) if line.startswith('width, placed:')) - 1
    mass = lines[last].split()[5]
    _edit(path, last, f' {mass} ', f' {float(mass) + 1:.2f} ')    # an object not grasped
    assert doc_examples.sweep_rows_sample('contact_sweep.txt', 1), 'the edited object passed'


def test_a_figure_edited_in_grip_study_s_named_case_fails(doc_examples):
    path = doc_examples.DOCS / 'grip_study.txt'
    lines = path.read_text().splitlines()
    index = next(i for i, line in enumerate(lines) if ', largest slip: ' in line)
    edited = _edit(path, index, 'margin mean 1.', 'margin mean 2.')
    drift = doc_examples.grip_study_sample('grip_study.txt')
    assert any(line.endswith(edited) for line in drift), drift
    assert len(drift) == 2, drift           # that line alone: shown, and what is printed
