"""
Bags without DDS: metadata versions 5-9 in MCAP and sqlite3, the v9 writer, splits, errors.

The independent reader is ``mcap`` + ``mcap-ros2-support`` (not rosbags): every file the package
writes must decode there with the same bytes and values.
"""

from pathlib import Path
import shutil

from cbha_inverse.bag.info import format_info
from cbha_inverse.bag.qos import adapt_offered, DEFAULT_QOS, load_qos_overrides
from cbha_inverse.bag.storage import (
    absolute_topic, BagError, BagWriter, deserialize, open_bag)
from cbha_inverse.errors import ConfigError
from cbha_inverse.ros.bag.cli import main as cbha_bag
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import pytest
from rosbags.interfaces import QosDurability, QosReliability
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores
import yaml

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
POINT = 'geometry_msgs/msg/PointStamped'
ARRAY = 'std_msgs/msg/Float64MultiArray'


def _point_bytes(k):
    message = TYPESTORE.types[POINT](
        header=TYPESTORE.types['std_msgs/msg/Header'](
            stamp=TYPESTORE.types['builtin_interfaces/msg/Time'](sec=k, nanosec=7 * k),
            frame_id='cbha_base'),
        point=TYPESTORE.types['geometry_msgs/msg/Point'](x=0.1 * k, y=-0.2 * k, z=1.5))
    return bytes(TYPESTORE.serialize_cdr(message, POINT))


def _mcap_messages(path):
    """Decode every message of every MCAP file of a bag with the independent reader."""
    decoded = []
    for file in sorted(Path(path).glob('*.mcap')):
        with open(file, 'rb') as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            for schema, channel, message, ros_message in reader.iter_decoded_messages():
                decoded.append((channel.topic, schema.name, message.log_time, message.data,
                                ros_message))
    return decoded


COUNTS = {'/a_points': 100, '/b_points': 50, '/empty': 0,
          '/test_service1/_service_event': 4}
"""Topics of the generated bags and their message counts (one topic never written)."""

ADDED_IN_VERSION = {6: ('custom_data',), 7: ('type_description_hash',), 8: ('ros_distro',)}
"""Metadata keys each rosbag2 metadata version added (rosbag2's version history)."""


def _versioned_bag(path, version, storage, start_ns=1_699_345_836_023_194_036):
    """
    Write a bag of metadata ``version`` (5-9) in ``storage`` ('mcap' or 'sqlite3').

    rosbags' Writer (an implementation of the rosbag2 format, independent of this package) writes
    versions 8 and 9; versions 5-7 are its version-8 bag with the metadata keys that later
    versions added removed, as rosbag2's version history describes them. Messages are 10 ms apart.
    """
    plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
    writer = Writer(path, version=max(version, 8), storage_plugin=plugin)
    writer.open()
    connections = {topic: writer.add_connection(topic, POINT, typestore=TYPESTORE)
                   for topic in COUNTS if not topic.endswith('_service_event')}
    # a service-event topic (rosbag2 >= Jazzy records services so); its type is not in the
    # typestore, so no definition and a zero hash: only its name and type string are read back
    connections['/test_service1/_service_event'] = writer.add_connection(
        '/test_service1/_service_event', 'std_srvs/srv/SetBool_Event', msgdef='',
        rihs01='RIHS01_' + '0' * 64)
    k = 0
    for topic, count in COUNTS.items():
        for _ in range(count):
            writer.write(connections[topic], start_ns + 10_000_000 * k, _point_bytes(k))
            k += 1
    writer.close()
    if version < 8:
        document = yaml.safe_load((path / 'metadata.yaml').read_text())
        information = document['rosbag2_bagfile_information']
        information['version'] = version
        for added in range(version + 1, 9):
            for key in ADDED_IN_VERSION.get(added, ()):
                information.pop(key, None)
                for topic in information['topics_with_message_count']:
                    topic['topic_metadata'].pop(key, None)
        (path / 'metadata.yaml').write_text(yaml.safe_dump(document, sort_keys=False))
    return k


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
@pytest.mark.parametrize('version', [5, 6, 7, 8, 9])
def test_reads_bags_of_every_metadata_version_and_storage(tmp_path, version, storage):
    """Every message of v5-v9 bags in both storages is read; counts, start and end match."""
    total = _versioned_bag(tmp_path / 'bag', version, storage)
    with open_bag(tmp_path / 'bag') as bag:
        summary = bag.summary
        read = {}
        stamps = []
        for topic, stamp, data in bag.messages():
            read[topic] = read.get(topic, 0) + 1
            stamps.append(stamp)
            assert isinstance(data, bytes) and len(data) >= 4  # CDR header at least
    assert (summary.version, summary.storage_identifier) == (version, storage)
    assert {t.name: t.count for t in summary.topics} == COUNTS
    assert read == {k: v for k, v in COUNTS.items() if v}
    assert summary.message_count == total == sum(COUNTS.values())
    assert summary.start_ns == min(stamps) and summary.end_ns == max(stamps)
    assert summary.end_ns - summary.start_ns == 10_000_000 * (total - 1)
    info = format_info(summary)
    assert f'Storage id:        {storage}\n' in info
    assert f'Messages:          {total}\n' in info


