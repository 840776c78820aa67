"""``heliotrack config docs|validate``: the configuration reference, and checking a file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("config", help="configuration reference and validation")
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])
    s = p.add_subparsers(dest="config_command", metavar="ACTION")
    d = s.add_parser("docs", help="write the configuration reference (docs/config.md)")
    d.add_argument(
        "--out", type=Path, default=None, help="file to write (default docs/config.md; - for stdout)"
    )
    d.set_defaults(func=_docs)
    v = s.add_parser("validate", help="validate a plant or scenario file (exit 2 on an error)")
    v.add_argument("file", type=Path)
    v.add_argument("--scenario", action="store_true", help="allow the simulator's [hil] table")
    v.set_defaults(func=_validate)


def _docs(args: argparse.Namespace) -> int:
    from controller.atomic import atomic_write
    from heliotrack.config_docs import DOCS_PATH, reference

    text = reference()
    if str(args.out) == "-":
        print(text, end="")
        return 0
    from controller.errors import InputError

    target = args.out or DOCS_PATH
    if target.is_dir() or not target.name:
        raise InputError(f"--out: {target} is a folder; give the file to write")
    try:
        path = atomic_write(target, text)
    except OSError as exc:
        raise InputError(f"--out: cannot write {target} ({exc.strerror or exc})") from None
    print(f"wrote {path}")
    return 0


def _validate(args: argparse.Namespace) -> int:
    from controller.calibration.bundle import load_bundle
    from controller.calibration.fisheye_bundle import load_fisheye_bundle
    from controller.config import load_config
    from controller.errors import ConfigError
    from heliotrack.scenario import load_scenario

    try:
        cfg = load_scenario(args.file) if args.scenario else load_config(args.file)
    except ConfigError as exc:
        if exc.key == "hil" and not args.scenario:
            raise ConfigError(
                exc.file,
                "hil",
                "a plant file, with no [hil] table (a [hil] table makes a scenario: validate it with --scenario)",
            ) from None
        raise
    from heliotrack.runtime import refuse_hil, require_hil

    if args.scenario:  # what simulate will say, said now
        require_hil(cfg)
    else:  # what run and check will say
        refuse_hil(cfg, "run")
    bundles = 0
    for name, load in (("hotspot", load_bundle), ("fisheye", load_fisheye_bundle)):
        cam = getattr(cfg, name, None)
        if cam is not None and getattr(cam, "calibration", None) is not None:
            bundle = load(cam.calibration)  # a bad bundle is the plant file's error too (raises with its key)
            bundles += 1
            if name == "fisheye":  # a bundle calibrated at another site: said now, as run will
                from heliotrack.sun_sources import plant_site_bundle

                plant_site_bundle(cfg, bundle)
    extra = f", {bundles} calibration bundle(s)" if bundles else ""
    from controller.drives.links import link_timing_warnings
    from controller.geometry.travel import travel_warnings

    for warning in travel_warnings(cfg) + link_timing_warnings(cfg):  # valid, but it will not track as meant
        print(f"heliotrack: warning: {args.file}: {warning}", file=sys.stderr)
    print(f"{args.file}: ok ({len(cfg.links)} link(s), {len(cfg.trackers)} tracker(s){extra})")
    return 0
