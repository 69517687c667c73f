"""A Foxglove / Lichtblick layout made for one arm and the topics of its recording.

``viewer_layout(scene, topics)`` is the layout ``impact-arm layout`` prints and ``impact-arm
run`` / ``simulate --mcap`` write beside each recording; for the article's scene it is
``config/impact_arm.foxglove.json`` (test/io/test_viewer_layout.py keeps the two equal). What
it holds, and why:

- a 3D panel facing the arm's x-z plane, its camera distance scaled by the arm's reach;
- plots of every joint's position and effort, each line labelled with the joint's name
  (``/joint_states`` carries the scene's joints in ``Scene.joint_names`` order);
- the contact force: each period's peak beside its averages;
- each mounted surface's plate displacement (``/surface_mounts``), when the scene has one;
- the impacts so far as a table, from ``/impact_table`` (every row in each message, so a
  seek shows them all), inside a tab whose title says what it is: a Table panel's own
  toolbar shows its message path, not a title.

A panel is left out when the recording lacks its topics. The plots' legends sit above the
data ("top"): floating, they covered the force spikes' tops. Panel titles are set under the
keys both apps read (``foxglovePanelTitle``, ``lichtblickPanelTitle``, ``title``).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from typing import TYPE_CHECKING, Any

import math

from ..contract import (
    CONTACT_FORCE_PEAK,
    CONTACT_WRENCH,
    IMPACT_MARKERS,
    IMPACT_REPORT,
    IMPACT_TABLE,
    JOINT_STATES,
    ROBOT_DESCRIPTION,
    SURFACE_MOUNTS,
    TF,
    TF_STATIC,
)
from .impact_table import COLUMNS
from .scene_visuals import mounted_surfaces

if TYPE_CHECKING:
    from ..physics.scene import Scene

# the article's view (2 m reach): 6.5 m away, the target 0.3 m below the shoulder; other
# arms scale with their reach
CAMERA_DISTANCE_PER_REACH = 3.25
CAMERA_DROP_PER_REACH = 0.15
# px of the legend beside a plot: the longest label and its value at the cursor
LEGEND_WIDTH = 215
TABLE_SCRIPT_OUTPUT = '/studio_script/impacts'
TABLE_PATH = TABLE_SCRIPT_OUTPUT + '.rows'
TABLE_TITLE = 'Impacts so far: time, duration [µs], deformation [µm], force [kN], CoR'
TAB_TITLE = 'Impacts so far'  # a tab shows ~15 characters of its title
# the user script: /impact_table's JSON as rows, unchanged (rounded where it is written,
# io/impact_table.py); stateless, so a seek cannot leave it holding part of the table. The
# apps derive the output's message definition from its TypeScript type, which must name every
# field (an index signature or a union such as ``number | null`` fails to compile there)
TABLE_COLUMNS = ('impact', 't_contact [s]', *(column for column, _, _ in COLUMNS))
_ROW_FIELDS = '\n'.join(f'  "{column}": number;' for column in TABLE_COLUMNS)
TABLE_SCRIPT = f"""// every impact so far (/impact_table, JSON) as the rows of a table
import {{ Input }} from "./types";

export const inputs = ["{IMPACT_TABLE}"];
export const output = "{TABLE_SCRIPT_OUTPUT}";

type Row = {{
{_ROW_FIELDS}
}};
type Output = {{ rows: Row[] }};

export default function script(event: Input<"{IMPACT_TABLE}">): Output {{
  return {{ rows: JSON.parse(event.message.data).rows as Row[] }};
}}
"""


def recording_topics(scene: Scene) -> set[str]:
    """The topics a recording of ``scene`` holds (offline or ``impact-arm run``)."""
    topics = {JOINT_STATES, CONTACT_WRENCH, CONTACT_FORCE_PEAK, IMPACT_REPORT}
    topics |= {ROBOT_DESCRIPTION, TF_STATIC, TF, IMPACT_MARKERS, IMPACT_TABLE}
    if mounted_surfaces(scene):
        topics.add(SURFACE_MOUNTS)
    return topics


def _titled(title: str, config: dict[str, Any]) -> dict[str, Any]:
    return {'title': title, 'foxglovePanelTitle': title, 'lichtblickPanelTitle': title, **config}


def _plot(title: str, paths: Sequence[tuple[str, str]]) -> dict[str, Any]:
    """A plot of ``paths`` ((message path, label)) against the time since the file's start
    (header stamps), its legend above the data with each line's value at the cursor."""
    return _titled(
        title,
        {
            'paths': [
                {'value': v, 'enabled': True, 'timestampMethod': 'headerStamp', 'label': label}
                for v, label in paths
            ],
            'showXAxisLabels': True,
            'showYAxisLabels': True,
            'showLegend': True,
            'legendDisplay': 'left',
            'showPlotValuesInLegend': True,
            'isSynced': True,
            'xAxisVal': 'timestamp',
            'sidebarDimension': LEGEND_WIDTH,
        },
    )


