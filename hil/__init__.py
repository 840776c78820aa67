"""The world: drive firmware emulators, sensors, sky and camera renderers, virtual links.

Shares nothing with ``controller`` except ``firmware_protocol`` (never import controller
here: a sign error must not cancel out between the world and the controller).
"""
