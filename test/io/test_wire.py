"""Pre-serialized hot-path messages, checked with rclpy's own (C) serializer and deserializer."""

import math

import pytest
from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from impact_arm.io.msgdefs import serialize_cdr
from impact_arm.io import wire
from impact_arm.io.wire import (
    PatchedMessage,
    MalformedMessage,
    float64_array_data,
    joint_state_effort,
    joint_state_fields,
    wrench_stamped_fields,
)


@pytest.mark.parametrize('n', [1, 2, 3])
def test_patched_joint_state_deserializes_to_the_filled_values(n):
    names = [f'joint{i + 1}' for i in range(n)]
    zeros = [0.0] * n
    wire = PatchedMessage(
        JointState(name=names, position=zeros, velocity=zeros, effort=zeros),
        ('position', 'velocity', 'effort'),
    )
    for sec, nanosec, values in (
        (0, 0, [0.0] * 3 * n),
        (12, 999_999_999, [0.1 * k - 1.0 for k in range(3 * n)]),
        (-5, 1, [math.pi * (k + 1) for k in range(3 * n)]),
    ):
        msg = deserialize_message(wire.fill(values, (sec, nanosec)), JointState)
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (sec, nanosec)
        assert list(msg.name) == names and msg.header.frame_id == ''
        assert list(msg.position) == values[:n]
        assert list(msg.velocity) == values[n : 2 * n]
        assert list(msg.effort) == values[2 * n :]


def test_patched_wrench_keeps_frame_and_unpatched_fields():
    template = WrenchStamped()
    template.header.frame_id = 'surface'
    template.wrench.torque.z = 7.5  # not patched: must survive every fill
    wire = PatchedMessage(template, ('wrench.force.x', 'wrench.force.y'))
    msg = deserialize_message(wire.fill((1.5, -2.25), (3, 4)), WrenchStamped)
    assert msg.header.frame_id == 'surface'
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (3, 4)
    assert (msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z) == (1.5, -2.25, 0.0)
    assert msg.wrench.torque.z == 7.5


def test_patched_command_without_header():
    wire = PatchedMessage(Float64MultiArray(data=[0.0, 0.0]), ('data',), stamp=None)
    assert list(deserialize_message(wire.fill([2.5, -1.0]), Float64MultiArray).data) == [2.5, -1.0]
    assert float64_array_data(wire.data) == [2.5, -1.0]


def test_patched_message_refuses_a_field_it_cannot_find():
    msg = JointState(name=['a'], position=[0.0])
    with pytest.raises(AttributeError):
        PatchedMessage(msg, ('positions',))


@pytest.mark.parametrize('labels', [[], ['joints'], ['ab', 'x' * 7], ['', 'abc', 'defgh']])
@pytest.mark.parametrize('data', [[], [1.25], [1.25, -3.5, 1e300]])
def test_float64_array_data_reads_rclpy_serialized_commands(labels, data):
    msg = Float64MultiArray(data=data)
    msg.layout.dim = [
        MultiArrayDimension(label=lab, size=len(data), stride=len(data)) for lab in labels
    ]
    msg.layout.data_offset = 3
    assert float64_array_data(serialize_message(msg)) == data


def test_float64_array_data_refuses_truncated_bytes():
    raw = serialize_cdr(Float64MultiArray(data=[1.0, 2.0]))  # exact size, no padding
    assert float64_array_data(raw) == [1.0, 2.0]
    with pytest.raises(ValueError):
        float64_array_data(raw[:-4])


@pytest.mark.parametrize('names', [[], ['joint1'], ['j', 'joint22', 'abc']])
def test_joint_state_fields_read_rclpy_serialized_states(names):
    n = len(names)
    msg = JointState(
        name=names,
        position=[0.5 * k for k in range(n)],
        velocity=[-1.0 * k for k in range(n)],
        effort=[9.0] * n,
    )
    msg.header.stamp.sec, msg.header.stamp.nanosec = 41, 123_456_789
    msg.header.frame_id = 'base_link_x'
    assert joint_state_fields(serialize_cdr(msg)) == (
        41,
        123_456_789,
        names,
        list(msg.position),
        list(msg.velocity),
    )
    # a driver that leaves velocities out
    msg.velocity = []
    assert joint_state_fields(serialize_message(msg))[4] == []


