"""Hostile input without ROS: scene files and raw payloads either give finite values or are
refused in one line. Property-based parts are bounded and derandomized."""

import copy
import math
import os
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from impact_arm.physics.errors import SceneError
from impact_arm.physics.scene import load_scene, parse_scene, scene_from_text
from impact_arm.io.wire import (
    MalformedMessage,
    float64_array_data,
    joint_state_command,
    joint_state_fields,
    wrench_stamped_fields,
)
from impact_arm_bench.generators import key_paths

from scenes import PAPER, paper_dict

BOUNDED = settings(
    max_examples=150, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck)
)
READERS = (
    float64_array_data,
    joint_state_fields,
    wrench_stamped_fields,
    lambda raw: joint_state_command(raw, ('joint1', 'joint2')),
)
with open(PAPER, encoding='utf-8') as _f:
    PAPER_TEXT = _f.read()


# ------------------------------------------------------------------------ raw payloads
def joint_state_bytes(names, position, velocity, sec=0, nanosec=0):
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    msg = JointState(name=names, position=position, velocity=velocity)
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    return serialize_message(msg)


@BOUNDED
@given(st.binary(max_size=300))
def test_random_bytes_give_a_value_or_a_malformed_message(raw):
    for read in READERS:
        try:
            read(raw)
        except MalformedMessage as exc:
            assert '\n' not in str(exc)


@BOUNDED
@given(st.data())
def test_mutated_joint_states_give_a_value_or_a_malformed_message(data):
    """Valid messages with bytes cut, flipped or overwritten by absurd lengths."""
    raw = bytearray(joint_state_bytes(['joint1', 'joint2'], [0.1, 0.2], [0.0, 0.0]))
    action = data.draw(st.sampled_from(('cut', 'flip', 'length')))
    at = data.draw(st.integers(0, len(raw) - 4))
    if action == 'cut':
        raw = raw[:at]
    elif action == 'flip':
        raw[at] ^= data.draw(st.integers(1, 255))
    else:
        raw[at : at + 4] = struct.pack(
            '<I', data.draw(st.sampled_from((2**31 - 1, 2**32 - 1, 1000, 7)))
        )
    for read in READERS:
        try:
            read(bytes(raw))
        except MalformedMessage:
            pass


@pytest.mark.parametrize(
    'raw, why',
    [
        (b'', 'empty'),
        (b'\x00\x01\x00\x00', 'header only'),
        (b'\x07\x01\x00\x00' + bytes(40), 'wrong encapsulation'),
        (b'\x00\x01\x00\x00' + bytes(8) + struct.pack('<I', 2**31 - 1) + bytes(16), 'huge frame'),
    ],
)
def test_each_reader_refuses_named_malformations(raw, why):
    for read in READERS:
        with pytest.raises(MalformedMessage):
            read(raw)


def test_absurd_sequence_lengths_and_non_utf8_names_are_malformed():
    good = joint_state_bytes(['joint1', 'joint2'], [0.1, 0.2], [0.0, 0.0])
    names_at = good.index(b'joint1') - 8  # the name count, then the first length
    huge = good[:names_at] + struct.pack('<I', 2**31 - 1) + good[names_at + 4 :]
    with pytest.raises(MalformedMessage, match='cannot fit'):
        joint_state_fields(huge)
    bad_name = good.replace(b'joint1', b'joi\xffn1')
    with pytest.raises(MalformedMessage, match='UTF-8'):
        joint_state_fields(bad_name)
    assert joint_state_fields(good)[2:4] == (['joint1', 'joint2'], [0.1, 0.2])


# ------------------------------------------------------------------------- scene files
def refusal(text):
    with pytest.raises(SceneError) as info:
        scene_from_text(text, origin='t.yaml')
    message = str(info.value)
    assert '\n' not in message and len(message) < 600, message
    return message


