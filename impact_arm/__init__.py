"""impact_arm: a planar n-link arm striking a hard surface, simulated like real hardware.

The Python API (docs/api.md)::

    import impact_arm as ia

    scene = ia.load_scene('paper')
    result = ia.simulate(scene)
    print(result.impacts[0].F_max)

Its names (``__all__``) come from ``impact_arm.api`` and are imported on first use, so
``import impact_arm`` costs nothing beyond this file. Underneath, three ROS-free packages hold
the behaviour: ``physics`` (scene, model, contact, control, integrator, simulate, metrics),
``driver`` (the simulated arm as its driver sees it) and ``calibration`` (impacts identified
and fitted, studies); ``io`` reads and writes messages and files, ``impact_arm.nodes`` adapts
the core to ROS 2 and ``impact_arm.tools`` is the ``impact-arm`` command.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

__version__ = '0.1.0'

# the API's names (impact_arm.api.SOURCES, spelled out: reading them must not import it)
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

if TYPE_CHECKING:
    from .api import (
        FitError,
        FitOptions,
        FitResult,
        IdentifyError,
        Impact,
        ImpactArmError,
        JointRecording,
        Param,
        ParameterEstimate,
        RecordingInputError,
        RunResult,
        Sample,
        Scene,
        SceneError,
        SimulationError,
        StopReason,
        Study,
        StudyRun,
        Verdict,
        compare,
        fit,
        load_scene,
        read_recording,
        simulate,
        write_fitted_scene,
    )


def __getattr__(name: str) -> Any:
    if name not in __all__:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    from . import api

    return getattr(api, name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
