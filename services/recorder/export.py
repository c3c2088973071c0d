"""``arroch runs export RUN --ros2 OUT``: a recorded ``run.mcap`` as a ROS 2 bag, offline.

The recording's messages (as they travelled, from its wire store) go through the very profile that
records a bag live (:class:`.ros2.Ros2Profile`), on the recording's own timebase, and so do the log
lines it followed (the ``/log`` entries that name their file); the bag is what ``arroch record
--profile ros2`` would have written beside it.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from protocol.keys import Keys
from protocol.site import Site, load_site

from . import topics
from .convert import LEVELS
from .logtail import LogLine
from .reading import RecordingError, messages, metadata
from .ros2 import Ros2Profile
from .rosbag import Distro
from .timebase import ORIGIN_KEY, Timebase

_LEVEL_NAMES = {int(level): name for name, level in LEVELS.items()}


def _followed_lines(recording: Path) -> Iterator[tuple[int, LogLine, str]]:
    """(log time, line, file) of every followed log line in the recording's ``/log``."""
    with open(recording, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, _channel, message, log in reader.iter_decoded_messages(topics=[topics.LOG]):
            if log.file:
                line = LogLine(log.name, _LEVEL_NAMES.get(int(log.level), "INFO"), log.message, int(log.line))
                yield message.log_time, line, log.file


def _site_of(recording: Path, recorded: dict[str, str], site: str | None) -> Site:
    if site:
        return load_site(site)
    source = recorded.get("site_source", "")
    if source and Path(source).is_file():
        return load_site(source)
    if recorded.get("site") == load_site().name:  # the packaged site
        return load_site()
    raise RecordingError(f"{recording}: its site file {source or '(not named)'} is not here: give --site FILE")


def export_ros2(recording: Path, out: Path, distro: Distro, site: str | None = None) -> int:
    """Write the bag; returns the number of ARROCH messages converted. A failure leaves no folder."""
    recorded = metadata(recording)
    namespace = recorded.get("namespace")
    if not namespace:
        raise RecordingError(f"{recording}: names no namespace (not recorded by arroch record?)")
    keys = Keys(namespace)
    timebase = Timebase(int(recorded.get(ORIGIN_KEY, 0)))
    profile = Ros2Profile(out, _site_of(recording, recorded, site), timebase, distro, namespace)
    count = 0
    started = False
    try:
        for record in messages(recording):
            if not started:
                profile.start(timebase.at(record.time))
                profile.origin_fixed()
                started = True
            profile.handle(record.message, topics.key_of(keys, record.topic), record.payload)
            count += 1
        if not started:
            raise RecordingError(f"{recording}: no ARROCH messages to convert")
        for at, line, file in _followed_lines(recording):
            profile.log_line(line, at, file)
    except BaseException:
        profile.abort()
        raise
    profile.close()
    return count