@pytest.mark.parametrize(
    'old, new, words',
    [
        ('gravity: 9.81', 'gravity: 1:30', ['line 5', "'gravity'", '1:30', 'YAML 1.1']),
        ('cycles: 15', 'cycles: 017', ["'cycles'", '017']),
        ('actuators_during_contact: false', 'actuators_during_contact: on', ['on']),
        ('cycles: 15', 'cycles: 15\ncycles: 3', ['duplicate key', "'cycles'"]),
        ('t_max: 60.0', 't_max: [1, 2', ['line', 'column']),
        (
            '  - {length: 1.0, mass: 1.0}\n  - {length: 1.0, mass: 1.0}',
            '  - {length: 1.0, mass: 1.0}\n  - {length: 1' + '0' * 400 + ', mass: 1.0}',
            ['links[1].length', '401 digits'],
        ),
        (
            '  - {length: 1.0, mass: 1.0}\n  - {length: 1.0, mass: 1.0}',
            '  - {length: 1.0, mass: 1.0}\n  - {length: 1.0, mass: 5e-324}',
            ['links[1].mass', 'kg'],
        ),
        (
            '  - {length: 1.0, mass: 1.0}\n  - {length: 1.0, mass: 1.0}',
            '  - {length: 1.0, mass: 1.0}\n  - {length: 1.0e-6, mass: 1.0}',
            ['links[1].length'],
        ),
        (
            '  - {length: 1.0, mass: 1.0}\n  - {length: 1.0, mass: 1.0}',
            '  - {length: 1.0, mass: 1.0}\n  - {length: 1.0, mass: 1.0e-5}',
            ['ratio', 'masses'],
        ),
        ('preset: balanced', 'max_step: 1.0e-300', ['integrator.max_step', '1e-05']),
        ('rate: 0 ', 'rate: 1.0e-300 ', ['controller.rate', 'more than a second']),
        ('kd: [100.0, 100.0]', 'kd: [1.0e9, 100.0]', ['controller.kd[0]', 'closed-loop rate']),
        (
            '  - {length: 1.0, mass: 1.0}\n  - {length: 1.0, mass: 1.0}\n',  # stiff, light
            '  - {length: 1.0, mass: 1.0e-6}\n  - {length: 1.0, mass: 1.0e-6}\nmaterials: {steel: '
            '{E: 1.0e13, nu: 0.29, S_y: 1.12e9}}\n',
            ['contact lasts', 'surfaces[0].material'],
        ),
    ],
)
def test_scene_refusals_name_the_key_in_one_line(old, new, words):
    assert PAPER_TEXT.count(old) == 1
    text = PAPER_TEXT.replace(old, new)
    if new.count('materials:'):  # the replacement brings its own materials
        text = text.replace('materials:\n  steel: {E: 210.0e9, nu: 0.29, S_y: 1.12e9}\n', '')
    message = refusal(text)
    for word in words:
        assert word in message, message


def test_alias_bomb_is_refused_without_expanding_it():
    levels = ['a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]']
    levels += [f'a{k}: &a{k} [' + ', '.join([f'*a{k - 1}'] * 10) + ']' for k in range(1, 9)]
    message = refusal('\n'.join(levels) + '\n')
    assert 'aliases' in message


def test_oversized_and_endless_files_are_refused_quickly(tmp_path):
    with pytest.raises(SceneError, match='larger than'):
        load_scene('/dev/zero')
    binary = tmp_path / 'b.yaml'
    binary.write_bytes(b'name: \xff\xfe\n')
    with pytest.raises(SceneError, match='UTF-8'):
        load_scene(str(binary))


def test_yaml_12_numbers_still_read():
    scene = scene_from_text(
        PAPER_TEXT.replace('gravity: 9.81', 'gravity: 0x0A').replace('cycles: 15', 'cycles: 0o17')
    )
    assert scene.gravity == 10.0 and scene.cycles == 15
    assert (
        math.copysign(
            1, scene_from_text(PAPER_TEXT.replace('gravity: 9.81', 'gravity: -0.0')).gravity
        )
        == -1
    )  # -0.0 is within [0, 1000]


