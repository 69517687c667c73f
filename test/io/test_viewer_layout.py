"""The Foxglove / Lichtblick layouts, read the way the viewers read them: the layout tree and
its panel configs, the titles the apps show, and every message path and script input
resolved against a recording (read back with rosbags). The seek a viewer makes is played
too: the newest /impact_table before a time must hold every impact up to it."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from impact_arm.io.offline_mcap import OfflineRecorder
from impact_arm.io.scene_visuals import event_states
from impact_arm.io.viewer_layout import layout_path_beside, recording_layout, viewer_layout
from impact_arm.physics.scene import load_scene, resolve_scene_path
from impact_arm.physics.simulate import run
from repo_paths import REPO_ROOT

ROOT = REPO_ROOT
SHIPPED = os.path.join(ROOT, 'config', 'impact_arm.foxglove.json')
REAL_ARM = os.path.join(ROOT, 'examples', 'real_arm.yaml')
PANEL_KINDS = {'3D', 'Plot', 'Table', 'Tab'}
# the legend positions the Plot panel knows; "floating" lies over the data
LEGENDS = {'top', 'left', 'none'}


def _record(tmp_path, scene_name, cycles):
    scene = load_scene(resolve_scene_path(scene_name))
    scene = scene.replace(cycles=cycles) if hasattr(scene, 'replace') else scene
    path = tmp_path / f'{scene.name}.mcap'
    rec = OfflineRecorder(path, scene)
    result = None
    try:
        result = run(scene, observer=rec)
    finally:
        rec.close(result)
    messages = {}
    with AnyReader([Path(path)]) as reader:
        for conn, t_ns, raw in reader.messages():
            messages.setdefault(conn.topic, []).append(
                (t_ns, reader.deserialize(raw, conn.msgtype))
            )
    return path, scene, result, messages


@pytest.fixture(scope='module')
def paper(tmp_path_factory):
    return _record(tmp_path_factory.mktemp('paper'), 'paper', None)


@pytest.fixture(scope='module')
def real_arm(tmp_path_factory):
    return _record(tmp_path_factory.mktemp('real'), REAL_ARM, None)


def panels_of(layout):
    """The panel ids the apps render: the layout tree's leaves and the tabs' layouts."""

    def walk(node):
        if isinstance(node, str):
            tabs = layout['configById'][node].get('tabs', [])
            return [node] + [p for tab in tabs for p in walk(tab['layout'])]
        assert node['direction'] in ('row', 'column') and 0 < node['splitPercentage'] < 100
        return walk(node['first']) + walk(node['second'])

    return walk(layout['layout'])


def resolve(message, path):
    """A message path's value in ``message`` (the part after the topic: fields and [i])."""
    value = message
    for name, index in re.findall(r'\.(\w+)|\[(\d+)\]', path):
        value = getattr(value, name) if name else value[int(index)]
    return value


def check_layout(layout, messages):
    """What a viewer needs of ``layout`` to show ``messages`` (topic -> [(log ns, msg)])."""
    # what the apps require of a layout file before they install it (Lichtblick refuses one
    # without these): objects for configById and globalVariables, a numeric playback speed,
    # userNodes an object, layout a panel id or a split tree
    assert isinstance(layout['configById'], dict) and isinstance(layout['globalVariables'], dict)
    assert isinstance(layout['playbackConfig']['speed'], (int, float))
    assert isinstance(layout['userNodes'], dict)
    assert isinstance(layout['layout'], (str, dict))
    shown = panels_of(layout)
    assert sorted(shown) == sorted(layout['configById']), 'a panel without config or unshown'
    assert {p.split('!')[0] for p in shown} <= PANEL_KINDS
    for panel_id, config in layout['configById'].items():
        # each app reads its own key for the title: none may show the bare panel kind
        title = config['foxglovePanelTitle']
        assert title and config['lichtblickPanelTitle'] == config['title'] == title
        for entry in config.get('paths', []):
            topic, _, rest = entry['value'].partition('.')
            assert topic in messages, f'{panel_id}: {topic} is not in the recording'
            value = resolve(messages[topic][0][1], '.' + rest)
            assert isinstance(value, float), (panel_id, entry['value'])
            assert entry['timestampMethod'] == 'headerStamp' and entry['label']
        if panel_id.startswith('Plot!'):
            assert config['legendDisplay'] in LEGENDS, 'the legend would cover the data'
    three_d = layout['configById']['3D!arm']
    assert set(three_d['topics']) <= set(messages)
    for node in layout['userNodes'].values():
        source = node['sourceCode']
        inputs = re.search(r'inputs = \[([^]]*)\]', source).group(1)
        output = re.search(r'output = "([^"]+)"', source).group(1)
        assert output.startswith('/studio_script/')
        for topic in (t.strip().strip('"') for t in inputs.split(',')):
            assert topic in messages
        tables = [c for c in layout['configById'].values() if 'topicPath' in c]
        assert tables and all(c['topicPath'] == output + '.rows' for c in tables)


