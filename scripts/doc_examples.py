#!/usr/bin/env python3
"""Regenerate the example outputs docs/ shows, by running the commands that print them.

    source scripts/env.sh
    python3 scripts/doc_examples.py                  # every doc below (tens of minutes)
    python3 scripts/doc_examples.py BAG_TOOLS.md     # one doc (about two minutes)
    python3 scripts/doc_examples.py --list           # what is regenerated, and how
    python3 scripts/doc_examples.py --check BAG_TOOLS.md   # say where a doc differs; write nothing

A transcript in a doc is a fenced block of ``$ COMMAND`` lines, each followed by what the command
printed (and ``[exit N]`` where the doc shows the exit status). Three kinds of example:

* docs/BAG_TOOLS.md: ``docs/bag_tools/examples.sh`` records the bags and writes the inputs its
  examples use, then prints every example; each ``$ COMMAND`` of the doc takes the output of the
  same command there (bag names matched without their time stamps and process ids).
* the transcripts of ``TRANSCRIPTS`` docs: their commands run in order in a scratch folder of
  their own (``SETUP`` first), bag names carried from the bag that made them to the commands
  that use them. A block whose commands cannot all run as shown (an exit status other than the
  doc's, an input only a reader has) stays as it is, and is listed.
* a command and its output (``PAIRS`` docs): a ```` ```bash ```` block of one command, then a
  plain fenced block of what it printed (``ros2 run gripper_ros NAME`` runs ``NAME``).
* whole files (``FILES``): a command run from the repository's root, its output the file.

Shown as they vary (:func:`masked`): the numbers a run cannot repeat, wall-clock times (a ``wall
s`` column, ``N s wall``, ``wall N s``), bag names' time stamps and process ids (bag_key), and
this checkout's path, shown as ``<checkout>``. Everything else a program prints is the same on
every run and every machine (the simulation runs in simulated time, bit for bit).

Each doc is rewritten in place; review with ``git diff``. ``--check`` writes nothing and prints,
per doc, each shown line that differs from what the program prints now, the varying numbers left
out. Exits 1 when an example could not be regenerated or (with ``--check``) differs, each
named; 0 otherwise.

``--check --rows N`` checks a contact_sweep table (:data:`SWEEPS`) on N of its rows, spread
evenly over it, each grasped by the program alone (the rows are independent: each object is
grasped on its own, and its floors are exact minima), with the row's lines in the summary, and
the table's objects, every row, against the program's grid of them (nothing simulated). That is
the suite's check of those docs (test/test_docs_*.py); the whole study, without ``--rows``, is
the check before a release and what regenerates them.
"""
from __future__ import annotations

import argparse
import difflib
import os
from pathlib import Path
import re
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / 'docs'
BIN = ROOT / 'install' / 'gripper_ros' / 'lib' / 'gripper_ros'
CONFIG = ROOT / 'install' / 'gripper_ros' / 'share' / 'gripper_ros' / 'config' / 'gripper.yaml'
BAG_TOOLS_OUT = Path('/tmp/bt24')
"""Where examples.sh records: the folder docs/BAG_TOOLS.md names in its commands and output."""

BAG_TOOLS = 'BAG_TOOLS.md'
TRANSCRIPTS = ('GRIP.md', 'IDENTIFICATION.md', 'STUDIES.md', 'USING.md', 'results_whatif.md')
CHATTER = ("python3 -c 'from rosbags.rosbag2 import StoragePlugin, Writer; "
           'from rosbags.typesys import get_typestore, Stores; '
           'ts = get_typestore(Stores.ROS2_JAZZY); S = ts.types["std_msgs/msg/String"]; '
           'w = Writer("chatter", version=9, storage_plugin=StoragePlugin.MCAP); w.open(); '
           'c = w.add_connection("/chatter", S.__msgtype__, typestore=ts); '
           'w.write(c, 0, ts.serialize_cdr(S(data="hello"), S.__msgtype__)); w.close()' + "'")