LEAVES = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=8),
    st.integers(min_value=-(2**80), max_value=2**1100),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([5e-324, -0.0, 1e308, 1e-300, 2.0**64]),
    st.lists(st.floats(), max_size=3),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


@BOUNDED
@given(st.data())
def test_mutated_scenes_are_accepted_finite_or_refused_in_one_line(data):
    scene = copy.deepcopy(paper_dict())
    paths = list(key_paths(scene))
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(paths))
        parent = scene
        try:
            for key in path[:-1]:
                parent = parent[key]
            if data.draw(st.booleans()) and isinstance(parent, dict):
                parent.pop(path[-1], None)
            else:
                parent[path[-1]] = data.draw(LEAVES)
        except (KeyError, IndexError, TypeError):
            continue  # an earlier mutation removed or replaced the parent
    try:
        result = parse_scene(scene, origin='fuzz')
    except SceneError as exc:
        assert '\n' not in str(exc) and len(str(exc)) < 600
        return
    numbers = [*result.lengths, *result.masses, result.gravity, result.t_max, *result.q0]
    assert all(math.isfinite(x) for x in numbers)


@BOUNDED
@given(
    st.text(alphabet=st.sampled_from(list(' \n:-[]{}&*!|>#"\'0123456789.eE+abcxyz_')), max_size=120)
)
def test_arbitrary_yaml_text_is_refused_in_one_line(text):
    try:
        scene_from_text(text)
    except SceneError as exc:
        assert '\n' not in str(exc)


# ------------------------------------------------------------------------- run budget
def test_a_run_that_cannot_progress_stops_with_the_run_budget(monkeypatch):
    """max_step 1e-300 (refused in a scene file, possible through the API) stepped forever:
    the kernel now returns every STEPS_PER_CALL steps and the run stops by name."""
    from dataclasses import replace
    from impact_arm.physics import integrator
    from impact_arm.physics.simulate import run
    from scenes import scene_from

    monkeypatch.setattr(integrator, 'STEPS_PER_CALL', 1000)
    monkeypatch.setattr(integrator, 'MIN_STEP_BUDGET', 5000)
    scene = scene_from(cycles=1)
    result = run(replace(scene, integrator=replace(scene.integrator, max_step=1e-300)))
    assert result.stopped == 'error' and 'run budget exceeded' in result.error, result.error


# --------------------------------------------------------------------- CLI output paths
def short_scene(tmp_path):
    path = tmp_path / 'short.yaml'
    path.write_text(PAPER_TEXT.replace('cycles: 15', 'cycles: 1'))
    return str(path)


@pytest.mark.parametrize('flag', ['--json', '--mcap'])
def test_output_paths_are_refused_before_the_run(tmp_path, capsys, flag):
    from impact_arm.tools.cli import main

    fifo = tmp_path / 'fifo'
    os.mkfifo(fifo)
    for target, words in (
        (tmp_path, 'is a directory'),
        (tmp_path / 'missing' / 'x', 'does not exist'),
        (fifo / 'x', 'is not a directory'),
        (fifo, 'not a regular file'),
    ):
        assert main(['simulate', '--scene', short_scene(tmp_path), flag, str(target)]) == 2
        err = capsys.readouterr().err
        assert words in err and err.count('\n') == 1, err
    assert not (tmp_path / 'missing').exists() and fifo.is_fifo()


def test_json_through_a_symlink_keeps_the_link_and_writes_no_nan(tmp_path, capsys):
    import json
    from impact_arm.tools.cli import write_json, main

    real = tmp_path / 'real.json'
    real.write_text('{}')
    link = tmp_path / 'link.json'
    link.symlink_to(real)
    assert (
        main(['simulate', '--scene', short_scene(tmp_path), '--no-samples', '--json', str(link)])
        == 0
    )
    assert link.is_symlink() and 'impacts' in json.loads(real.read_text())
    assert 'link is kept' in capsys.readouterr().out
    write_json(str(real), {'a': float('nan'), 'b': [float('inf'), 1.0]})
    assert json.loads(real.read_text()) == {'a': None, 'b': [None, 1.0]}
    assert sorted(p.name for p in tmp_path.iterdir()) == ['link.json', 'real.json', 'short.yaml']


