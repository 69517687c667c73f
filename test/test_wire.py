"""Pre-serialized hot-path messages, checked with rclpy's own (C) serializer and deserializer."""
import math

import pytest
from geometry_msgs.msg import WrenchStamped
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from impact_arm.msgdefs import serialize_cdr
from impact_arm.wire import PatchedMessage, float64_array_data


@pytest.mark.parametrize('n', [1, 2, 3])
def test_patched_joint_state_deserializes_to_the_filled_values(n):
    names = [f'joint{i + 1}' for i in range(n)]
    zeros = [0.0] * n
    wire = PatchedMessage(JointState(name=names, position=zeros, velocity=zeros, effort=zeros),
                          ('position', 'velocity', 'effort'))
    for sec, nanosec, values in ((0, 0, [0.0] * 3 * n),
                                 (12, 999_999_999, [0.1 * k - 1.0 for k in range(3 * n)]),
                                 (-5, 1, [math.pi * (k + 1) for k in range(3 * n)])):
        msg = deserialize_message(wire.fill(sec, nanosec, values), JointState)
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (sec, nanosec)
        assert list(msg.name) == names and msg.header.frame_id == ''
        assert list(msg.position) == values[:n]
        assert list(msg.velocity) == values[n:2 * n]
        assert list(msg.effort) == values[2 * n:]


def test_patched_wrench_keeps_frame_and_unpatched_fields():
    template = WrenchStamped()
    template.header.frame_id = 'surface'
    template.wrench.torque.z = 7.5          # not patched: must survive every fill
    wire = PatchedMessage(template, ('wrench.force.x', 'wrench.force.y'))
    msg = deserialize_message(wire.fill(3, 4, (1.5, -2.25)), WrenchStamped)
    assert msg.header.frame_id == 'surface'
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (3, 4)
    assert (msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z) == (1.5, -2.25, 0.0)
    assert msg.wrench.torque.z == 7.5


def test_patched_message_refuses_a_message_without_a_stamp():
    with pytest.raises(AttributeError):
        PatchedMessage(Float64MultiArray(data=[0.0]), ('data',))


@pytest.mark.parametrize('labels', [[], ['joints'], ['ab', 'x' * 7], ['', 'abc', 'defgh']])
@pytest.mark.parametrize('data', [[], [1.25], [1.25, -3.5, 1e300]])
def test_float64_array_data_reads_rclpy_serialized_commands(labels, data):
    msg = Float64MultiArray(data=data)
    msg.layout.dim = [MultiArrayDimension(label=lab, size=len(data), stride=len(data))
                      for lab in labels]
    msg.layout.data_offset = 3
    assert float64_array_data(serialize_message(msg)) == data


def test_float64_array_data_refuses_truncated_bytes():
    raw = serialize_cdr(Float64MultiArray(data=[1.0, 2.0]))      # exact size, no padding
    assert float64_array_data(raw) == [1.0, 2.0]
    with pytest.raises(ValueError):
        float64_array_data(raw[:-4])