"""A bag of another program (one String on /chatter), which results_whatif.md's reader has."""
SETUP = {
    'IDENTIFICATION.md': (f'cp {ROOT}/test/data/hidden_gripper.yaml my_gripper.yaml && '
                          f'cp {ROOT}/test/data/slow_gripper.yaml slow_gripper.yaml && '
                          f'ln -s {ROOT}/config config'),
    'GRIP.md': f'ln -s {DOCS} docs',
    'results_whatif.md': CHATTER,
}
"""Shell set-up of a doc's scratch folder: the inputs its text says the reader has."""
CHECK_SETUP = {'GRIP.md': f'cp -r {DOCS} docs'}
"""The set-up instead, for ``--check``: a copy of docs/, so that the figures the commands write
there (``grip_study --plot-step docs/grip_step.png``) do not overwrite the checkout's."""
SHOWN_IN = {'GRIP.md': {'grip_study --jobs 2': 'grip_study.txt'}}
"""Commands whose output is also a whole file of docs/ (FILES): with ``--rows``, the doc's lines
are compared with that file's, which is checked on its own (the whole study is not run twice)."""
FILES = {'contact_sweep.txt': 'contact_sweep --plot docs/contact_sweep.png',
         'contact_sweep_fingers.txt': 'contact_sweep --fingers',
         'grip_study.txt': 'grip_study --plot docs/grip_study.png'}

PAIRS = ('RESULTS.md',)
NOT_RUN = {
    'USING.md': ('bench_launch_stop', 'ros2 run gripper_ros grasp_demo --serve'),
}
"""Transcripts shown but not run: a benchmark's wall-clock figures, a graph served in several
terminals (each line of a doc's transcript starting so)."""
NOT_COMPARED = {
    'STUDIES.md': ('tune ',),
}
"""Commands regenerated but not run by ``--check``: their output is not the same from run to
run (tune's trials on two workers: which trial the sampler sees first decides the next one)."""
CHECKOUT = '<checkout>'
"""How a doc shows this checkout's path (the reader's own, wherever it is)."""

BAG_NAME = re.compile(r'\b(?:grasp|move|excite)_\d{8}_\d{6}_[\w.]+?_\d+\b')
EXIT = re.compile(r'^\[exit (\d+)\]$')
LOG_TIME = re.compile(r'^(\[(?:WARN|ERROR|FATAL)\]) \[[\d.]+\]')
"""A node's warning: shown with its time as ``[...]``."""
ROS_LOG = re.compile(r'^\[(DEBUG|INFO)\] \[[\d.]+\] \[')
"""A node's log line: the transcripts leave them out (as ``grep -v '^\\[INFO\\]'`` does)."""


def bag_key(name: str) -> str:
    """Return a bag's name without its time stamp and process id: the same run's name."""
    return re.sub(r'_\d+$', '', re.sub(r'_\d{8}_\d{6}_', '_', name))


def command_key(command: str) -> str:
    """Return ``command`` with its bags' names keyed and the checkout's path left out."""
    command = re.sub(r'\S*/(docs/bag_tools/)', r'\1', command)
    return BAG_NAME.sub(lambda m: bag_key(m.group()), command)


CLAIMS: dict[str, str] = {}
"""``GRIPPER_ROS_CLAIMS_DIR`` of the commands run: a folder of this run's own (main sets it), so
request ids start at 1, as on a reader's first run, and no other run's names get in the way."""


def run(command: str, cwd: Path) -> tuple[str, int]:
    """Run ``command`` in bash as the docs do (stderr with stdout); return (output, status)."""
    env = dict(os.environ, PATH=f'{BIN}{os.pathsep}{os.environ.get("PATH", "")}', **CLAIMS)
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
            command += '\n' + body[i]                  # bash runs it so, and it reads so
        i += 1
        output = []
        while i < len(body) and not body[i].startswith('$ '):
            output.append(body[i])
            i += 1
        out.append((command, output))
    return out


def render(command: str, output: list[str]) -> list[str]:
    """Return a transcript entry's lines, without trailing white space (markdown keeps none).

    The command names this checkout's files relative to it; its output shows the checkout's path
    as :data:`CHECKOUT`.
    """
    return [f'$ {command.replace(f"{ROOT}/", "").rstrip()}',
            *(LOG_TIME.sub(r'\1 [...]', line.replace(str(ROOT), CHECKOUT)).rstrip()
              for line in output)]