def test_a_lone_surrogate_in_a_name_is_refused():
    message = refusal(PAPER_TEXT.replace('name: paper', 'name: "a\\ud800b"'))
    assert 'name' in message and 'surrogate' in message


def test_bench_stress_fuzz_classifies_each_scene():
    """A smoke run of ``bench stress --fuzz``: a worker process, seeded scenes, a tally."""
    from impact_arm_bench.fuzz import GOOD, run_fuzz

    tally, bad = run_fuzz(4, seed=1, timeout=60.0)
    assert sum(tally.values()) == 4 and not bad, bad
    assert set(k for k, v in tally.items() if v) <= set(GOOD)


def test_a_nul_byte_in_a_scene_is_refused_in_one_line(tmp_path):
    path = tmp_path / 'nul.yaml'
    path.write_bytes(PAPER_TEXT.encode()[:40] + b'\x00' + PAPER_TEXT.encode()[40:])
    with pytest.raises(SceneError) as err:
        load_scene(str(path))
    assert 'not valid YAML' in str(err.value) and '\n' not in str(err.value)


@pytest.mark.parametrize('cut', [1, 2, 3])
def test_a_command_cut_short_and_zero_padded_is_refused(cut):
    """A transport pads a payload cut 1-3 bytes short back to its length with zeros (seen
    between two processes with Fast DDS): the last torque's top bytes, sign and exponent,
    become zero. (A torque whose low mantissa bytes are zero too would read as exactly 0,
    which no check can tell from a valid zero.)"""
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64MultiArray
    from impact_arm.driver.arm import CommandError, SimulatedArm

    raw = serialize_message(Float64MultiArray(data=[1.5, -2.2500001]))
    padded = raw[: len(raw) - cut] + bytes(cut)
    with pytest.raises(MalformedMessage):
        float64_array_data(raw[: len(raw) - cut])  # as sent: too short
    values = float64_array_data(padded)  # as received: parses ...
    assert values[0] == 1.5 and 0 < abs(values[1]) < 1e-300
    arm = SimulatedArm(load_scene(PAPER), 1000.0)
    with pytest.raises(CommandError, match='subnormal'):  # ... and the driver refuses it
        arm.check_command(values)
    assert arm.check_command([1.5, 0.0]) == [1.5, 0.0]


def test_a_command_with_bytes_appended_is_malformed():
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Float64MultiArray

    raw = serialize_message(Float64MultiArray(data=[1.5, -2.25]))
    assert float64_array_data(raw) == [1.5, -2.25]
    with pytest.raises(MalformedMessage, match='after the end'):
        float64_array_data(raw + bytes(8))


def test_a_huge_sampled_run_is_estimated_and_needs_yes(tmp_path, capsys):
    """publish_rate 1e6 Hz up to t_max 60 s is 6e7 samples (~3 min): refused up front with
    the estimate unless --yes; a run past a tenth of the limit states its estimate and runs."""
    from impact_arm.tools import cli

    huge = tmp_path / 'huge.yaml'
    huge.write_text(PAPER_TEXT.replace('publish_rate: 1000.0', 'publish_rate: 1000000.0'))
    assert cli.main(['simulate', '--scene', str(huge)]) == 2
    err = capsys.readouterr().err
    assert '6e+07 samples' in err and '--yes' in err and err.count('\n') == 1, err
    medium = tmp_path / 'medium.yaml'
    medium.write_text(
        PAPER_TEXT.replace('cycles: 15', 'cycles: 1')
        .replace('t_max: 60.0', 't_max: 2.0')
        .replace('publish_rate: 1000.0', 'publish_rate: 600000.0')
    )
    assert cli.main(['simulate', '--scene', str(medium)]) == 0
    assert 'samples: up to about' in capsys.readouterr().err
