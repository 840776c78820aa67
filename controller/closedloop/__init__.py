"""Panel-mounted closed loop (paper 003's use of the sky camera), as pure per-axis logic.

The camera rides on the panel; its sun offset drives each axis through the paper's fuzzy
PID (:mod:`.fuzzy`), and each row's mounting or encoder offset is learned and kept through
cloud gaps (:mod:`.learner`, :mod:`.axis`).  :mod:`.geometry` turns the camera's sun
direction into per-axis errors.  :mod:`.panel` wires them into the control loop
(``[closedloop]``, :mod:`.settings`); it is imported from there, not here (it needs the
loop).
"""

from .axis import MODES, AxisCommand, ClosedLoopAxis
from .fuzzy import FuzzyPID, FuzzyPIDGains
from .geometry import dual_axis_enu_from_camera, dual_axis_errors, single_axis_error
from .learner import MisalignmentStore, OffsetLearner

__all__ = [
    "MODES",
    "AxisCommand",
    "ClosedLoopAxis",
    "FuzzyPID",
    "FuzzyPIDGains",
    "MisalignmentStore",
    "OffsetLearner",
    "dual_axis_enu_from_camera",
    "dual_axis_errors",
    "single_axis_error",
]