def seek(messages, topic, t_ns):
    """The newest message of ``topic`` logged at or before ``t_ns``: what a viewer hands a
    panel (or a user script) after seeking there."""
    before = [m for log, m in messages.get(topic, []) if log <= t_ns]
    return before[-1] if before else None


def test_the_shipped_layout_is_the_articles_generated_one():
    """config/impact_arm.foxglove.json is what ``viewer_layout`` makes for the article's
    scene, so the article's layout and every generated one change together."""
    expected = viewer_layout(load_scene(resolve_scene_path('paper')))
    assert json.load(open(SHIPPED, encoding='utf-8')) == expected


def test_the_articles_layout_reads_its_recording(paper):
    path, scene, result, messages = paper
    layout = json.load(open(SHIPPED, encoding='utf-8'))
    check_layout(layout, messages)
    positions = layout['configById']['Plot!positions']['paths']
    assert [p['label'] for p in positions] == ['joint1 [rad]', 'joint2 [rad]']
    assert 'Plot!plates' not in layout['configById']  # no mount: no plate to plot
    assert layout['configById']['3D!arm']['scene']['transforms']['showLabel'] is True
    # the recording's own layout, from its stored scene and topics, is the shipped one
    assert recording_layout(str(path)) == layout


def test_the_three_link_arm_plots_every_joint_by_name_and_its_plate(real_arm):
    path, scene, result, messages = real_arm
    layout = recording_layout(str(path))
    check_layout(layout, messages)
    names = list(messages['/joint_states'][0][1].name)
    assert names == ['shoulder', 'elbow', 'wrist']
    for plot, unit in (('Plot!positions', 'rad'), ('Plot!efforts', 'N m')):
        paths = layout['configById'][plot]['paths']
        # each line's label names the joint whose index the path reads
        assert [p['label'] for p in paths] == [f'{n} [{unit}]' for n in names]
        assert [int(re.search(r'\[(\d+)\]', p['value']).group(1)) for p in paths] == [0, 1, 2]
    (plate,) = layout['configById']['Plot!plates']['paths']
    mount = messages['/surface_mounts'][0][1]
    index = int(re.search(r'\[(\d+)\]', plate['value']).group(1))
    assert plate['label'].startswith(mount.name[index])
    # the plate moves by a few µm: its plot's y range is set from the recording (the apps'
    # own was +-1 mm, a flat line), the largest displacement within it but above half of it
    zs = [abs(m.position[index]) for _, m in messages['/surface_mounts']]
    config = layout['configById']['Plot!plates']
    assert config['minYValue'] == -config['maxYValue']
    assert max(zs) < config['maxYValue'] < 4 * max(zs) and max(zs) > 1e-7
    # the frames of a URDF arm share origins: no labels, which overprinted each other
    assert layout['configById']['3D!arm']['scene']['transforms']['showLabel'] is False
    # the 3D camera scaled to the arm, not the article's view copied
    assert layout != json.load(open(SHIPPED, encoding='utf-8'))