def test_info_layout_of_a_sqlite3_bag(tmp_path):
    """The info text has rosbag2's labels, columns and one line per topic and service."""
    _versioned_bag(tmp_path / 'events', 8, 'sqlite3')
    with open_bag(tmp_path / 'events') as bag:
        lines = format_info(bag.summary).split('\n')
    assert lines[0] == 'Files:             events.db3'
    assert lines[4] == 'Duration:          1.530000000s'
    assert lines[5].endswith('(1699345836.023194036)')
    assert lines[6].endswith('(1699345837.553194036)')
    assert lines[7] == 'Messages:          154'
    assert lines[8].startswith('Topic information: Topic: /a_points | Type: '
                               'geometry_msgs/msg/PointStamped | Count: 100 | '
                               'Serialization Format: cdr | QoS: ')
    assert lines[10].startswith(' ' * 19 + 'Topic: /empty | Type: '
                                'geometry_msgs/msg/PointStamped | Count: 0')
    assert lines[11] == 'Service:           1'
    assert lines[12] == ('Service information: Service: /test_service1 | Type: '
                         'std_srvs/srv/SetBool | Event Count: 4 | Serialization Format: cdr')


def test_writer_v9_mcap_is_read_by_the_independent_reader(tmp_path):
    """metadata.yaml as Jazzy expects it; the mcap reader decodes the same bytes and values."""
    writer = BagWriter(tmp_path / 'bag')
    reliable = adapt_offered([DEFAULT_QOS])
    writer.add_topic('/cbha/target', POINT, [reliable])
    writer.add_topic('/cbha/pressure_command', ARRAY, [])
    points = [_point_bytes(k) for k in range(20)]
    for k, data in enumerate(points):
        writer.write('/cbha/target', 1_000_000_000 + 10_000_000 * k, data)
    command = bytes(TYPESTORE.serialize_cdr(TYPESTORE.types[ARRAY](
        layout=TYPESTORE.types['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0),
        data=__import__('numpy').array([1.0, 2.5e4])), ARRAY))
    writer.write('/cbha/pressure_command', 1_005_000_000, command)
    writer.close()
    information = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    assert information['version'] == 9 and information['storage_identifier'] == 'mcap'
    assert information['relative_file_paths'] == ['bag_0.mcap']
    assert information['message_count'] == 21
    assert information['starting_time']['nanoseconds_since_epoch'] == 1_000_000_000
    assert information['duration']['nanoseconds'] == 190_000_000
    topics = {t['topic_metadata']['name']: t for t in information['topics_with_message_count']}
    assert topics['/cbha/target']['message_count'] == 20
    target = topics['/cbha/target']['topic_metadata']
    assert target['offered_qos_profiles'][0]['reliability'] == 'reliable'
    assert target['offered_qos_profiles'][0]['history'] == 'keep_last'
    assert target['type_description_hash'] == TYPESTORE.hash_rihs01(POINT)
    assert target['type_description_hash'].startswith('RIHS01_')
    decoded = _mcap_messages(tmp_path / 'bag')
    assert [d[3] for d in decoded if d[0] == '/cbha/target'] == points
    assert [d[2] for d in decoded if d[0] == '/cbha/target'] == [
        1_000_000_000 + 10_000_000 * k for k in range(20)]
    fifth = [d[4] for d in decoded if d[0] == '/cbha/target'][5]
    assert (fifth.header.stamp.sec, fifth.header.stamp.nanosec) == (5, 35)
    assert fifth.point.x == pytest.approx(0.5) and fifth.header.frame_id == 'cbha_base'
    (command_decoded,) = [d for d in decoded if d[0] == '/cbha/pressure_command']
    assert command_decoded[1] == ARRAY and list(command_decoded[4].data) == [1.0, 2.5e4]


@pytest.mark.parametrize('split', [{'max_bag_duration': 300_000_000}, {'max_bag_size': 3000}])
def test_writer_splits_by_duration_and_size(tmp_path, split):
    """Split bags list every file; each file decodes alone; nothing is lost or duplicated."""
    writer = BagWriter(tmp_path / 'split', **split)
    writer.add_topic('/cbha/target', POINT, [DEFAULT_QOS])
    points = [_point_bytes(k) for k in range(200)]
    for k, data in enumerate(points):
        writer.write('/cbha/target', 10_000_000 * k, data)
    writer.close()
    information = yaml.safe_load((tmp_path / 'split' / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    files = information['relative_file_paths']
    assert len(files) >= 3
    assert files == [f'split_{i}.mcap' for i in range(len(files))]
    assert sorted(p.name for p in (tmp_path / 'split').iterdir()) == sorted(
        files + ['metadata.yaml'])
    assert sum(f['message_count'] for f in information['files']) == 200
    if 'max_bag_duration' in split:
        assert all(f['duration']['nanoseconds'] < split['max_bag_duration']
                   for f in information['files'])
    else:  # every file but the last closes with the first message that reaches the size
        size = len(points[0])
        assert all(split['max_bag_size'] <= f['message_count'] * size
                   < split['max_bag_size'] + size for f in information['files'][:-1])
    for file, entry in zip(files, information['files']):
        with open(tmp_path / 'split' / file, 'rb') as stream:
            count = sum(1 for _ in make_reader(stream).iter_messages())
        assert count == entry['message_count']
    assert [d[3] for d in _mcap_messages(tmp_path / 'split')] == points
    with open_bag(tmp_path / 'split') as bag:
        assert [data for _, _, data in bag.messages()] == points


def test_bad_bags_give_one_line_errors(tmp_path, capsys):
    """Missing, not-a-bag, damaged metadata, truncated storage, unsupported format: exit 2."""
    good = tmp_path / 'good'
    writer = BagWriter(good)
    writer.add_topic('/t', POINT)
    for k in range(300):
        writer.write('/t', k, _point_bytes(k))
    writer.close()
    truncated = tmp_path / 'truncated'
    shutil.copytree(good, truncated)
    (truncated / 'good_0.mcap').rename(truncated / 'truncated_0.mcap')
    document = (good / 'metadata.yaml').read_text().replace('good_0', 'truncated_0')
    (truncated / 'metadata.yaml').write_text(document)
    data = (truncated / 'truncated_0.mcap').read_bytes()
    (truncated / 'truncated_0.mcap').write_bytes(data[:len(data) // 2])
    broken_yaml = tmp_path / 'broken_yaml'
    shutil.copytree(good, broken_yaml)
    (broken_yaml / 'metadata.yaml').write_text('rosbag2_bagfile_information: [unclosed\n')
    (tmp_path / 'empty_folder').mkdir()
    wrong_format = tmp_path / 'wrong_format'
    shutil.copytree(good, wrong_format)
    (wrong_format / 'good_0.mcap').rename(wrong_format / 'wrong_format_0.mcap')
    (wrong_format / 'metadata.yaml').write_text(document.replace(
        'truncated_0', 'wrong_format_0').replace('serialization_format: cdr',
                                                 'serialization_format: wrong_format'))
    # YAML, but not a bag's metadata: named by what is missing, not by a Python error
    not_a_mapping = tmp_path / 'not_a_mapping'
    shutil.copytree(good, not_a_mapping)
    (not_a_mapping / 'metadata.yaml').write_text('rosbag2_bagfile_information: hello\n')
    no_files = tmp_path / 'no_files'
    shutil.copytree(good, no_files)
    (no_files / 'metadata.yaml').write_text('\n'.join(
        line for line in (good / 'metadata.yaml').read_text().splitlines()
        if 'relative_file_paths' not in line and not line.strip().startswith('- good_0')))
    cases = {tmp_path / 'missing': 'does not exist', tmp_path / 'empty_folder': 'no metadata',
             broken_yaml: 'damaged metadata', truncated: 'truncated',
             wrong_format: 'wrong_format',
             not_a_mapping: 'damaged metadata: no rosbag2_bagfile_information mapping',
             no_files: 'damaged metadata: rosbag2_bagfile_information.relative_file_paths: '
             'missing'}
    for path, words in cases.items():
        for command in (['info', str(path)], ['eval', str(path)]):
            assert cbha_bag(command) == 2, (path, command)
            captured = capsys.readouterr()
            assert captured.out == ''
            assert captured.err.count('\n') == 1 and str(path) in captured.err
            assert 'Traceback' not in captured.err
            assert words in captured.err or command[0] == 'eval' and words == 'truncated', \
                captured.err
    with pytest.raises(BagError, match='exists already'):
        BagWriter(good)


def test_qos_override_file(tmp_path):
    """rosbag2's override format: named policies change, others keep the adapted profile."""
    path = tmp_path / 'qos.yaml'
    path.write_text('/cbha/tip/measured:\n  reliability: reliable\n  depth: 50\n'
                    '/latched:\n  durability: transient_local\n')
    best_effort = DEFAULT_QOS._replace(reliability=QosReliability.BEST_EFFORT)
    overrides = load_qos_overrides(path, {'/cbha/tip/measured': best_effort})
    assert overrides['/cbha/tip/measured'] == DEFAULT_QOS._replace(depth=50)
    assert overrides['/latched'] == DEFAULT_QOS._replace(
        durability=QosDurability.TRANSIENT_LOCAL)
    for text, key in [('/a:\n  reliability: sometimes\n', '/a.reliability'),
                      ('/a:\n  depth: -1\n', '/a.depth'), ('/a:\n  colour: red\n', '/a.colour'),
                      ('/a: [1\n', 'line'), ('- 1\n', 'file')]:
        path.write_text(text)
        with pytest.raises(ConfigError, match=f'^{path}: {key}'):
            load_qos_overrides(path, {})
    with pytest.raises(ConfigError, match='missing.yaml: file'):
        load_qos_overrides(tmp_path / 'missing.yaml', {})


def test_adapted_qos_reaches_every_publisher():
    """Reliable only if every publisher is; transient local only if every one is."""
    best_effort = DEFAULT_QOS._replace(reliability=QosReliability.BEST_EFFORT, depth=5)
    latched = DEFAULT_QOS._replace(durability=QosDurability.TRANSIENT_LOCAL, depth=30)
    assert adapt_offered([DEFAULT_QOS, best_effort]).reliability == QosReliability.BEST_EFFORT
    assert adapt_offered([DEFAULT_QOS, latched]).durability == QosDurability.VOLATILE
    assert adapt_offered([latched]).durability == QosDurability.TRANSIENT_LOCAL
    assert adapt_offered([latched, best_effort]).depth == 30
    assert adapt_offered([]) == DEFAULT_QOS
    assert deserialize(_point_bytes(3), POINT).point.x == pytest.approx(0.3)


def test_topic_names_are_resolved_against_the_root_namespace():
    assert absolute_topic('target') == '/target'
    assert absolute_topic('cbha/tip/true') == '/cbha/tip/true'
    assert absolute_topic('/cbha/target') == '/cbha/target'
