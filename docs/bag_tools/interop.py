"""Open a grasp bag with two third-party readers (rosbags, mcap_ros2)."""
from pathlib import Path
import sys

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import get_typestore, Stores

bag = Path(sys.argv[1])
with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
    n = 0
    last = None
    for c, _t, raw in reader.messages():
        n += 1
        if c.topic.endswith('/supervisor/status'):
            last = reader.deserialize(raw, c.msgtype)
    print(f'rosbags AnyReader: {n} messages, {len(reader.topics)} topics')
    print(f'  last status: phase {last.phase}, force {last.force_n:g} N, position '
          f'{last.position_m:g} m')
with open(next(bag.glob('*.mcap')), 'rb') as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    summary = reader.get_summary()
    count = sum(summary.statistics.channel_message_counts.values())
    schemas = sorted({s.encoding for s in summary.schemas.values()})
    channels = sorted({c.message_encoding for c in summary.channels.values()})
    print(f'mcap reader: profile {reader.get_header().profile} | {count} messages | {schemas} '
          f'schemas | {channels} channels')
    last = None
    for _s, channel, _m, msg in reader.iter_decoded_messages():
        if channel.topic.endswith('/loop/motor_command'):
            last = msg
    print(f'  last loop/motor_command: {last}')
    f.seek(0)
    names = [r.name for r in make_reader(f).iter_metadata()]
    print(f'  metadata records: {names}')
