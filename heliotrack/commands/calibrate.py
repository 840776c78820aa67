"""``heliotrack calibrate ...``: build the hotspot sensor's calibration bundle from images."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="calibrate the hotspot sensor (writes a bundle TOML)")
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])
    from controller.calibration import cli as calcli

    calcli.add_subcommands(p)