def _three_d(reach: float, urdf_arm: bool) -> dict[str, Any]:
    return _titled(
        'Arm in its plane (URDF, TF, impact points coloured by peak force)',
        {
            'cameraState': {
                'distance': round(CAMERA_DISTANCE_PER_REACH * reach, 3),
                'perspective': True,
                'phi': 90.0,
                'thetaOffset': 0.0,
                'targetOffset': [0.0, 0.0, round(-CAMERA_DROP_PER_REACH * reach, 3)],
                'target': [0, 0, 0],
                'targetOrientation': [0, 0, 0, 1],
                'fovy': 45,
                'near': 0.01,
                'far': 5000,
            },
            # no followTf and no grid frameId: naming 'world' there made the 3D panel log
            # "Frame world not found" and "Missing transform from frame <world>" at every
            # load, before the first TF message reached it; unnamed, both are the root
            # frame of the TF tree, which is world for every arm
            'followMode': 'follow-none',
            'scene': {
                'backgroundColor': '#202020',
                # a URDF arm's frames share origins (world, impact_plane, its base link):
                # their labels overprinted each other into one unreadable word
                'transforms': {
                    'showLabel': not urdf_arm,
                    'axisScale': 0.4,
                    'enablePreloading': True,
                },
            },
            'transforms': {},
            'topics': {ROBOT_DESCRIPTION: {'visible': True}, IMPACT_MARKERS: {'visible': True}},
            'layers': {
                'grid': {
                    'layerId': 'foxglove.Grid',
                    'visible': True,
                    'label': 'Grid (x-z plane, 0.25 m)',
                    'size': 5,
                    'divisions': 20,
                    'lineWidth': 1,
                    'color': '#a0a0a040',
                    'position': [0, 0.3, 0],
                    'rotation': [90, 0, 0],
                    'order': 1,
                }
            },
            'publish': {
                'type': 'point',
                'poseTopic': '/move_base_simple/goal',
                'pointTopic': '/clicked_point',
                'poseEstimateTopic': '/initialpose',
                'poseEstimateXDeviation': 0.5,
                'poseEstimateYDeviation': 0.5,
                'poseEstimateThetaDeviation': 0.26179939,
            },
            'imageMode': {},
        },
    )


def _column(panels: Sequence[Any], direction: str = 'column') -> Any:
    """``panels`` stacked in equal shares (nested two-way splits, as the apps store them)."""
    if len(panels) == 1:
        return panels[0]
    return {
        'direction': direction,
        'splitPercentage': round(100 / len(panels)),
        'first': panels[0],
        'second': _column(panels[1:], direction),
    }


def nice_bound(extent: float) -> float:
    """The y bound a plot of values within +-``extent`` gets: 1.25 x extent rounded up to
    1, 2 or 5 times a power of ten (0 for no extent)."""
    if not (math.isfinite(extent) and extent > 0):
        return 0.0
    target = 1.25 * extent
    power = 10.0 ** math.floor(math.log10(target))
    return next(m * power for m in (1, 2, 5, 10) if m * power >= target * (1 - 1e-12))


