"""Device drivers: the boundary between the bridge's tick and a haptic arm.

Every driver is a `Device`. The tick calls `read` and `write_force` once per tick; neither may block (a
driver that needs blocking I/O does it in a thread of its own and hands over the latest values). A device
that unplugs reads as not connected, and the tick falls back to zero force; a driver that can reconnect
does so by itself and reads as connected again.

A driver that speaks a byte protocol keeps its codec in a module of its own, without I/O (serial_protocol,
hid_report), so that tests feed it bytes and an emulator plays the device with it.

The drivers are registered in drivers/registry.py, one entry each, and nowhere else. The list that ends
this docstring is generated from that registry when the package is imported.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from . import registry

if TYPE_CHECKING:
    from ..profile import Profile

__doc__ = f"{__doc__ or ''}\nDrivers:\n{registry.listing()}\n"


class DeviceError(RuntimeError):
    """A device that cannot be opened or used; the message names the device and what is wrong."""


class DeviceSample:
    """The latest reading of a device, filled in place by `Device.read` (no allocation per tick)."""

    __slots__ = ("position", "orientation", "buttons", "time_ns", "sequence")

    def __init__(self) -> None:
        self.position = [0.0, 0.0, 0.0]         # device frame [m] (3)
        self.orientation = [1.0, 0.0, 0.0, 0.0]  # device frame, unit quaternion w, x, y, z (4)
        self.buttons = 0                        # bit mask
        self.time_ns = 0                        # bridge monotonic clock when the device measured it
        self.sequence = 0                       # the device's own counter, increasing (0 if it has none)


class Device(abc.ABC):
    """A haptic device as the tick sees it."""

    def __init__(self, profile: Profile) -> None:
        self.profile = profile

    @abc.abstractmethod
    def open(self) -> None:
        """Connects; DeviceError when the device is not there or not usable (naming it and why)."""

    @abc.abstractmethod
    def read(self, now_ns: int, sample: DeviceSample) -> bool:
        """Writes the newest reading into `sample`; False (sample untouched) while not connected."""

    @abc.abstractmethod
    def write_force(self, now_ns: int, force_N: Sequence[float]) -> None:
        """Commands a force [N] (3, device frame); ignored while not connected. Never blocks."""

    @abc.abstractmethod
    def close(self) -> None:
        """Commands zero force where it still can, then releases the device."""

    @property
    @abc.abstractmethod
    def connected(self) -> bool:
        """Whether readings are arriving now."""

    def describe(self) -> str:
        """One line for the status line and logs: what the device is and its link state."""
        return f"{self.profile.driver} {'connected' if self.connected else 'not connected'}"


def make_device(profile: Profile, **options: Any) -> Device:
    """The driver a profile names, not yet opened."""
    device: Device = registry.get(profile.driver).load().make_device(profile, **options)
    return device
