"""The small things of the command line a newcomer meets: the help lists every command and
explains every option, the printed "whole command" time includes the interpreter's start,
`compare` keeps an earlier result, a resumed sweep prints no "nan", the report names an
offline file once."""

import argparse
import math
import subprocess
import sys

import pytest

from impact_arm.tools.cli import COMMANDS, build_parser, main

EVERY_COMMAND = ['simulate', 'urdf', *COMMANDS]


def test_help_lists_every_command():
    out = subprocess.run(
        [sys.executable, '-m', 'impact_arm.tools.cli', '--help'],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0
    description = out.stdout.split('positional arguments')[0]
    for name in EVERY_COMMAND:
        assert name in description, name
        assert f'\n    {name} ' in out.stdout, name  # with its one-line help


def _options_without_help(parser, prefix):
    missing = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                missing += _options_without_help(sub, f'{prefix} {name}')
            continue
        if not action.help or action.help == argparse.SUPPRESS:
            missing.append(f'{prefix} {"/".join(action.option_strings) or action.dest}')
    return missing


@pytest.mark.parametrize('command', EVERY_COMMAND)
def test_every_option_has_a_help_text(command):
    parser = build_parser(command)
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    assert _options_without_help(sub.choices[command], command) == []


def test_the_whole_command_time_counts_the_interpreter_start():
    """A process that spends 0.6 s before importing the command line: its whole-command time
    includes them (the time a user waits), not only what follows the import."""
    code = (
        'import time; time.sleep(0.6)\n'
        'from impact_arm.tools.cli import whole_command_seconds, STARTED\n'
        'print(whole_command_seconds(), time.perf_counter() - STARTED)'
    )
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=60)
    whole, since_import = map(float, out.stdout.split())
    assert whole >= 0.6 > since_import


def test_compare_keeps_an_earlier_result(tmp_path, capsys):
    from impact_arm.tools.compare import default_out

    assert default_out('runs/a.mcap', 'paper') != default_out('runs/a.mcap', 'fitted.yaml')
    out = tmp_path / 'cmp'
    out.mkdir()
    (out / 'table.json').write_text('{"earlier": true}')
    code = main(['compare', str(tmp_path / 'a.mcap'), 'paper', '--out', str(out)])
    err = capsys.readouterr().err
    assert code == 2 and 'holds an earlier comparison (table.json)' in err and '--force' in err
    assert (out / 'table.json').read_text() == '{"earlier": true}'


def test_a_resumed_sweep_prints_no_nan():
    from impact_arm.tools.sweep import summary_line

    stats = dict(runs=8, ran=0, skipped=8, failed=0, wall=0.2, startup=0.2, rate=math.nan)
    assert 'nothing left to run' in summary_line(stats) and 'nan' not in summary_line(stats)
    one_chunk = dict(stats, ran=2, skipped=6)  # every result in the first chunk: no rate
    assert 'nan' not in summary_line(one_chunk) and 'runs/s' not in summary_line(one_chunk)
    assert '250 runs/s' in summary_line(dict(stats, ran=8, skipped=0, rate=250.0))


def test_the_report_names_an_offline_recording_once():
    from impact_arm.tools.analysis import recording_origin

    assert recording_origin({'node': 'offline', 'mode': 'offline'}) == (
        'offline run, impact-arm simulate --mcap'
    )
    assert recording_origin({'node': 'recorder', 'mode': 'lockstep'}) == 'recorder, lockstep'
    assert recording_origin({'node': 'recorder'}) == 'recorder, live'


def _option_helps(command):
    parser = build_parser(command)
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return {
        action.option_strings[0]: (action.help, action.metavar, action.default)
        for action in sub.choices[command]._actions
        if action.option_strings
    }


def test_fit_and_compare_read_a_recording_through_the_same_options():
    """`fit` and `compare` declare --joints, --states-topic and --wrench-topic through one
    function: the same metavar and default, the help texts each command has always shown."""
    fit, compare = _option_helps('fit'), _option_helps('compare')
    joints = 'joint names in the joint states, base first (default joint1..jointN)'
    assert fit['--joints'] == compare['--joints'] == (joints, 'A,B,...', None)
    assert fit['--states-topic'] == (
        'sensor_msgs/JointState topic (default /joint_states)',
        'T',
        None,
    )
    assert compare['--states-topic'] == (
        'sensor_msgs/JointState topic of the recordings (default /joint_states)',
        'T',
        None,
    )
    assert fit['--wrench-topic'] == (
        'geometry_msgs/WrenchStamped topic (default /contact_wrench if recorded; without it '
        'the fit uses the joint states alone)',
        'T',
        None,
    )
    assert compare['--wrench-topic'] == (
        'geometry_msgs/WrenchStamped topic (default /contact_wrench if recorded)',
        'T',
        None,
    )
