"""The simulator's side of the panel-mounted closed loop (``[closedloop]``, docs/fisheye.md).

:func:`make_controller` builds the plain :class:`~controller.loop.Controller`, or, with
``[closedloop] enabled``, the :class:`~controller.closedloop.panel.ClosedLoopController`
whose panel cameras are the world's (:class:`hil.panelcam.PanelCamera`): each renders, at
the simulated time, the sky seen along the panel's true normal (the drive's output angles
plus the row's ``[[hil.mount_offsets]]``) with the clouds' beam transmittance over the sun
(0 in ``[[hil.sun_gaps]]``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from controller.closedloop.panel import ClosedLoopController, axis_names
from controller.config import SingleAxisTracker
from controller.errors import ConfigError
from controller.loop import Controller
from controller.sun.camera import CallableFrameSource, FrameSource
from hil.camera import Site as CameraSite
from hil.panelcam import PanelCamera

from .renderers import cloud_layer
from .scenario import ScenarioConfig
from .world import World

#: What the summary's ``closedloop`` block means (written into summary.json).
CLOSEDLOOP_DEFINITIONS = {
    "closedloop": "panel-mounted closed loop: learned_offset_deg is the setpoint correction "
    "the loop learned per axis (deg; for a panel sitting d off its encoder it should be -d: "
    "mount_offset_deg is the world's d); setpoints counts the cycles by what set the "
    "target (camera: the fuzzy PID on a frame with the sun; learned: reference + learned "
    "offset without the camera, or with a frame the offset learner refused; settling: "
    "reference + learned offset + correction while the drive is more than 0.5 deg from its "
    "last target, the frame unused; hold: the paper's setpoint held; reference: the sun "
    "source's target); frames counts the panel camera's outcomes (refused: found, but "
    "refused by the learned offset; implausible: found, but measuring an offset beyond "
    "[closedloop] max_offset_deg)",
}


def panel_frames(
    config: ScenarioConfig, world: World, transmittance: Callable[[float], float]
) -> dict[str, FrameSource]:
    """The world's panel camera of every tracker in the closed loop, by tracker name."""
    cl = config.closedloop
    assert cl is not None
    names = set(cl.trackers) if cl.trackers else {tr.name for tr in config.trackers}
    site = CameraSite(config.site.latitude, config.site.longitude, config.site.altitude)
    cam_cfg = config.hil.panel_camera
    out: dict[str, FrameSource] = {}
    for tr in config.trackers:
        if tr.name not in names:
            continue
        row = tr if isinstance(tr, SingleAxisTracker) else None
        cam = PanelCamera(
            tr.type,
            site,
            axis_azimuth=row.axis_azimuth if row is not None else 180.0,
            axis_tilt=row.axis_tilt if row is not None else 0.0,
            scale=cam_cfg.scale,
            noise=cam_cfg.noise,
            clouds=cloud_layer(config) if cam_cfg.clouds else None,
        )

        def angles(name: str = tr.name) -> list[float]:
            return world.firmwares[name].panel_angles()

        out[tr.name] = CallableFrameSource(cam.source(angles, transmittance))
    return out


def make_controller(
    config: ScenarioConfig,
    world: World,
    transmittance: Callable[[float], float],
    *args: Any,
    **kwargs: Any,
) -> Controller:
    """The scenario's controller (``args``, ``kwargs``: the :class:`Controller`'s after
    its configuration)."""
    cl = config.closedloop
    if cl is None or not cl.enabled:
        return Controller(config, *args, **kwargs)
    if cl.frames != "hil":  # pragma: no cover - the schema allows only "hil" today
        raise ConfigError(f"[closedloop] frames = {cl.frames!r}: the simulator renders only 'hil'")
    frames = panel_frames(config, world, transmittance)
    return ClosedLoopController(config, *args, panel_frames=frames, **kwargs)


def closedloop_summary(controller: Controller, config: ScenarioConfig) -> dict:
    """The ``closedloop`` block of summary.json (empty without the closed loop)."""
    if not isinstance(controller, ClosedLoopController):
        return {}
    out = controller.closedloop_summary()
    for tr in config.trackers:
        if tr.name in out["rows"]:
            truth = config.hil.mount_offset(tr.name, tr.axes)
            out["rows"][tr.name]["mount_offset_deg"] = dict(zip(axis_names(tr), truth))
    return {"closedloop": out}
