#!/usr/bin/env python3
"""Regenerate the example outputs docs/ shows, by running the commands that print them.

    source scripts/env.sh
    python3 scripts/doc_examples.py                  # every doc below (tens of minutes)
    python3 scripts/doc_examples.py BAG_TOOLS.md     # one doc (about two minutes)
    python3 scripts/doc_examples.py --list           # what is regenerated, and how

A transcript in a doc is a fenced block of ``$ COMMAND`` lines, each followed by what the command
printed (and ``[exit N]`` where the doc shows the exit status). Three kinds of example:

* docs/BAG_TOOLS.md: ``docs/bag_tools/examples.sh`` records the bags and writes the inputs its
  examples use, then prints every example; each ``$ COMMAND`` of the doc takes the output of the
  same command there (bag names matched without their time stamps and process ids).
* the transcripts of ``TRANSCRIPTS`` docs: their commands run in order in a scratch folder of
  their own (``SETUP`` first), bag names carried from the bag that made them to the commands
  that use them. A block whose commands cannot all run as shown (an exit status other than the
  doc's, an input only a reader has) stays as it is, and is listed.
* whole files (``FILES``): a command run from the repository's root, its output the file.

Each doc is rewritten in place; review with ``git diff`` (wall times and dates change every
run). Exits 1 when an example could not be regenerated (each named), 0 otherwise.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / 'docs'
BIN = ROOT / 'install' / 'gripper_ros' / 'lib' / 'gripper_ros'
CONFIG = ROOT / 'install' / 'gripper_ros' / 'share' / 'gripper_ros' / 'config' / 'gripper.yaml'
BAG_TOOLS_OUT = Path('/tmp/bt24')
"""Where examples.sh records: the folder docs/BAG_TOOLS.md names in its commands and output."""

BAG_TOOLS = 'BAG_TOOLS.md'
TRANSCRIPTS = ('GRIP.md', 'IDENTIFICATION.md', 'STUDIES.md', 'results_whatif.md')
SETUP = {
    'IDENTIFICATION.md': (f'cp {ROOT}/test/data/hidden_gripper.yaml my_gripper.yaml && '
                          f'ln -s {ROOT}/config config'),
    'GRIP.md': f'ln -s {DOCS} docs',
}
"""Shell set-up of a doc's scratch folder: the inputs its text says the reader has."""
FILES = {'contact_sweep.txt': 'contact_sweep --plot docs/contact_sweep.png',
         'contact_sweep_fingers.txt': 'contact_sweep --fingers',
         'grip_study.txt': 'grip_study --plot docs/grip_study.png'}

BAG_NAME = re.compile(r'\b(?:grasp|move|excite)_\d{8}_\d{6}_[\w.]+?_\d+\b')
EXIT = re.compile(r'^\[exit (\d+)\]$')
ROS_LOG = re.compile(r'^\[(DEBUG|INFO)\] \[[\d.]+\] \[')
"""A node's log line: the transcripts leave them out (as ``grep -v '^\\[INFO\\]'`` does)."""


def bag_key(name: str) -> str:
    """Return a bag's name without its time stamp and process id: the same run's name."""
    return re.sub(r'_\d+$', '', re.sub(r'_\d{8}_\d{6}_', '_', name))


def command_key(command: str) -> str:
    """Return ``command`` with its bags' names keyed and the checkout's path left out."""
    command = re.sub(r'\S*/(docs/bag_tools/)', r'\1', command)
    return BAG_NAME.sub(lambda m: bag_key(m.group()), command)


def run(command: str, cwd: Path) -> tuple[str, int]:
    """Run ``command`` in bash as the docs do (stderr with stdout); return (output, status)."""
    env = dict(os.environ, PATH=f'{BIN}{os.pathsep}{os.environ.get("PATH", "")}')
    done = subprocess.run(['bash', '-c', command], cwd=cwd, env=env, text=True,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          stdin=subprocess.DEVNULL)
    return done.stdout, done.returncode


# --- transcripts in a doc --------------------------------------------------------------------
def blocks(lines: list[str]) -> list[tuple[int, int]]:
    """Return (first, end) line indices of each fenced block's body that starts with ``$ ``."""
    out, start = [], None
    for i, line in enumerate(lines):
        if line.startswith('```'):
            if start is None:
                start = i + 1
            else:
                if start < i and lines[start].startswith('$ '):
                    out.append((start, i))
                start = None
    return out


def entries(body: list[str]) -> list[tuple[str, list[str]]]:
    """Split a transcript into (command, output lines); a command goes on past a backslash."""
    out: list[tuple[str, list[str]]] = []
    i = 0
    while i < len(body):
        command = body[i][2:]
        while command.endswith('\\') and i + 1 < len(body):
            i += 1
            command = command[:-1] + ' ' + body[i].strip()
        i += 1
        output = []
        while i < len(body) and not body[i].startswith('$ '):
            output.append(body[i])
            i += 1
        out.append((command, output))
    return out


