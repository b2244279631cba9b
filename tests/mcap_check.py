"""Independent check of an MCAP file with the ``mcap`` + ``mcap-ros2-support`` readers (not
rosbags, which writes them): summary and chunk index present, every schema ``ros2msg`` text,
every message decodes, and the counts agree with the summary's statistics."""

from __future__ import annotations

from collections import Counter
from pathlib import Path


def check_mcap(path: str | Path) -> Counter[str]:
    """Assert the file is a complete, indexed ROS 2 MCAP; return messages per topic."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None, f"{path}: no summary section"
        assert summary.statistics is not None, f"{path}: no statistics record"
        assert summary.chunk_indexes or summary.statistics.message_count == 0, f"{path}: no chunk index"
        assert summary.schemas, f"{path}: no schemas"
        for schema in summary.schemas.values():
            assert schema.encoding == "ros2msg", f"{path}: schema {schema.name} is {schema.encoding}"
            assert schema.data, f"{path}: schema {schema.name} is empty"
        for channel in summary.channels.values():
            assert channel.message_encoding == "cdr", f"{path}: {channel.topic} is {channel.message_encoding}"
        counts: Counter[str] = Counter()
        for _schema, channel, _message, decoded in reader.iter_decoded_messages():
            assert decoded is not None
            counts[channel.topic] += 1
        assert sum(counts.values()) == summary.statistics.message_count, f"{path}: message count mismatch"
        return counts
