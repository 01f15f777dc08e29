"""What several test modules share: running a console main, and writing an MCAP file again."""
from __future__ import annotations

from pathlib import Path
from typing import Callable


def run_main(main: Callable, argv: list, capsys) -> tuple:
    """Run a console program's ``main(argv)``; return (exit code, captured output).

    The code is what it returned or what it passed to ``SystemExit``.
    """
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr()


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
