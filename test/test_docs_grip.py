"""docs/GRIP.md's transcripts are as printed now.

``scripts/doc_examples.py --check --rows`` per doc, the varying numbers left out (test_docs.py
says how): ``grip_study --jobs 2``'s lines are compared with docs/grip_study.txt (the whole
study, which test_docs_studies checks on the cases it names); every other command runs. A module
of its own so that the suite's workers share the docs' checks (``helpers.DOC_EXAMPLE_MODULES``).
"""
from pathlib import Path

from helpers import assert_doc_examples_printed, DOC_EXAMPLE_MODULES, STUDY_ROWS
import pytest


@pytest.mark.parametrize('doc', DOC_EXAMPLE_MODULES[Path(__file__).name])
def test_every_shown_example_is_what_its_command_prints(doc, tmp_path):
    assert_doc_examples_printed(doc, tmp_path, '--rows', str(STUDY_ROWS))