def test_joint_state_layout_is_reused_only_for_the_same_layout():
    wire._joint_state_layouts.clear()  # layouts remembered by earlier tests

    def state(names, position, velocity, effort, sec=1):
        msg = JointState(name=names, position=position, velocity=velocity, effort=effort)
        msg.header.stamp.sec = sec
        return serialize_message(msg)

    first = state(['ja', 'jb'], [1.0, 2.0], [3.0, 4.0], [0.0, 0.0])
    assert joint_state_fields(first) == (1, 0, ['ja', 'jb'], [1.0, 2.0], [3.0, 4.0])
    # the same layout, new stamp and numbers: read at the remembered offsets
    assert joint_state_fields(state(['ja', 'jb'], [5.0, 6.0], [7.0, 8.0], [0.0, 0.0], 2)) == (
        2,
        0,
        ['ja', 'jb'],
        [5.0, 6.0],
        [7.0, 8.0],
    )
    # as long, but other names, or no velocities (the efforts make up the length)
    same_size = state(['jb', 'ja'], [1.0, 2.0], [3.0, 4.0], [0.0, 0.0])
    no_velocity = state(['ja', 'jb'], [1.0, 2.0], [], [0.0, 0.0, 0.0, 0.0])
    assert len(same_size) == len(no_velocity) == len(first)
    assert joint_state_fields(no_velocity)[3:] == ([1.0, 2.0], [])
    assert joint_state_fields(same_size)[2] == ['jb', 'ja']


@pytest.mark.parametrize('frame', ['', 'abc', 'abcdefg'])
@pytest.mark.parametrize('names', [['joint1'], ['joint1', 'joint2'], ['a', 'bb', 'ccc']])
def test_joint_state_effort_reads_what_rclpy_serialized(names, frame, monkeypatch):
    """Efforts (the driver's acting torques), read at the remembered layout's offsets once
    joint_state_fields has seen a message of that layout, and by a full parse otherwise:
    both what rclpy serialized, whatever the padding before them."""
    n = len(names)
    for effort in ([], [0.25 + k for k in range(n)]):
        msg = JointState(name=names, position=[1.0] * n, velocity=[-2.0] * n, effort=effort)
        msg.header.frame_id = frame
        raw = serialize_message(msg)
        wire._joint_state_layouts.clear()
        assert joint_state_effort(raw) == effort  # full parse
        joint_state_fields(raw)  # its layout remembered
        with monkeypatch.context() as m:
            m.setattr(wire, 'CdrReader', None)  # the fast path parses nothing
            assert joint_state_effort(raw) == effort
    with pytest.raises(MalformedMessage):
        joint_state_effort(raw[:-3])


def test_wrench_stamped_fields_read_rclpy_serialized_wrenches():
    for frame in ('', 'surface', 'abcdefg'):
        msg = WrenchStamped()
        msg.header.frame_id = frame
        msg.header.stamp.sec, msg.header.stamp.nanosec = 7, 8
        msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = 1.0, -2.0, 3.0
        assert wrench_stamped_fields(serialize_message(msg)) == (7, 8, (1.0, -2.0, 3.0))


def test_patched_clock():
    from rosgraph_msgs.msg import Clock

    wire = PatchedMessage(Clock(), (), stamp='clock')
    msg = deserialize_message(wire.fill((), (1_700_000_000, 5)), Clock)
    assert (msg.clock.sec, msg.clock.nanosec) == (1_700_000_000, 5)


def test_joint_state_command_matches_efforts_by_name_and_refuses_the_rest():
    joint_state_command = wire.joint_state_command
    joints = ['joint1', 'joint2']

    def raw(**fields):
        return serialize_cdr(JointState(**fields))

    assert joint_state_command(
        raw(name=['joint2', 'joint1'], position=[9.0, 9.0], effort=[-2.5, 7.0]), joints
    ) == [7.0, -2.5]
    for bad, why in (
        ({'name': ['joint1', 'jointX'], 'effort': [1.0, 2.0]}, 'unknown'),
        ({'name': ['joint1', 'joint2'], 'effort': []}, 'one effort per joint'),
        ({'name': ['joint1', 'joint2'], 'effort': [1.0]}, 'one effort per joint'),
        ({'name': ['joint1'], 'effort': [1.0]}, 'once'),
        ({'name': ['joint1', 'joint1'], 'effort': [1.0, 2.0]}, 'once'),
    ):
        with pytest.raises(ValueError, match=why):
            joint_state_command(raw(**bad), joints)
