"""Sun observations, estimates and the sources that produce them."""

from .types import SunEstimate, SunObservation, azel_to_enu, enu_to_azel

__all__ = ["SunEstimate", "SunObservation", "azel_to_enu", "enu_to_azel"]
