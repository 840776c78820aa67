"""The panel cameras of the panel-mounted closed loop (``[closedloop]``, docs/fisheye.md).

In the simulator, :func:`make_controller` builds the plain :class:`~controller.loop.Controller`,
or, with ``[closedloop] enabled``, the :class:`~controller.closedloop.panel.ClosedLoopController`
whose panel cameras are the world's (:class:`hil.panelcam.PanelCamera`): each renders, at
the simulated time, the sky seen along the panel's true normal (the drive's output angles
plus the row's ``[[hil.mount_offsets]]``) with the clouds' beam transmittance over the sun
(0 in ``[[hil.sun_gaps]]``).  On a plant (``heliotrack run``, ``check``),
:func:`open_panel_cameras` opens each tracker's real camera from ``[closedloop] frames``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from controller.clock import Clock
from controller.closedloop.panel import ClosedLoopController
from controller.closedloop.pose import axis_names
from controller.config import Config, SingleAxisTracker
from controller.errors import ConfigError
from controller.loop import Controller
from controller.sun.camera import CallableFrameSource, FrameSource
from hil.camera import Site as CameraSite
from hil.panelcam import PanelCamera
from hil.skycam.distractors import SpecularReflection

from .renderers import cloud_layer
from .scenario import ScenarioConfig
from .world import World

#: What the summary's ``closedloop`` block means (written into summary.json).
CLOSEDLOOP_DEFINITIONS = {
    "closedloop": "panel-mounted closed loop: learned_offset_deg is the setpoint correction "
    "the loop learned per axis (deg; for a panel sitting d off its encoder it should be -d: "
    "mount_offset_deg is the world's d; camera_mount_deg, when there is one, the world's "
    "rotation of the camera on its panel, a rotation vector in deg); setpoints counts the cycles by what set the "
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
    names = set(looped_trackers(config))
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
            distractors=tuple(
                SpecularReflection(r.azimuth_deg, r.elevation_deg, strength=r.strength)
                for r in cam_cfg.reflections
            ),
            mount_deg=config.hil.camera_mount(tr.name),
        )

        def angles(name: str = tr.name) -> list[float]:
            return world.firmwares[name].panel_angles()

        out[tr.name] = CallableFrameSource(cam.source(angles, transmittance))
    return out


def looped_trackers(config: Config) -> list[str]:
    """The names of the trackers in the closed loop (none when it is off), in plant order."""
    cl = config.closedloop
    if cl is None or not cl.enabled:
        return []
    return [tr.name for tr in config.trackers if not cl.trackers or tr.name in cl.trackers]


def open_panel_cameras(
    config: Config, clock: Clock | None = None, only: str | None = None
) -> dict[str, FrameSource]:
    """Each looped tracker's panel camera on a plant (or tracker ``only``'s), by tracker
    name (``[closedloop] frames`` with ``{tracker}`` filled in: a folder, ``device:N`` or a
    URL).

    Raises
    ------
    ConfigError
        ``frames = "hil"`` (the simulator's renderer), or a camera that cannot be opened
        (the ones opened before it are closed).
    """
    from .sun_sources import open_frame_source

    cl = config.closedloop
    out: dict[str, FrameSource] = {}
    try:
        for name in looped_trackers(config) if only is None else [only]:
            assert cl is not None
            out[name] = open_frame_source(cl.camera(name), clock, "closedloop.frames")
    except BaseException:
        for source in out.values():
            source.close()
        raise
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
    if cl.frames != "hil":  # a real camera would see the real sky, not the simulated panel's
        raise ConfigError(
            config.file,
            "closedloop.frames",
            '"hil" in the simulator (its panel cameras are rendered)',
            cl.frames,
        )
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
            camera = config.hil.camera_mount(tr.name)
            if any(camera):
                out["rows"][tr.name]["camera_mount_deg"] = list(camera)
    return {"closedloop": out}
