"""The Python API (docs/api.md): its names, its import cost, its typed records, what it refuses,
and the document's own example run as written."""

import ast
import json
import os
import re
import subprocess
import sys

import pytest

import impact_arm as ia
from impact_arm import api
from repo_paths import REPO_ROOT

ROOT = REPO_ROOT
DOC = os.path.join(ROOT, 'docs', 'api.md')


def _python(code):
    out = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, timeout=120, cwd=ROOT
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def test_import_impact_arm_loads_nothing_of_the_api():
    """``import impact_arm`` is the cost of its own file: no numpy, no scene, no kernel."""
    loaded = _python(
        'import sys, time\n'
        't = time.perf_counter()\n'
        'import impact_arm\n'
        'print(time.perf_counter() - t)\n'
        'print(" ".join(sorted(m for m in sys.modules if m.startswith(("impact_arm", "numpy")))))'
    ).split('\n')
    assert loaded[1].split() == ['impact_arm'], loaded[1]
    assert float(loaded[0]) < 0.3  # generous: the file alone takes a few milliseconds


def test_every_name_resolves_and_the_api_imports_no_ros():
    out = _python(
        'import sys\n'
        'import impact_arm as ia\n'
        'missing = [n for n in ia.__all__ if getattr(ia, n, None) is None]\n'
        'print(missing, "rclpy" in sys.modules)'
    )
    assert out.strip() == '[] False'


def test_the_top_level_offers_exactly_the_api():
    assert ia.__all__ == api.__all__ == sorted(api.SOURCES)
    assert set(dir(ia)) >= set(ia.__all__)
    with pytest.raises(AttributeError, match='no attribute'):
        ia.not_a_name  # noqa: B018


def test_every_package_states_its_public_names():
    """Each package's ``__init__`` has an ``__all__``, and each name in it is there."""
    package = os.path.join(ROOT, 'impact_arm')
    without = []
    for folder, _, files in os.walk(package):
        if '__init__.py' not in files:
            continue
        path = os.path.join(folder, '__init__.py')
        tree = ast.parse(open(path, encoding='utf-8').read())
        assigned = [
            node
            for node in tree.body
            if isinstance(node, (ast.Assign, ast.AnnAssign))
            and any(
                isinstance(t, ast.Name) and t.id == '__all__'
                for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
            )
        ]
        if not assigned:
            without.append(os.path.relpath(path, ROOT))
    assert not without, without


def _headings(text):
    return set(re.findall(r'^### `(\w+)', text, re.M))


def test_the_document_describes_every_name():
    text = open(DOC, encoding='utf-8').read()
    errors = {n for n in ia.__all__ if n.endswith('Error')}
    assert _headings(text) | errors >= set(ia.__all__), set(ia.__all__) - _headings(text)
    assert all(f'`{n}`' in text for n in errors)
    # every function's section says what it takes, gives and refuses
    for name in ('load_scene', 'simulate', 'read_recording', 'fit', 'compare'):
        section = text.split(f'### `{name}(')[1].split('\n### ')[0]
        assert 'Args:' in section and 'Returns:' in section and 'Raises:' in section, name


def _examples():
    text = open(DOC, encoding='utf-8').read()
    return re.findall(r'^```python\n(.*?)^```', text, re.M | re.S)


def test_the_documents_example_runs_as_written(tmp_path, monkeypatch, capsys):
    """The code blocks of docs/api.md, in order, in one namespace, in a fresh directory: the
    recordings they read are the ones they write."""
    blocks = _examples()
    assert len(blocks) >= 3
    monkeypatch.chdir(tmp_path)
    namespace = {'__name__': '__docs__'}
    for block in blocks:
        exec(compile(block, DOC, 'exec'), namespace)
    out = capsys.readouterr().out
    assert 'fits' in out and "['joint1', 'joint2', 'joint3']" in out
    assert (tmp_path / 'fitted.yaml').is_file()


def test_the_five_lines_on_a_three_link_recording(tmp_path):
    """The issue's five lines, on a recording of three links whose scene it stores."""
    path = str(tmp_path / 'three.mcap')
    ia.simulate('three_link', mcap=path)
    scene = ia.load_scene('three_link')
    res = ia.simulate(scene)
    rec = ia.read_recording(path)
    verdict = ia.fit(rec, scene, {'surfaces[0].mu': ia.Param(0.05, 1.0)}).verdict
    assert rec.n == 3 and rec.joints == ['joint1', 'joint2', 'joint3']
    assert res.impacts[0].F_max > 0 and verdict == 'fits'


def test_impacts_are_typed_and_give_back_the_same_json():
    """The run's own records are the API's, not converted; the JSON holds their dicts, and
    a record read back from it is the same record."""
    res = ia.simulate('paper', samples=False)
    assert res.ok and res.impacts and all(isinstance(i, ia.Impact) for i in res.impacts)
    assert list(res.impacts) == res.run.impacts and res.impacts[0] is res.run.impacts[0]
    data = res.to_json()
    assert data['impacts'] == [i.to_dict() for i in res.impacts]
    assert json.dumps(data) == json.dumps(res.run.to_json())
    first = res.impacts[0]
    assert ia.Impact.from_dict(json.loads(json.dumps(first.to_dict()))) == first
    with pytest.raises(AttributeError):
        first.F_max = 0.0  # frozen


