"""The one list of drivers. A driver is registered here once, and only here.

Each entry gives the driver's name, which is the value of `driver = "..."` in a profile and also the name
of the profile table that holds the driver's settings (`[NAME]`). It also gives the module under
tactile_bridge.drivers that implements the driver, and a line that describes it. Other code derives
everything it needs from this list:
  profile.py           the values `driver` may take, and the driver tables a profile may have
  drivers/__init__.py  `make_device`, and the driver list in its docstring
  cli.py               the driver list in `--help`
A driver's module provides `parse_config(table, where, fields)` (its profile table, checked through
profile.Fields) and `make_device(profile, **options)` (its `Device`, not yet opened).

This module imports no driver module and nothing of the bridge's own. A driver's module is imported by name
when a profile first uses that driver, so the only dependency between the two modules runs from the driver to
profile.py.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType


@dataclass(frozen=True)
class Driver:
    name: str      # `driver = "NAME"` in a profile; its settings are the profile's [NAME] table
    module: str    # its module in tactile_bridge.drivers: parse_config(table, where, fields), make_device(...)
    summary: str   # one line, for --help and the docstrings

    @property
    def section(self) -> str:
        """The profile table that holds this driver's settings: the table named after the driver."""
        return self.name

    @property
    def module_name(self) -> str:
        return f"{__package__}.{self.module}"

    def load(self) -> ModuleType:
        """The driver's module, imported the first time it is asked for."""
        return importlib.import_module(self.module_name)


# The order is the order of the error messages and listings: the default driver first.
REGISTRY: tuple[Driver, ...] = (
    Driver("sim", "sim_arm", "a mass-damper arm held by a scripted, yielding hand (default)"),
    Driver("serial", "serial_link", "the framed binary protocol of docs/serial-protocol.md (pyserial)"),
    Driver("hid", "hid_device", "report layouts from the profile (hidapi)"),
)


def names() -> tuple[str, ...]:
    """The values a profile's `driver` may take, in registry order."""
    return tuple(d.name for d in REGISTRY)


def sections() -> tuple[str, ...]:
    """The driver tables a profile may have, in registry order."""
    return tuple(d.section for d in REGISTRY)


def get(name: str) -> Driver:
    """The driver registered as `name`; KeyError for a name that is not registered."""
    for d in REGISTRY:
        if d.name == name:
            return d
    raise KeyError(name)


def listing(indent: str = "  ") -> str:
    """One line per driver (name, module, summary), for docstrings and --help."""
    width = max(len(d.name) for d in REGISTRY)
    mod = max(len(d.module_name) for d in REGISTRY)
    return "\n".join(f"{indent}{d.name:<{width}}  {d.module_name:<{mod}}  {d.summary}" for d in REGISTRY)
