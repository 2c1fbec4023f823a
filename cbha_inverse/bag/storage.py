"""
Read and write rosbag2 bags: raw CDR messages with their topics, types, timestamps and QoS.

Reading goes through ``rosbags``' reader, which opens what rosbag2 writes: MCAP or sqlite3
storage, metadata versions 5 to 9, split bags. Writing produces what Jazzy's ``ros2 bag record``
writes by default: a folder with ``metadata.yaml`` (version 9) and MCAP files named
``<folder>_<index>.mcap``, split by size or duration like rosbag2's ``--max-bag-size`` and
``--max-bag-duration``. Every failure is a :class:`BagError` with a one-line message.
"""

from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
import shutil

from cbha_inverse.bag.qos import dump_qos
from rosbags.interfaces import ConnectionExtRosbag2
from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer, WriterError
from rosbags.typesys import get_typestore, Stores
import yaml

METADATA_VERSION = 9
"""The metadata version Jazzy's rosbag2 writes."""

STORAGE_ID = 'mcap'
"""Jazzy's default storage plugin."""


class BagError(ValueError):
    """A bag is missing, damaged or cannot be written; the message is one line."""


def absolute_topic(topic):
    """Return a topic name resolved against the root namespace (``target`` -> ``/target``)."""
    return topic if topic.startswith('/') else '/' + topic


@dataclass(frozen=True)
class TopicRecord:
    """
    One topic of a bag.

    Attributes
    ----------
    name : str
        Topic name.
    msgtype : str
        Message type, e.g. ``geometry_msgs/msg/PointStamped``.
    count : int
        Messages of this topic in the bag.
    offered_qos : tuple of rosbags.interfaces.Qos
        QoS profiles its publishers offered while recording (one per publisher).
    serialization_format : str
        ``cdr``.
    type_hash : str
        RIHS01 type description hash ('' in bags older than metadata version 9).

    """

    name: str
    msgtype: str
    count: int
    offered_qos: tuple
    serialization_format: str
    type_hash: str


@dataclass(frozen=True)
class BagSummary:
    """
    What ``metadata.yaml`` says about a bag.

    Attributes
    ----------
    path : pathlib.Path
        The bag folder.
    version : int
        Metadata version.
    storage_identifier : str
        ``mcap`` or ``sqlite3``.
    files : tuple of pathlib.Path
        The storage files.
    size_bytes : int
        Bytes of all files of the folder.
    start_ns, end_ns : int  [ns]
        First and last message timestamp (0 and 0 for an empty bag).
    message_count : int
        Messages in the bag.
    ros_distro : str
        Distribution that wrote it ('' if not recorded).
    topics : tuple of TopicRecord
        The topics in metadata order.

    """

    path: Path
    version: int
    storage_identifier: str
    files: tuple
    size_bytes: int
    start_ns: int
    end_ns: int
    message_count: int
    ros_distro: str
    topics: tuple

    @property
    def duration_ns(self):
        """Return the time from the first to the last message [ns]."""
        return self.end_ns - self.start_ns


class BagReader:
    """
    An open bag: its summary and its messages (use :func:`open_bag`).

    Parameters
    ----------
    reader : rosbags.rosbag2.Reader
        The open rosbags reader.
    summary : BagSummary
        What the metadata says.

    """

    def __init__(self, reader, summary):
        self._reader = reader
        self.summary = summary

    def messages(self, topics=None, start_ns=None):
        """
        Yield the messages in timestamp order.

        Parameters
        ----------
        topics : collection of str, optional
            Only these topics (default all).
        start_ns : int, optional  [ns]
            Only messages at or after this timestamp.

        Yields
        ------
        tuple of (str, int, bytes)
            Topic, timestamp [ns] and the raw CDR bytes.

        Raises
        ------
        BagError
            If a storage file is damaged.

        """
        # rosbags matches the requested connections with each file's channels including their
        # QoS; MCAP files of old rosbag2 versions (metadata v5) carry no QoS in their channels,
        # so the files' own connections are requested as well (rosbags 0.11.9)
        files = getattr(self._reader.storage, 'storages', [])
        connections = [c for c in [*self._reader.connections,
                                   *(c for f in files for c in f.connections)]
                       if topics is None or c.topic in topics]
        if not connections:
            return
        try:
            for connection, timestamp, data in self._reader.messages(connections, start_ns):
                yield connection.topic, timestamp, bytes(data)
        except (ReaderError, OSError, ValueError, KeyError, IndexError, EOFError) as exc:
            raise BagError(f'{self.summary.path}: damaged storage file: {_one_line(exc)}') \
                from None


def _one_line(exc):
    return ' '.join(str(exc).split()) or type(exc).__name__


