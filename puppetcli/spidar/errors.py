"""The device model's error class."""

from __future__ import annotations

from solver.errors import PuppetError

__all__ = ["DeviceError"]


class DeviceError(PuppetError):
    """A device preset, a preset file or a device pose is invalid (one line, names the cause)."""