def test_an_impact_record_with_a_wrong_key_is_refused_in_one_line():
    record = ia.simulate('paper', samples=False).impacts[0].to_dict()
    record['F_peak'] = record.pop('F_max')
    with pytest.raises(ia.ImpactArmError) as exc:
        ia.Impact.from_dict(record)
    message = str(exc.value)
    assert 'missing F_max' in message and 'unknown F_peak' in message and '\n' not in message


def test_a_report_is_read_back_once_into_its_record_or_refused_in_one_line():
    """``impact_from_json``, the readers' one way from a report's text to its ``Impact``:
    the text of ``to_dict`` gives the record back; text that is no JSON object of the
    record's fields is refused with a one-line ImpactArmError."""
    from impact_arm.physics.impact import impact_from_json

    first = ia.simulate('paper', samples=False).impacts[0]
    text = json.dumps(first.to_dict())
    assert impact_from_json(text) == first == impact_from_json(text.encode())
    for bad in ('', 'ab', '[1, 2]', '{"index": 1}', b'\xff'):
        with pytest.raises(ia.ImpactArmError) as exc:
            impact_from_json(bad)
        assert str(exc.value).startswith('impact record:') and '\n' not in str(exc.value)


def test_load_scene_takes_a_name_a_path_data_and_a_scene(tmp_path):
    by_name = ia.load_scene('paper')
    by_path = ia.load_scene(by_name.source_path)
    from impact_arm.physics.scene import scene_data  # YAML 1.2 numbers, as scene files mean

    data = scene_data(by_name.source_text, by_name.source_path)
    by_data = ia.load_scene(data)
    assert by_name == by_path == by_data and ia.load_scene(by_name) is by_name
    # a scene from data keeps its text: a study and a fit can rebuild it
    assert ia.Study(by_data).scene() == by_name
    with pytest.raises(ia.SceneError, match='no_such_scene'):
        ia.load_scene('no_such_scene')
    with pytest.raises(ia.SceneError, match='expected a scene name'):
        ia.load_scene(42)


@pytest.mark.parametrize(
    'kwargs, message',
    [
        ({'control_rate': -1.0}, 'control_rate = -1.0 is out of range: must be >= 0 Hz'),
        ({'samples': False, 'mcap': 'x.mcap'}, 'no mcap can be written'),
        ({'samples': False, 'control_rate': 1000.0}, 'control_rate = 1000 Hz must be 0'),
    ],
)
def test_simulate_refuses_what_it_cannot_do_in_one_line(kwargs, message, tmp_path):
    with pytest.raises(ia.SceneError) as exc:
        ia.simulate('paper', **kwargs)
    assert message in str(exc.value) and '\n' not in str(exc.value)
    assert not (tmp_path / 'x.mcap').exists()


@pytest.mark.parametrize(
    'args, message',
    [
        ((1.0, 0.5), 'lo = 1 must be < hi = 0.5'),
        ((0.0, float('inf')), 'must be finite numbers'),
        ((0.1, 1.0, 2.0), 'start = 2 is out of range: must be in [0.1, 1]'),
    ],
)
def test_param_refuses_bounds_out_of_range(args, message):
    with pytest.raises(ia.FitError) as exc:
        ia.Param(*args)
    assert message in str(exc.value)
    assert ia.Param(0.1, 1.0, 0.5).bounds() == (0.1, 1.0, 0.5)


def test_a_recording_that_stores_no_scene_is_read_only_with_one(tmp_path):
    """No arm is assumed: a recording without its scene needs one (or its joints)."""
    from impact_arm.io.synthetic import synthetic_recording, write_rosbag2

    folder = str(tmp_path / 'bag')
    write_rosbag2(synthetic_recording('paper', cycles=2, noise={}), folder)
    with pytest.raises(ia.RecordingInputError) as exc:
        ia.read_recording(folder)
    assert 'stores no scene' in str(exc.value) and 'pass scene=' in str(exc.value)
    from impact_arm.io.recording import read_recording

    with pytest.raises(ia.RecordingInputError, match='stores no scene'):
        read_recording(folder)  # the reader underneath assumes no joint count either
    rec = ia.read_recording(folder, 'paper')
    assert rec.joints == ['joint1', 'joint2'] and rec.n == 2


def test_fit_takes_a_path_and_the_scene_the_recording_stores(tmp_path):
    path = str(tmp_path / 'paper.mcap')
    ia.simulate('paper', mcap=path)
    result = ia.fit(path, None, {'surfaces[0].mu': (0.05, 1.0)})
    assert result.verdict_kind is ia.Verdict.FITS and result.fits
    assert result.parameters['surfaces[0].mu'].value == pytest.approx(0.2, rel=1e-3)
    with pytest.raises(ia.FitError, match='scene: None needs a recording path'):
        ia.fit(result.recording, None, {'surfaces[0].mu': (0.05, 1.0)})