def _read_metadata(path):
    """Return the ``rosbag2_bagfile_information`` map of a bag folder."""
    metadata = path / 'metadata.yaml'
    if not path.exists():
        raise BagError(f'{path}: no such bag (folder does not exist)')
    if not metadata.is_file():
        raise BagError(f'{path}: not a rosbag2 bag (no metadata.yaml)')
    try:
        document = yaml.safe_load(metadata.read_text())
    except (OSError, yaml.YAMLError, ValueError) as exc:
        raise BagError(f'{metadata}: damaged metadata: {_one_line(exc)}') from None
    problem = _metadata_problem(document)
    if problem:
        raise BagError(f'{metadata}: damaged metadata: {problem}')
    return document[_INFORMATION]


_INFORMATION = 'rosbag2_bagfile_information'
# the keys of every metadata version (rosbag2 1 to 9)
_REQUIRED_KEYS = ('version', 'storage_identifier', 'relative_file_paths',
                  'topics_with_message_count')


def _metadata_problem(document):
    """Return what is wrong with the structure of a ``metadata.yaml`` document ('' if nothing)."""
    information = document.get(_INFORMATION) if isinstance(document, dict) else None
    if not isinstance(information, dict):
        return f'no {_INFORMATION} mapping'
    missing = [key for key in _REQUIRED_KEYS if key not in information]
    if missing:
        return f'{_INFORMATION}.{missing[0]}: missing'
    if isinstance(information['version'], bool) or not isinstance(information['version'], int):
        return f'{_INFORMATION}.version: not an integer, got {information["version"]!r}'
    for key in ('relative_file_paths', 'topics_with_message_count'):
        if not isinstance(information[key], list):
            return f'{_INFORMATION}.{key}: not a list, got {information[key]!r}'
    return ''


@contextmanager
def open_bag(path):
    """
    Open a rosbag2 bag for reading.

    Parameters
    ----------
    path : str or os.PathLike
        The bag folder (with ``metadata.yaml``).

    Yields
    ------
    BagReader
        The open bag; closed on exit.

    Raises
    ------
    BagError
        If the folder is missing, is not a bag, or its metadata or storage is damaged.

    """
    path = Path(path)
    information = _read_metadata(path)
    reader = Reader(path)
    try:
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError, IndexError, EOFError) as exc:
        raise BagError(f'{path}: cannot open bag: {_one_line(exc)}') from None
    try:
        topics = tuple(TopicRecord(
            c.topic, c.msgtype, int(c.msgcount), tuple(c.ext.offered_qos_profiles),
            c.ext.serialization_format, c.digest or '') for c in reader.connections
            if isinstance(c.ext, ConnectionExtRosbag2))
        count = int(reader.message_count)
        files = tuple(path / Path(p).name for p in information.get('relative_file_paths', []))
        summary = BagSummary(
            path=path, version=int(information['version']),
            storage_identifier=str(information.get('storage_identifier', '')), files=files,
            size_bytes=sum(f.stat().st_size for f in path.iterdir() if f.is_file()),
            start_ns=int(reader.start_time) if count else 0,
            end_ns=int(reader.end_time) - 1 if count else 0, message_count=count,
            ros_distro=str(information.get('ros_distro') or ''), topics=topics)
        yield BagReader(reader, summary)
    finally:
        reader.close()


_TYPESTORE = None


def _typestore():
    global _TYPESTORE
    if _TYPESTORE is None:
        _TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
    return _TYPESTORE


def knows_type(msgtype):
    """
    Return whether a message type can be recorded (its definition is known).

    Parameters
    ----------
    msgtype : str
        E.g. ``std_msgs/msg/Float64MultiArray``.

    Returns
    -------
    bool
        True for the ROS 2 Jazzy standard and common interfaces.

    """
    return msgtype in _typestore().fielddefs


def deserialize(data, msgtype):
    """
    Decode raw CDR bytes without rclpy.

    Parameters
    ----------
    data : bytes
        The serialized message.
    msgtype : str
        Its type.

    Returns
    -------
    object
        A rosbags message dataclass with the fields of the ROS message.

    """
    return _typestore().deserialize_cdr(data, msgtype)


