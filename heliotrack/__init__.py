"""heliotrack: the application layer that puts the controller and the HIL world together.

``controller`` runs on the tracker's edge computer, ``hil`` is the emulated world and
``firmware_protocol`` is the only thing they share.  This package holds what joins them:
the command-line interface and the HIL scenario runner.
"""

__version__ = "0.1.0"