def viewer_layout(
    scene: Scene, topics: Collection[str] | None = None, plate_extent: float | None = None
) -> dict[str, Any]:
    """The layout for ``scene`` and a recording holding ``topics`` (default: what a recording
    of the scene holds); ``plate_extent``: the largest plate displacement [m] recorded, which
    fixes the plate plot's y range (the apps' own range for a few µm was +-1 mm, a flat
    line). Raises ValueError when the topics allow no panel at all."""
    have = recording_topics(scene) if topics is None else set(topics)
    joints = list(scene.joint_names)
    configs: dict[str, Any] = {}
    user_nodes: dict[str, Any] = {}
    left: list[Any] = []
    right: list[Any] = []
    if have & {ROBOT_DESCRIPTION, TF, IMPACT_MARKERS}:
        configs['3D!arm'] = _three_d(sum(scene.lengths), bool(scene.urdf_text))
        left.append('3D!arm')
    if JOINT_STATES in have:
        configs['Plot!positions'] = _plot(
            'Joint positions [rad]',
            [(f'{JOINT_STATES}.position[{i}]', f'{n} [rad]') for i, n in enumerate(joints)],
        )
        configs['Plot!efforts'] = _plot(
            'Joint efforts [N m]',
            [(f'{JOINT_STATES}.effort[{i}]', f'{n} [N m]') for i, n in enumerate(joints)],
        )
        right += ['Plot!positions', 'Plot!efforts']
    forces = [
        # short: the legend beside the plot shows ~20 characters
        (f'{CONTACT_FORCE_PEAK}.wrench.force.y', 'normal peak [N]'),
        (f'{CONTACT_WRENCH}.wrench.force.y', 'normal mean [N]'),
        (f'{CONTACT_WRENCH}.wrench.force.x', 'tangential mean [N]'),
    ]
    forces = [(path, label) for path, label in forces if path.split('.')[0] in have]
    if forces:
        configs['Plot!force'] = _plot('Contact force: peak and average of each period [N]', forces)
        right.append('Plot!force')
    mounted = mounted_surfaces(scene)
    if mounted and SURFACE_MOUNTS in have:
        configs['Plot!plates'] = _plot(
            'Plate displacement from rest, up [m]',
            [(f'{SURFACE_MOUNTS}.position[{j}]', f'{f} z [m]') for j, (f, _) in enumerate(mounted)],
        )
        bound = nice_bound(plate_extent or 0.0)
        if bound > 0:
            configs['Plot!plates'].update(minYValue=-bound, maxYValue=bound)
        right.append('Plot!plates')
    if IMPACT_TABLE in have:
        configs['Table!impacts'] = _titled(TABLE_TITLE, {'topicPath': TABLE_PATH})
        configs['Tab!impacts'] = _titled(
            TABLE_TITLE,
            {'activeTabIdx': 0, 'tabs': [{'title': TAB_TITLE, 'layout': 'Table!impacts'}]},
        )
        user_nodes['impact-table'] = {'name': 'impacts', 'sourceCode': TABLE_SCRIPT}
        left.append('Tab!impacts')
    if not configs:
        raise ValueError(f'no panel to show: none of its topics is among {sorted(have)}')
    if len(left) == 2:  # the arm above its impacts, as the article's figures
        left_tree: Any = {'direction': 'column', 'splitPercentage': 65, 'first': left[0]}
        left_tree['second'] = left[1]
    else:
        left_tree = _column(left) if left else None
    right_tree = _column(right) if right else None
    if left_tree is not None and right_tree is not None:
        tree: Any = {'direction': 'row', 'splitPercentage': 55}
        tree['first'], tree['second'] = left_tree, right_tree
    else:
        tree = left_tree if left_tree is not None else right_tree
    return {
        'configById': configs,
        'globalVariables': {},
        'userNodes': user_nodes,
        'playbackConfig': {'speed': 1.0},
        'layout': tree,
    }


LAYOUT_SUFFIX = '.foxglove.json'


def layout_path_beside(recording: str) -> str:
    """Where the layout of ``recording`` goes: ``runs/x.mcap`` -> ``runs/x.foxglove.json``
    (a rosbag2 folder ``runs/x/`` -> ``runs/x.foxglove.json``)."""
    base = recording.rstrip('/\\')
    if base.endswith('.mcap'):
        base = base[: -len('.mcap')]
    return base + LAYOUT_SUFFIX


def recording_layout(recording: str, scene: Scene | None = None) -> dict[str, Any]:
    """The layout for a recording: its stored scene (or ``scene``) and the topics its files
    hold. Raises RecordingInputError for an unreadable recording or one without a scene."""
    from .mcap_ros2 import topics_info
    from .recording import RecordingInputError, mcap_files, recorded_scene

    from .mcap_ros2 import iter_raw
    from .recording import _joint_state  # the one JointState reader of the package

    topics: set[str] = set()
    extent = 0.0
    for f in mcap_files(recording):
        topics |= set(topics_info(f))
        for m in iter_raw(f, [SURFACE_MOUNTS], log_time_order=False):
            z = [abs(v) for v in _joint_state(m.data)[2] if math.isfinite(v)]
            extent = max([extent, *z])
    if scene is None:
        scene = recorded_scene(recording)
    if scene is None:
        raise RecordingInputError(
            f'recording {recording}: it stores no scene; give the one it ran (--scene)'
        )
    return viewer_layout(scene, topics, extent)


def layout_text(layout: dict[str, Any]) -> str:
    """The layout as the file the apps import (UTF-8 JSON, 2-space indent, final newline)."""
    import json

    return json.dumps(layout, indent=2, ensure_ascii=False) + '\n'


def write_layout_beside(recording: str, scene: Scene | None = None) -> str:
    """Writes the recording's layout beside it (``layout_path_beside``); returns its path."""
    path = layout_path_beside(recording)
    with open(path, 'w', encoding='utf-8') as f:
        f.write(layout_text(recording_layout(recording, scene)))
    return path