class BagWriter:
    """
    Write a rosbag2 bag (metadata v9, MCAP files), split by size or duration.

    Parameters
    ----------
    path : str or os.PathLike
        The bag folder; must not exist.
    max_bag_size : int, optional  [bytes]
        Start a new file once the messages written to the current one reach this size (0:
        never). Message bytes are counted, as the MCAP writer buffers a chunk before the file
        on disk grows.
    max_bag_duration : int, optional  [ns]
        Start a new file before a message this much later than the file's first (0: never).

    Raises
    ------
    BagError
        If the folder exists already.

    Notes
    -----
    Each file is an MCAP written by ``rosbags`` with every topic's schema and channel, so each
    file can be read on its own; ``metadata.yaml`` lists them all with their message counts.

    """

    def __init__(self, path, max_bag_size=0, max_bag_duration=0):
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'{self.path}: exists already, not overwriting')
        if max_bag_size < 0 or max_bag_duration < 0:
            raise BagError('split sizes and durations must be >= 0')
        self.max_bag_size = int(max_bag_size)
        self.max_bag_duration = int(max_bag_duration)
        self.path.mkdir(parents=True)
        self.topics = {}
        self.counts = {}
        self.files = []
        self._writer = None
        self._connections = {}
        self._file_start = None

    def add_topic(self, name, msgtype, offered_qos=()):
        """
        Register a topic (once) before writing its messages.

        Parameters
        ----------
        name : str
            Topic name.
        msgtype : str
            Message type; its definition must be known (:func:`knows_type`).
        offered_qos : sequence of rosbags.interfaces.Qos
            The QoS its publishers offer.

        Raises
        ------
        BagError
            If the type is unknown or the topic was added already.

        """
        if name in self.topics:
            raise BagError(f'topic {name} added twice')
        if not knows_type(msgtype):
            raise BagError(f'topic {name}: message type {msgtype} is not known to the bag '
                           'writer (only ROS 2 Jazzy standard interfaces)')
        self.topics[name] = (msgtype, tuple(offered_qos))
        self.counts[name] = 0
        if self._writer is not None:
            self._connect(name)

    def _connect(self, name):
        msgtype, offered = self.topics[name]
        self._connections[name] = self._writer.add_connection(
            name, msgtype, typestore=_typestore(), offered_qos_profiles=list(offered))

    def _open_file(self, timestamp):
        name = f'{self.path.name}_{len(self.files)}'
        writer = Writer(self.path / f'.{name}', version=METADATA_VERSION,
                        storage_plugin=StoragePlugin.MCAP)
        writer.open()
        self._writer = writer
        self._connections = {}
        for topic in self.topics:
            self._connect(topic)
        self._file_start = timestamp
        self.files.append({'path': f'{name}.mcap', 'start': timestamp, 'end': timestamp,
                           'count': 0, 'bytes': 0})

    def _close_file(self):
        writer, self._writer = self._writer, None
        writer.close()
        inner = writer.path / f'{writer.path.name}.mcap'
        inner.replace(self.path / self.files[-1]['path'])
        shutil.rmtree(writer.path)

    def write(self, topic, timestamp, data):
        """
        Append one message.

        Parameters
        ----------
        topic : str
            A topic added with :meth:`add_topic`.
        timestamp : int  [ns]
            Receive time.
        data : bytes
            Raw CDR bytes.

        """
        if topic not in self.topics:
            raise BagError(f'topic {topic} was not added')
        if self._writer is not None and self.max_bag_duration and (
                timestamp - self._file_start >= self.max_bag_duration):
            self._close_file()
        if self._writer is None:
            self._open_file(timestamp)
        try:
            self._writer.write(self._connections[topic], timestamp, data)
        except WriterError as exc:
            raise BagError(f'{self.path}: {_one_line(exc)}') from None
        self.counts[topic] += 1
        current = self.files[-1]
        current['count'] += 1
        current['start'] = min(current['start'], timestamp)
        current['end'] = max(current['end'], timestamp)
        current['bytes'] += len(data)
        if self.max_bag_size and current['bytes'] >= self.max_bag_size:
            self._close_file()

    def close(self):
        """Close the current file and write ``metadata.yaml``; return the bag folder."""
        if not self.files:
            self._open_file(0)
        if self._writer is not None:
            self._close_file()
        start = min((f['start'] for f in self.files if f['count']), default=0)
        end = max((f['end'] for f in self.files if f['count']), default=0)
        information = {
            'version': METADATA_VERSION, 'storage_identifier': STORAGE_ID,
            'duration': {'nanoseconds': end - start},
            'starting_time': {'nanoseconds_since_epoch': start},
            'message_count': sum(self.counts.values()),
            'topics_with_message_count': [{
                'topic_metadata': {
                    'name': name, 'type': msgtype, 'serialization_format': 'cdr',
                    'offered_qos_profiles': dump_qos(offered),
                    'type_description_hash': _typestore().hash_rihs01(msgtype)},
                'message_count': self.counts[name]}
                for name, (msgtype, offered) in self.topics.items()],
            'compression_format': '', 'compression_mode': '',
            'relative_file_paths': [f['path'] for f in self.files],
            'files': [{'path': f['path'],
                       'starting_time': {'nanoseconds_since_epoch': f['start']},
                       'duration': {'nanoseconds': f['end'] - f['start']},
                       'message_count': f['count']} for f in self.files],
            'custom_data': {}, 'ros_distro': 'jazzy'}
        text = yaml.safe_dump({'rosbag2_bagfile_information': information}, sort_keys=False)
        temporary = self.path / 'metadata.yaml.tmp'
        temporary.write_text(text)
        temporary.replace(self.path / 'metadata.yaml')
        return self.path