SIM_STATUS_VARIES = (
    re.compile(r'(?<=^Bag size:)\s+\S+ \S+$'),
    re.compile(r'(?<=^Messages:)\s+\d+$'),
    re.compile(r'(?<=/sim/status ).*$'),
    re.compile(r'(?<=/supervisor/status ).*$'),
    re.compile(r'\b\d+(?= messages\b)'),
    re.compile(r'(?<=^  message_count: )\d+$'),
    re.compile(r'(?<=^\[bag_replay\] ).*$'),
    re.compile(r'(?<=\bstage_id=)\d+'),
)
"""What depends on how many sim/status a bag holds (one about every wall second: its line, a
bag's total and size), on supervisor/status's heartbeat (one a wall second when nothing
changes), bag_replay's progress line (its wall-clock position), and a stage id: it counts every
handover since the graph started, those between a realtime graph's grasps included."""
WALL = (re.compile(r'\b\d+(?:\.\d+)?(?= s wall\b)'),
        re.compile(r'(?<=\bwall )\d+(?:\.\d+)?(?= s\b)'))
"""Wall-clock times in a line: ``N s wall``, ``wall N s``."""
VARIES = '<varies>'


ELISION = re.compile(r'^(\.\.\.|\(more .*\)|)$')
"""A line of a shown output that stands for lines left out (``...``, ``(more rows)``), or a blank
one the doc puts between two commands."""


def fit(shown: list[str], printed: list[str]) -> list[str]:
    """Return the output to show: ``printed``, as abridged as ``shown`` where it can be.

    Where every line ``shown`` has (but its elisions) is one ``printed`` has, in order, with
    what varies left out (:func:`masked`), the printed lines that those are, and the elisions
    in place: a doc may show part of what a command prints (nothing, for a command whose
    result is a file). Else all of ``printed``.
    """
    if not shown:
        return []
    a, b = masked(shown), masked(printed)
    out: list[str] = []
    matcher = difflib.SequenceMatcher(None, a, b, autojunk=False)
    for tag, i1, i2, j1, j2 in matcher.get_opcodes():
        if tag == 'equal':
            out += printed[j1:j2]
        elif tag in ('delete', 'replace'):
            if not all(ELISION.match(line) for line in shown[i1:i2]):
                return printed
            out += shown[i1:i2]
    return out


def masked(lines: list[str]) -> list[str]:
    """Return ``lines`` with what varies from run to run replaced by :data:`VARIES`.

    This checkout's path as :data:`CHECKOUT`, bag names keyed (bag_key), wall-clock times, the
    last column of a table whose header ends with ``wall s``, and what depends on a bag's
    sim/status (:data:`SIM_STATUS_VARIES`).
    """
    out, wall_column = [], False
    for line in lines:
        line = re.sub(r'_\d+(_\d+\.mcap)\b', r'\1', line)      # a bag file: its process id
        line = re.sub(r'(\.\d*?)0+$', r'\1', line)   # a number cut short by `cut` (names vary)
        line = BAG_NAME.sub(lambda m: bag_key(m.group()),
                            LOG_TIME.sub(r'\1 [...]', line.replace(str(ROOT), CHECKOUT)))
        for pattern in (*WALL, *SIM_STATUS_VARIES):
            line = pattern.sub(VARIES, line)
        if wall_column and re.match(r'^\s+-?\d', line):
            line = re.sub(r'\s*\S+$', f' {VARIES}', line)
        elif line.strip():
            wall_column = line.rstrip().endswith('wall s') or (wall_column and
                                                               line.startswith(' '))
        out.append(line)
    return out


# --- docs/BAG_TOOLS.md ----------------------------------------------------------------------
KILLED_SECTION = '## a bag killed'
"""examples.sh's section whose outputs vary as a whole: where a kill -9 lands in a grasp."""


def bag_tools_transcript(out: Path) -> tuple[dict[str, tuple[str, list[str]]], set[str]]:
    """Run examples.sh in ``out``; return its entries by command with bag names keyed (bag_key).

    And the keys of the commands whose whole output varies (:data:`KILLED_SECTION`). ``out``
    reads as :data:`BAG_TOOLS_OUT`, the folder the doc names.
    """
    text, _ = run(f'bash {DOCS / "bag_tools" / "examples.sh"} {out}', ROOT)
    text = text.replace(str(out), str(BAG_TOOLS_OUT))
    found, varying = {}, set()
    sections = re.split(r'^(## .*)$', text, flags=re.MULTILINE)
    heading = ''
    for part in sections:
        if part.startswith('## '):
            heading = part
            continue
        lines = part.splitlines()
        first = next((i for i, line in enumerate(lines) if line.startswith('$ ')), None)
        if first is None:
            continue
        for command, output in entries(lines[first:]):
            key = command_key(command)
            found[key] = (command, output)
            if heading.startswith(KILLED_SECTION):
                varying.add(key)
    return found, varying


