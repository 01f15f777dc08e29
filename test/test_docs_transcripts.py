"""IDENTIFICATION.md's and results_whatif.md's transcripts are as printed now.

``scripts/doc_examples.py --check`` per doc, the varying numbers left out (test_docs.py says
how); a module of its own so that the suite's two workers share the docs' checks
(``helpers.DOC_EXAMPLE_MODULES``).
"""
from pathlib import Path

from helpers import assert_doc_examples_printed, DOC_EXAMPLE_MODULES
import pytest


@pytest.mark.parametrize('doc', DOC_EXAMPLE_MODULES[Path(__file__).name])
def test_every_shown_example_is_what_its_command_prints(doc, tmp_path):
    assert_doc_examples_printed(doc, tmp_path)