def render(command: str, output: list[str]) -> list[str]:
    """Return a transcript entry's lines, without trailing white space (markdown keeps none).

    Paths inside this checkout read relative to it, as a reader's own checkout prints them.
    """
    def relative(line: str) -> str:
        return line.replace(f'{ROOT}/', '').rstrip()
    return [f'$ {relative(command)}', *(relative(line) for line in output)]


# --- docs/BAG_TOOLS.md ----------------------------------------------------------------------
def bag_tools_transcript() -> dict[str, tuple[str, list[str]]]:
    """Run examples.sh; return its entries by command with bag names keyed (bag_key)."""
    text, _ = run(f'bash {DOCS / "bag_tools" / "examples.sh"} {BAG_TOOLS_OUT}', ROOT)
    body = [line for line in text.splitlines() if not line.startswith('## ')]
    first = next(i for i, line in enumerate(body) if line.startswith('$ '))
    return {command_key(command): (command, output) for command, output in entries(body[first:])}


def regenerate_bag_tools(missed: list[str]) -> None:
    path = DOCS / BAG_TOOLS
    lines = path.read_text().splitlines()
    transcript = bag_tools_transcript()
    for first, end in reversed(blocks(lines)):
        new = []
        for command, output in entries(lines[first:end]):
            key = command_key(command)
            if key in transcript:
                new += render(*transcript[key])
            else:
                new += render(command, output)
                missed.append(f'{BAG_TOOLS}: $ {command} (not printed by examples.sh)')
        lines[first:end] = new
    path.write_text('\n'.join(lines) + '\n')


# --- the other transcripts ------------------------------------------------------------------
def regenerate_transcripts(doc: str, scratch: Path, missed: list[str]) -> None:
    path = DOCS / doc
    lines = path.read_text().splitlines()
    folder = scratch / doc.replace('.md', '')
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    if doc in SETUP:
        run(SETUP[doc], folder)
    names: dict[str, str] = {}              # bag_key -> the name this run gave it
    replaced = []
    for first, end in blocks(lines):
        new, whole = [], True
        for command, output in entries(lines[first:end]):
            live = BAG_NAME.sub(lambda m: names.get(bag_key(m.group()), m.group()), command)
            printed, status = run(live, folder)
            shown = EXIT.match(output[-1]) if output else None
            if status != (int(shown.group(1)) if shown else 0):
                missed.append(f'{doc}: $ {command} (exit {status}; the doc shows '
                              f'{shown.group(1) if shown else 0})')
                whole = False
                break
            for name in BAG_NAME.findall(printed):
                names[bag_key(name)] = name
            kept = [line for line in printed.splitlines() if not ROS_LOG.match(line)]
            new += render(live, kept + ([f'[exit {status}]'] if shown else []))
        if whole:
            replaced.append((first, end, new))
    for first, end, new in reversed(replaced):
        lines[first:end] = new
    path.write_text('\n'.join(lines) + '\n')


def regenerate_file(name: str, missed: list[str]) -> None:
    printed, status = run(FILES[name], ROOT)
    if status != 0:
        missed.append(f'docs/{name}: {FILES[name]} (exit {status})')
        return
    (DOCS / name).write_text(printed)


def main(argv=None) -> int:
    every = (BAG_TOOLS, *TRANSCRIPTS, *FILES)
    parser = argparse.ArgumentParser(prog='doc_examples', description=__doc__.splitlines()[0])
    parser.add_argument('docs', nargs='*', metavar='DOC', help=f'of: {", ".join(every)}')
    parser.add_argument('--scratch', default=None,
                        help='folder for the bags and inputs of the transcripts (default: a new '
                             f'temporary one; BAG_TOOLS.md records under {BAG_TOOLS_OUT})')
    parser.add_argument('--list', action='store_true', help='say what is regenerated, and how')
    args = parser.parse_args(argv)
    unknown = sorted(set(args.docs) - set(every))
    if unknown:
        parser.error(f'no examples regenerated in {", ".join(unknown)}; known: '
                     f'{", ".join(every)}')
    if args.list:
        print(f'docs/{BAG_TOOLS}: the transcript of docs/bag_tools/examples.sh')
        for doc in TRANSCRIPTS:
            print(f'docs/{doc}: its transcripts, run in order'
                  + (f' after: {SETUP[doc]}' if doc in SETUP else ''))
        for name, command in FILES.items():
            print(f'docs/{name}: {command}')
        return 0
    if not (BIN / 'bag_info').is_file():
        parser.error(f'{BIN} has no executables: run scripts/setup.sh and source scripts/env.sh')
    scratch = Path(args.scratch or tempfile.mkdtemp(prefix='doc_examples_'))
    missed: list[str] = []
    for doc in args.docs or every:
        print(f'doc_examples: {doc} ...', flush=True)
        if doc == BAG_TOOLS:
            regenerate_bag_tools(missed)
        elif doc in TRANSCRIPTS:
            regenerate_transcripts(doc, scratch, missed)
        else:
            regenerate_file(doc, missed)
    for line in missed:
        print(f'doc_examples: not regenerated: {line}')
    return 1 if missed else 0


if __name__ == '__main__':
    sys.exit(main())