def regenerate_bag_tools(out: Path, missed: list[str], check: bool = False) -> str:
    """Return docs/BAG_TOOLS.md with each transcript as examples.sh prints it now (in ``out``).

    ``check``: an entry whose whole output varies keeps the doc's.
    """
    lines = (DOCS / BAG_TOOLS).read_text().splitlines()
    transcript, varying = bag_tools_transcript(out)
    for first, end in reversed(blocks(lines)):
        new = []
        for command, output in entries(lines[first:end]):
            key = command_key(command)
            if check and key in varying:
                new += render(command, output)
            elif key in transcript:
                printed_command, printed = transcript[key]
                new += render(printed_command, fit(output, printed))
            else:
                new += render(command, output)
                missed.append(f'{BAG_TOOLS}: $ {command} (not printed by examples.sh)')
        lines[first:end] = new
    return '\n'.join(lines) + '\n'


# --- the other transcripts ------------------------------------------------------------------
def regenerate_transcripts(doc: str, scratch: Path, missed: list[str],
                           check: bool = False, rows: bool = False) -> str:
    """Return ``doc`` with each transcript as its commands print now, run in order.

    ``check``: a command of :data:`NOT_COMPARED` is not run; it keeps the doc's output.
    ``rows`` (``--rows``): a command of :data:`SHOWN_IN` prints what its file holds.
    """
    lines = (DOCS / doc).read_text().splitlines()
    folder = scratch / doc.replace('.md', '')
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    if doc in SETUP:
        run(CHECK_SETUP.get(doc, SETUP[doc]) if check else SETUP[doc], folder)
    names: dict[str, str] = {}              # bag_key -> the name this run gave it
    replaced = []
    for first, end in blocks(lines):
        new, whole = [], True
        shown = entries(lines[first:end])
        if any(command.startswith(NOT_RUN.get(doc, ())) for command, _ in shown):
            continue
        for command, output in shown:
            live = BAG_NAME.sub(lambda m: names.get(bag_key(m.group()), m.group()), command)
            if check and command.startswith(NOT_COMPARED.get(doc, ())):
                new += render(live, output)
                continue
            written = re.fullmatch(r'cat (\S+)', command)
            if written and not (folder / written.group(1)).exists():
                # a file the reader wrote, shown by cat: it holds what the doc shows
                (folder / written.group(1)).write_text(''.join(f'{line}\n' for line in output))
            if rows and live in SHOWN_IN.get(doc, {}):
                printed, status = (DOCS / SHOWN_IN[doc][live]).read_text(), 0
            else:
                printed, status = run(live, folder)
            exit_shown = EXIT.match(next((line for line in reversed(output) if line), ''))
            if status != (int(exit_shown.group(1)) if exit_shown else 0):
                missed.append(f'{doc}: $ {command} (exit {status}; the doc shows '
                              f'{exit_shown.group(1) if exit_shown else 0})')
                whole = False
                break
            for name in BAG_NAME.findall(printed):
                names[bag_key(name)] = name
            kept = [line for line in printed.splitlines() if not ROS_LOG.match(line)]
            kept += [f'[exit {status}]'] if exit_shown else []
            new += render(live, fit(output, kept))
        if whole:
            replaced.append((first, end, new))
    for first, end, new in reversed(replaced):
        lines[first:end] = new
    return '\n'.join(lines) + '\n'


# --- a command and its output ---------------------------------------------------------------
def pairs(lines: list[str]) -> list[tuple[str, int, int]]:
    """Return (command, first, end) of each output block that follows a one-command bash block."""
    out = []
    i = 0
    while i < len(lines) - 4:
        if lines[i] == '```bash' and lines[i + 2] == '```' and lines[i + 3] == '' and \
                lines[i + 4] == '```':
            end = lines.index('```', i + 5)
            out.append((lines[i + 1], i + 5, end))
            i = end
        i += 1
    return out


