"""The Python API of impact_arm: what ``import impact_arm as ia`` offers (docs/api.md).

Scenes in (a name, a file, YAML data or a ``Scene``), typed results out: ``load_scene``,
``simulate`` (-> ``RunResult`` of ``Impact`` records), ``read_recording`` (with the arm's scene,
by default the one the recording stores), ``fit`` (``Param`` bounds -> ``FitResult``),
``compare`` and ``Study``. It sits on the ROS-free core (physics, calibration, io) and imports
no ROS; the command line (``impact_arm.tools``) is built on it, never the reverse.

Each name is imported when first used (``__getattr__``): ``import impact_arm`` stays fast, and
``ia.load_scene`` does not load the fit's optimiser.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# the module each public name comes from (relative to this package)
SOURCES = {
    'FitError': '..calibration.fit.parameters',
    'FitOptions': '..calibration.fit.problem',
    'FitResult': '..calibration.fit.report',
    'IdentifyError': '..calibration.identify',
    'Impact': '..physics.impact',
    'ImpactArmError': '..physics.errors',
    'JointRecording': '..calibration.identify',
    'Param': '.fitting',
    'ParameterEstimate': '..calibration.fit.report',
    'RecordingInputError': '..io.recording',
    'RunResult': '.runs',
    'Sample': '..physics.simulate',
    'Scene': '..physics.scene.types',
    'SceneError': '..physics.errors',
    'SimulationError': '..physics.errors',
    'StopReason': '..physics.simulate',
    'Study': '..calibration.study',
    'StudyRun': '..calibration.study',
    'Verdict': '..calibration.fit.verdict',
    'compare': '.comparing',
    'fit': '.fitting',
    'load_scene': '.scenes',
    'read_recording': '.recordings',
    'simulate': '.runs',
    'write_fitted_scene': '..calibration.fit.fitted_scene',
}

__all__ = [
    'FitError',
    'FitOptions',
    'FitResult',
    'IdentifyError',
    'Impact',
    'ImpactArmError',
    'JointRecording',
    'Param',
    'ParameterEstimate',
    'RecordingInputError',
    'RunResult',
    'Sample',
    'Scene',
    'SceneError',
    'SimulationError',
    'StopReason',
    'Study',
    'StudyRun',
    'Verdict',
    'compare',
    'fit',
    'load_scene',
    'read_recording',
    'simulate',
    'write_fitted_scene',
]

if TYPE_CHECKING:  # what the names are, for type checkers and editors
    from ..calibration.fit.fitted_scene import write_fitted_scene
    from ..calibration.fit.parameters import FitError
    from ..calibration.fit.problem import FitOptions
    from ..calibration.fit.report import FitResult, ParameterEstimate
    from ..calibration.fit.verdict import Verdict
    from ..calibration.identify import IdentifyError, JointRecording
    from ..calibration.study import Study, StudyRun
    from ..io.recording import RecordingInputError
    from ..physics.errors import ImpactArmError, SceneError, SimulationError
    from ..physics.impact import Impact
    from ..physics.scene.types import Scene
    from ..physics.simulate import Sample, StopReason
    from .comparing import compare
    from .fitting import Param, fit
    from .recordings import read_recording
    from .runs import RunResult, simulate
    from .scenes import load_scene


def __getattr__(name: str) -> Any:
    source = SOURCES.get(name)
    if source is None:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(source, __name__), name)
    globals()[name] = value  # imported once
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
