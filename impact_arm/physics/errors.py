"""Exceptions shared by the core. Each carries a message meant for the user, not a traceback."""


class ImpactArmError(Exception):
    """Base class: anything the command line reports as a one-line error."""


class SceneError(ImpactArmError):
    """A scene file is missing, malformed, or has a value outside its allowed range."""


class SimulationError(ImpactArmError):
    """The integration cannot continue (non-finite state, step size underflow, model limit)."""

    def __init__(self, message, t=None, state=None):
        super().__init__(message)
        self.t = t
        self.state = state


class RunBudgetError(SimulationError):
    """A run took far more steps per simulated second than any meaningful scene needs."""


class ContactStateError(ImpactArmError):
    """No joint rates give a reported contact's tip velocity and link energies, so the
    impact cannot be integrated again from it (physics/replay.py, ``contact_rates``)."""


class UnstableControlWarning(UserWarning):
    """A sampled control law unstable at its rate that the scene allows
    (``controller.allow_unstable``): its commands will chatter (physics/stability.py)."""