def regenerate_pairs(doc: str, scratch: Path, missed: list[str]) -> str:
    """Return ``doc`` with each command's output block as the command prints it now."""
    lines = (DOCS / doc).read_text().splitlines()
    folder = scratch / doc.replace('.md', '')
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    for command, first, end in reversed(pairs(lines)):
        live = re.sub(r'^ros2 run gripper_ros ', '', command.split('#')[0].strip())
        printed, status = run(live, folder)
        if status != 0:
            missed.append(f'{doc}: {command} (exit {status})')
            continue
        kept = [line for line in printed.splitlines() if not ROS_LOG.match(line)]
        lines[first:end] = render('', fit(lines[first:end], kept))[1:]
    return '\n'.join(lines) + '\n'


def regenerate_file(name: str, missed: list[str], scratch: Path | None = None) -> str:
    """Return what ``name``'s command prints, run from the checkout (or from ``scratch``).

    ``scratch`` (``--check``): a folder with a ``docs`` folder of its own, where the command's
    figure goes instead of over the checkout's.
    """
    cwd = ROOT
    if scratch is not None:
        cwd = scratch / 'files'
        (cwd / 'docs').mkdir(parents=True, exist_ok=True)
    printed, status = run(FILES[name], cwd)
    if status != 0:
        missed.append(f'docs/{name}: {FILES[name]} (exit {status})')
        return (DOCS / name).read_text()
    return printed


SWEEPS = {'contact_sweep.txt': False, 'contact_sweep_fingers.txt': True}
"""The FILES that are a contact_sweep table (True: ``--fingers``'s), checkable on some rows."""