def test_plot_bounds_are_round_numbers_just_above_the_extent():
    from impact_arm.io.viewer_layout import nice_bound

    assert nice_bound(7.86e-6) == pytest.approx(1e-5)
    assert nice_bound(1e-5) == pytest.approx(2e-5)
    assert nice_bound(3.9e-4) == pytest.approx(5e-4)
    assert nice_bound(0.0) == nice_bound(float('nan')) == 0.0


def test_a_recording_without_a_topic_gets_no_panel_for_it():
    scene = load_scene(resolve_scene_path('paper'))
    layout = viewer_layout(scene, {'/joint_states', '/tf', '/robot_description'})
    assert sorted(layout['configById']) == ['3D!arm', 'Plot!efforts', 'Plot!positions']
    assert layout['userNodes'] == {}
    check_tree = panels_of(layout)
    assert sorted(check_tree) == sorted(layout['configById'])
    with pytest.raises(ValueError, match='no panel'):
        viewer_layout(scene, {'/something_else'})


def test_after_any_seek_the_table_lists_every_impact_so_far_rounded(paper):
    """The table's script turns the newest /impact_table into rows; after a seek to any
    time that message holds every impact up to it, as during play, with numbers of at most
    4 significant digits in kN, µs and µm."""
    path, scene, result, messages = paper
    # the contact frames' stamps (the first event of each impact)
    contacts = [event_states(i)[0][1] for i in result.impacts]
    assert len(contacts) == 15
    end = messages['/joint_states'][-1][0]
    for t_ns in [
        0,
        contacts[0] - 1,
        *contacts,
        *(c - 1 for c in contacts),
        contacts[6] + 10**8,
        end,
    ]:
        table = seek(messages, '/impact_table', t_ns)
        done = [c for c in contacts if c <= t_ns]
        rows = [] if table is None else json.loads(table.data)['rows']
        assert [r['impact'] for r in rows] == list(range(1, len(done) + 1)), t_ns
    rows = json.loads(messages['/impact_table'][-1][1].data)['rows']
    for row, impact in zip(rows, result.impacts):
        assert row['F max [kN]'] == pytest.approx(impact.F_max / 1e3, rel=5e-4)
        assert row['duration [µs]'] == pytest.approx(impact.duration * 1e6, rel=5e-4)
        assert row['δ max [µm]'] == pytest.approx(impact.delta_m * 1e6, rel=5e-4)
        # the time to 0.1 ms (tells every impact and event frame apart), the rest to 4 digits
        assert row['t_contact [s]'] == round(impact.t_contact, 4)
        for column, value in row.items():
            if column in ('impact', 't_contact [s]'):
                continue
            digits = re.sub(r'^-?0*\.?0*', '', repr(value)).replace('.', '')
            assert len(digits) <= 4, (column, value)
    assert rows[0]['F max [kN]'] == 27.79  # the article's first impact, 27 786 N


def test_layout_command_prints_a_scenes_layout_and_writes_a_recordings(tmp_path, real_arm):
    env = dict(os.environ, PYTHONPATH=ROOT)
    out = subprocess.run(
        [sys.executable, '-m', 'impact_arm.tools.cli', 'layout', '--scene', REAL_ARM],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    assert out.returncode == 0, out.stderr
    printed = json.loads(out.stdout)
    assert [p['label'] for p in printed['configById']['Plot!positions']['paths']][2] == (
        'wrist [rad]'
    )
    target = tmp_path / 'real.foxglove.json'
    out = subprocess.run(
        [sys.executable, '-m', 'impact_arm.tools.cli', 'layout', str(real_arm[0])]
        + ['--out', str(target)],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(target.read_text(encoding='utf-8')) == recording_layout(str(real_arm[0]))
    assert layout_path_beside('runs/a.mcap') == 'runs/a.foxglove.json'
    assert layout_path_beside('runs/bag/') == 'runs/bag.foxglove.json'
    out = subprocess.run(
        [sys.executable, '-m', 'impact_arm.tools.cli', 'layout'],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    assert out.returncode == 2 and 'give a recording' in out.stderr
