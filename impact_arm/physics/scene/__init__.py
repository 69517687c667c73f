"""Scenes: load, validate and normalise a YAML scene into a frozen ``Scene``.

Every key is checked against ``SCHEMA``: its type, its allowed range or choices, and whether it
is required. Unknown keys are refused so a typo never silently falls back to a default. Errors
name the key path, the value and the allowed range, e.g.::

    scene 'bad.yaml': links[1].mass = -1.0 is out of range: must be > 0 (kg)

Angles are given in degrees in the file (the user-facing edge) and converted to radians here;
everything after this package is SI. The schema is documented in ``docs/scene.md``.

The package in layers, each importing only those above it:

* ``types``: the frozen records (``Scene``, ``Surface``, ``JointSpec``, ...);
* ``schema``: every key's spec and ``SceneChecker``, which walks data against them;
* ``urdf``: a robot description (URDF text) to the planar chain the model simulates;
* ``arm``: the arm's links from the scene's ``links`` or its URDF;
* ``checks``: the checks across keys (physical ranges, joints, sensors);
* ``parse``: checked data to ``Scene``;
* ``files``: scene files and names, the YAML reader, the text a recording stores.
"""

from .checks import (
    MAX_COM_DISTANCE,
    MAX_LENGTH_RATIO,
    MAX_LOOP_RATE,
    MAX_MASS_RATIO,
    MAX_YIELD_STRAIN,
    MIN_CONTACT_TIME,
    MIN_JOINT_INERTIA,
)
from .files import (
    MAX_FILE_BYTES,
    MAX_YAML_NODES,
    config_dirs,
    installed_scenes,
    load_scene,
    read_scene_file,
    resolve_scene_path,
    scene_data,
    scene_from_text,
    self_contained_text,
)
from .parse import parse_scene
from .schema import (
    ARM,
    ARM_LINK,
    CONTROLLER,
    INTEGRATOR,
    JOINT,
    LINK,
    MATERIAL,
    MAX_SENSOR_LATENCY,
    REQUIRED,
    SCHEMA,
    SENSORS,
    SURFACE,
    TIP_RADIUS_RANGE,
    SceneChecker,
    choice_spec,
    number_spec,
)
from .types import (
    CONTACT_LAWS,
    ContactLaw,
    ControllerSpec,
    IntegratorSpec,
    JointSpec,
    Material,
    Mount,
    RateReading,
    Scene,
    SensorSpec,
    Surface,
    reduced_modulus,
    rod_centres,
    rod_inertias,
)

__all__ = [
    'ARM',
    'ARM_LINK',
    'CONTACT_LAWS',
    'ContactLaw',
    'CONTROLLER',
    'INTEGRATOR',
    'JOINT',
    'LINK',
    'MATERIAL',
    'MAX_COM_DISTANCE',
    'MAX_FILE_BYTES',
    'MAX_LENGTH_RATIO',
    'MAX_LOOP_RATE',
    'MAX_MASS_RATIO',
    'MAX_SENSOR_LATENCY',
    'MAX_YAML_NODES',
    'MAX_YIELD_STRAIN',
    'MIN_CONTACT_TIME',
    'MIN_JOINT_INERTIA',
    'REQUIRED',
    'SCHEMA',
    'SENSORS',
    'SURFACE',
    'TIP_RADIUS_RANGE',
    'ControllerSpec',
    'IntegratorSpec',
    'JointSpec',
    'Material',
    'Mount',
    'RateReading',
    'Scene',
    'SceneChecker',
    'SensorSpec',
    'Surface',
    'choice_spec',
    'config_dirs',
    'installed_scenes',
    'load_scene',
    'number_spec',
    'parse_scene',
    'read_scene_file',
    'reduced_modulus',
    'resolve_scene_path',
    'rod_centres',
    'rod_inertias',
    'scene_data',
    'scene_from_text',
    'self_contained_text',
]