def sweep_rows_sample(name: str, count: int) -> list[str]:
    """Return where ``name``'s table differs from the program's, on ``count`` of its rows.

    Every row's object (the columns up to kg) is the program's grid's, in order (a refused
    object has no row); ``count`` rows spread evenly over the table are grasped again, alone,
    and their lines, in the table and in the summary, must be what the program prints.
    """
    from gripper_ros.apps.contact_sweep import format_rows, summary
    from gripper_ros.core.config import load_config
    from gripper_ros.studies import sweep_runs
    fingers = SWEEPS[name]
    config = load_config(None)                      # the installed one, as contact_sweep's
    cases, excluded = (sweep_runs.finger_cases if fingers else sweep_runs.envelope_cases)(config)
    nan = float('nan')
    blank = [sweep_runs.SweepRow(c.contact, c.stiffness_n_per_m, c.damping_ratio,
                                 c.damping_n_s_per_m, c.width_m, c.object_width_m,
                                 c.width_tolerance_m, c.mass_kg, '-', nan, nan, nan, nan, nan,
                                 nan, nan, nan, nan, nan, nan, c.finger) for c in cases]
    grid = format_rows(blank).splitlines()
    header, legend, objects = grid[0], grid[-1], 7 if fingers else 6
    lines = (DOCS / name).read_text().splitlines()
    if header not in lines or legend not in lines:
        return [f'docs/{name}: no table of contact_sweep{" --fingers" if fingers else ""}']
    first, end = lines.index(header) + 1, lines.index(legend)
    shown = lines[first:end]
    found = []                              # (line index in the doc, case)
    for case, line in zip(cases, grid[1:-1]):
        k = len(found)
        if k < len(shown) and shown[k].split()[:objects] == line.split()[:objects]:
            found.append((first + k, case))
    out = [f'docs/{name}:{first + k + 1}: shown:   {shown[k]}  (not an object of the '
           "program's grid, in its order)" for k in range(len(found), len(shown))][:1]
    counted = summary(config, [blank[cases.index(c)] for _, c in found], excluded, 0.0)
    told = re.sub(r' in \S+ s wall on [^;]*', '', lines[0])
    if told != counted.splitlines()[0]:
        out += [f'docs/{name}:1: shown:   {told}', f'docs/{name}:1: printed: {counted}']
    picked = sorted({k * len(found) // count for k in range(min(count, len(found)))})
    rows = sweep_runs.sweep(config, [found[k][1] for k in picked],
                            hold_s=sweep_runs.DEFAULT_HOLD_S, jobs=1, rest_floors=not fingers)
    if len(rows) != len(picked):
        return out + [f'docs/{name}: a row of the table was refused by the program']
    printed = format_rows(rows).splitlines()[1:-1]
    told_lines = summary(config, rows, excluded, sweep_runs.DEFAULT_HOLD_S).splitlines()
    for k, row, line in zip(picked, rows, printed):
        at = found[k][0]
        if masked([lines[at]]) != masked([line]):
            out += [f'docs/{name}:{at + 1}: shown:   {lines[at]}',
                    f'docs/{name}:{at + 1}: printed: {line}']
        if row.width_tolerance_m > 0.0:     # its line in the summary, after the table's rows
            mine = [t for t in told_lines if t.startswith('  ') and
                    t.split()[:len(_described(row))] == _described(row)]
            theirs = [i for i, t in enumerate(lines[:first]) if t.startswith('  ') and
                      t.split()[:len(_described(row))] == _described(row)]
            for i, t in zip(theirs, mine):
                if lines[i] != t:
                    out += [f'docs/{name}:{i + 1}: shown:   {lines[i]}',
                            f'docs/{name}:{i + 1}: printed: {t}']
    print(f"doc_examples: {name}: {len(found)} rows are the grid's objects; {len(picked)} of "
          'them grasped again', flush=True)
    return out


NAMED_CASE = re.compile(r'^(?P<label>.+), largest (?P<what>slip|mean margin): (?P<kg>\S+) kg, '
                        r'mu_s (?P<mu>\S+), (?P<profile>[^:]+): slip ')
"""A line of grip_study's that names one case (the largest slip or mean margin of a law)."""


def grip_study_sample(name: str = 'grip_study.txt') -> list[str]:
    """Return where the cases ``name`` names differ from what grip_study prints for them.

    Each case a line names (a law's largest slip and largest mean margin, in the study and in
    the instant steps) is grasped again, alone, and its line must be what the program prints.
    """
    from gripper_ros.apps import grip_study
    from gripper_ros.apps.common import with_values
    from gripper_ros.core.config import load_config
    config = with_values(load_config(None),
                         {'contact.lift_off_s': grip_study.DEFAULT_LIFT_OFF_S})
    instant = with_values(config, {'contact.lift_off_s': 0.0})
    floats = grip_study._floats
    parts = (
        (config, grip_study.LAWS, grip_study.study_cases(floats('0.2,0.5,1,2', 'masses'),
                                                         floats('0.4,0.6,0.9', 'frictions'))),
        (instant, grip_study.INSTANT_LAWS, grip_study.instant_cases(
            *(floats(text, 'instant') for text in (grip_study.INSTANT_MASSES,
                                                   grip_study.INSTANT_FRICTIONS,
                                                   grip_study.INSTANT_STEPS)))))
    lines = (DOCS / name).read_text().splitlines()
    part, out, checked = 0, [], 0
    for i, line in enumerate(lines):
        if ' instant steps: ' in line:
            part = 1
        named = NAMED_CASE.match(line)
        if not named:
            continue
        cfg, laws, cases = parts[part]
        case = next((c for c in cases if c['label'] == named['label'] and
                     f'{c["mass_kg"]:g}' == named['kg'] and f'{c["mu_s"]:g}' == named['mu'] and
                     c['profile_label'] == named['profile']), None)
        printed = '(no such case in the study)'
        if case is not None:
            row = grip_study._case(cfg, case)
            lead = f'{named["label"]}, largest {named["what"]}: '
            printed = next((t for t in grip_study.summarise([row], laws) if t.startswith(lead)),
                           f'(the case has no {named["what"]}: {row["outcome"]})')
            checked += 1
        if printed != line:
            out += [f'docs/{name}:{i + 1}: shown:   {line}',
                    f'docs/{name}:{i + 1}: printed: {printed}']
    if not checked:
        out.append(f'docs/{name}: no line names a case of grip_study')
    print(f'doc_examples: {name}: {checked} named cases grasped again', flush=True)
    return out


def _described(row) -> list[str]:
    from gripper_ros.apps.contact_sweep import _describe
    return _describe(row).split()


def differences(name: str, shown: str, printed: str) -> list[str]:
    """Return a line for each line of ``shown`` that differs from ``printed``, masked alike."""
    a, b = masked(shown.splitlines()), masked(printed.splitlines())
    out = []
    for group in difflib.SequenceMatcher(None, a, b, autojunk=False).get_grouped_opcodes(0):
        for tag, i1, i2, j1, j2 in group:
            if tag == 'equal':
                continue
            out += [f'docs/{name}:{i + 1}: shown:   {a[i]}' for i in range(i1, i2)]
            out += [f'docs/{name}:{i1 + 1}: printed: {line}' for line in b[j1:j2]]
    return out


def main(argv=None) -> int:
    every = (BAG_TOOLS, *TRANSCRIPTS, *PAIRS, *FILES)
    parser = argparse.ArgumentParser(prog='doc_examples', description=__doc__.splitlines()[0])
    parser.add_argument('docs', nargs='*', metavar='DOC', help=f'of: {", ".join(every)}')
    parser.add_argument('--scratch', default=None,
                        help='folder for the bags and inputs of the transcripts (default: a new '
                             f'temporary one; BAG_TOOLS.md records under {BAG_TOOLS_OUT} unless '
                             'one is given)')
    parser.add_argument('--check', action='store_true',
                        help='write nothing; print where each doc differs from what its '
                             'commands print now (varying numbers left out)')
    parser.add_argument('--rows', type=int, metavar='N',
                        help='with --check: a contact_sweep table (' + ', '.join(SWEEPS) +
                             ') on N rows, spread over it, grasped again alone, and its objects '
                             'against the grid; grip_study.txt on the cases it names (the '
                             "suite's check); GRIP.md's grip_study against grip_study.txt; "
                             'other docs whole')
    parser.add_argument('--list', action='store_true', help='say what is regenerated, and how')
    args = parser.parse_args(argv)
    if args.rows is not None and (not args.check or args.rows < 1):
        parser.error('--rows N needs --check and N >= 1')
    unknown = sorted(set(args.docs) - set(every))
    if unknown:
        parser.error(f'no examples regenerated in {", ".join(unknown)}; known: '
                     f'{", ".join(every)}')
    if args.list:
        print(f'docs/{BAG_TOOLS}: the transcript of docs/bag_tools/examples.sh')
        for doc in TRANSCRIPTS:
            print(f'docs/{doc}: its transcripts, run in order'
                  + (f' after: {SETUP[doc]}' if doc in SETUP else '')
                  + (f' (not run: {", ".join(NOT_RUN[doc])})' if doc in NOT_RUN else '')
                  + (f' (not compared: {", ".join(NOT_COMPARED[doc])})'
                     if doc in NOT_COMPARED else ''))
        for doc in PAIRS:
            print(f'docs/{doc}: each command block and the output block after it')
        for name, command in FILES.items():
            print(f'docs/{name}: {command}')
        return 0
    if not (BIN / 'bag_info').is_file():
        parser.error(f'{BIN} has no executables: run scripts/setup.sh and source scripts/env.sh')
    scratch = Path(args.scratch or tempfile.mkdtemp(prefix='doc_examples_'))
    missed: list[str] = []
    drift: list[str] = []
    for doc in args.docs or every:
        print(f'doc_examples: {doc} ...', flush=True)
        t0 = time.monotonic()
        claims = scratch / 'claims' / doc
        shutil.rmtree(claims, ignore_errors=True)
        CLAIMS['GRIPPER_ROS_CLAIMS_DIR'] = str(claims)
        if args.rows and doc in (*SWEEPS, 'grip_study.txt'):
            drift += (sweep_rows_sample(doc, args.rows) if doc in SWEEPS else
                      grip_study_sample(doc))
            print(f'doc_examples: {doc} done in {time.monotonic() - t0:.0f} s', flush=True)
            continue
        if doc == BAG_TOOLS:
            text = regenerate_bag_tools(
                scratch / BAG_TOOLS_OUT.name if args.scratch else BAG_TOOLS_OUT, missed,
                args.check)
        elif doc in TRANSCRIPTS:
            text = regenerate_transcripts(doc, scratch, missed, args.check, bool(args.rows))
        elif doc in PAIRS:
            text = regenerate_pairs(doc, scratch, missed)
        else:
            text = regenerate_file(doc, missed, scratch if args.check else None)
        if args.check:
            drift += differences(doc, (DOCS / doc).read_text(), text)
        else:
            (DOCS / doc).write_text(text)
        print(f'doc_examples: {doc} done in {time.monotonic() - t0:.0f} s', flush=True)
    for line in missed:
        print(f'doc_examples: not regenerated: {line}')
    for line in drift:
        print(line)
    if args.check:
        print(f'doc_examples: {len(drift)} line(s) differ' if drift else
              'doc_examples: every shown example is what its command prints')
    return 1 if missed or drift else 0


if __name__ == '__main__':
    sys.exit(main())
