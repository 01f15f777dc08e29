"""What several test modules share.

Running a console main, writing an MCAP file again, holding a closed-loop re-run to its
recording, and the package's console scripts as setup.py declares them.
"""
from __future__ import annotations

import ast
from dataclasses import asdict
import json
from pathlib import Path
import re
from typing import Callable

import numpy as np


REPO = Path(__file__).resolve().parents[1]
SWEEP_OUTPUT = REPO / 'docs' / 'contact_sweep.txt'
"""``contact_sweep``'s output, as docs/RESULTS.md quotes it."""


def console_scripts() -> dict[str, str]:
    """Return setup.py's console scripts: executable name -> ``module:function``."""
    tree = ast.parse((REPO / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            for key, value in zip(node.keys, node.values):
                if isinstance(key, ast.Constant) and key.value == 'console_scripts':
                    entries = [ast.literal_eval(e) for e in value.elts]
                    return dict((part.strip() for part in e.split('=', 1)) for e in entries)
    raise AssertionError('setup.py declares no console_scripts')


def claimed_peak_ratio() -> float:
    """Return the worst contact peak / F_sp of the published sweep (its "worst peak" lines).

    Tests hold every grasp to it, so that the published figure and the code cannot drift apart.
    """
    text = SWEEP_OUTPUT.read_text(encoding='utf-8')
    return max(float(x) for x in re.findall(r'^worst peak [^:]*: (\d+\.\d+) x F_sp', text,
                                            re.MULTILINE))


def within_claimed_peak(peak_ratio: float) -> bool:
    """Tell whether ``peak_ratio`` is within the claim at the claim's four decimals."""
    return round(peak_ratio, 4) <= claimed_peak_ratio()


def run_main(main: Callable, argv: list, capsys) -> tuple:
    """Run a console program's ``main(argv)``; return (exit code, captured output).

    The code is what it returned or what it passed to ``SystemExit``.
    """
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr()


def assert_rerun_equals_recording(w) -> None:
    """Hold a what-if re-run without changes (``rerun.whatif(bag)``) to its recording.

    No series differs (``series_difference`` checks every field); the plotted series are equal
    bit for bit; every figure is the recorded one, but those of fields the bag's own (older)
    messages lack (the pads' readings), which the recording cannot give.
    """
    r = w.reruns[0]
    assert r.difference == '', r.difference
    rec, new = w.record.series, r.series
    for a, b in ((rec.ticks['force_n'], new.ticks['force_n']),
                 (rec.ticks['position_m'], new.ticks['position_m']),
                 (rec.joint.position_m, new.joint.position_m),
                 (rec.sensor.force_n, new.sensor.force_n),
                 (rec.motor.voltage_v, new.motor.voltage_v),
                 (rec.sensor.voltage_v, new.sensor.voltage_v),
                 (rec.commands['voltage_v'], new.commands['voltage_v']),
                 (rec.objects.slip_m, new.objects.slip_m)):
        assert a.size > 0 and np.array_equal(a, b, equal_nan=True)
    skip = {'bag'} | ({'pad_shear_max_n'} if 'tick.pad1_shear_n' in rec.absent else set())
    figures = {k: v for k, v in asdict(w.recorded).items() if k not in skip}
    again = {k: v for k, v in asdict(r.metrics).items() if k not in skip}
    assert json.dumps(figures, sort_keys=True) == json.dumps(again, sort_keys=True)


def copy_mcap(src: Path, dst: Path, *, schema_text: Callable[[str], str] | None = None,
              chunk_size: int | None = None) -> Path:
    """Write the MCAP file ``src`` again as ``dst``, record for record.

    ``schema_text`` rewrites each schema's text; ``chunk_size`` sets the chunks' size (default:
    the writer's). Header, channels, messages and metadata records are copied as they are.
    """
    from mcap.reader import make_reader
    from mcap.writer import Writer
    with open(src, 'rb') as fin, open(dst, 'wb') as fout:
        reader = make_reader(fin)
        header = reader.get_header()
        summary = reader.get_summary()
        writer = Writer(fout, **({} if chunk_size is None else {'chunk_size': chunk_size}))
        writer.start(profile=header.profile, library=header.library)
        schema_ids = {}
        for sid, schema in summary.schemas.items():
            data = schema.data
            if schema_text is not None:
                data = schema_text(data.decode('utf-8')).encode('utf-8')
            schema_ids[sid] = writer.register_schema(schema.name, schema.encoding, data)
        channel_ids = {cid: writer.register_channel(c.topic, c.message_encoding,
                                                    schema_ids[c.schema_id], c.metadata)
                       for cid, c in summary.channels.items()}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            writer.add_message(channel_ids[channel.id], message.log_time, message.data,
                               message.publish_time, message.sequence)
        for record in reader.iter_metadata():
            writer.add_metadata(record.name, record.metadata)
        writer.finish()
    return dst
