"""Device profiles: one TOML file per device (device-bridge/profiles/, README "Profiles").

A profile says which driver talks to the device and how, which server channel it drives, how the device's
workspace maps into the scene, and the force limits the safety layer holds it to. `load_profile(path)`
reads and checks a file; every refusal is a ProfileError that names the file and the field.

Frames: the driver reports the device's position in its own frame [m] and takes force in that frame [N].
The workspace maps device to scene: scene_i = offset_i + scale * sign_i * device[axis_i], for the axis map
`axes = ["x", "-z", "y"]` (scene x is device x, scene y is minus device z, scene z is device y). Forces go
the other way with the inverse map, times `force.gain`.
"""

from __future__ import annotations

import math
import pathlib
import tomllib
from dataclasses import dataclass, field
from typing import Any

# The drivers' names and tables come from their registry, which imports no driver module: a driver's module is
# imported by name when a profile uses it, so driver modules may import this one at module level.
from .drivers import registry

AXES = ("x", "y", "z")


class ProfileError(ValueError):
    """A profile this bridge refuses; the message names the file and the field."""


class Fields:
    """Reads one TOML table, naming `where` (file and table path) in every refusal."""

    def __init__(self, table: Any, where: str, known: tuple[str, ...]) -> None:
        if not isinstance(table, dict):
            raise ProfileError(f"{where}: must be a table")
        unknown = sorted(set(table) - set(known))
        if unknown:
            raise ProfileError(f"{where}: unknown field(s) {', '.join(unknown)} (known: {', '.join(known)})")
        self.table = table
        self.where = where

    def name(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where and not self.where.endswith(":") else f"{self.where} {key}"

    def has(self, key: str) -> bool:
        return key in self.table

    def number(self, key: str, default: float | None = None, *, low: float | None = None,
               high: float | None = None, low_open: bool = False) -> float:
        if key not in self.table:
            if default is None:
                raise ProfileError(f"{self.name(key)}: missing (a number)")
            return default
        v = self.table[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ProfileError(f"{self.name(key)}: must be a finite number (got {v!r})")
        if low is not None and (v <= low if low_open else v < low):
            raise ProfileError(f"{self.name(key)}: must be {'>' if low_open else '>='} {low:g} (got {v!r})")
        if high is not None and v > high:
            raise ProfileError(f"{self.name(key)}: must be <= {high:g} (got {v!r})")
        return float(v)

    def integer(self, key: str, default: int | None = None, *, low: int | None = None,
                high: int | None = None) -> int:
        if key not in self.table:
            if default is None:
                raise ProfileError(f"{self.name(key)}: missing (an integer)")
            return default
        v = self.table[key]
        if isinstance(v, bool) or not isinstance(v, int):
            raise ProfileError(f"{self.name(key)}: must be an integer (got {v!r})")
        if (low is not None and v < low) or (high is not None and v > high):
            raise ProfileError(f"{self.name(key)}: must be in [{low}, {high}] (got {v})")
        return v

    def string(self, key: str, default: str | None = None, *, choices: tuple[str, ...] | None = None) -> str:
        if key not in self.table:
            if default is None:
                raise ProfileError(f"{self.name(key)}: missing (a string)")
            return default
        v = self.table[key]
        if not isinstance(v, str) or not v:
            raise ProfileError(f"{self.name(key)}: must be a non-empty string (got {v!r})")
        if choices is not None and v not in choices:
            raise ProfileError(f"{self.name(key)}: must be one of {', '.join(choices)} (got {v!r})")
        return v

    def vector(self, key: str, default: tuple[float, ...] | None, n: int) -> tuple[float, ...]:
        if key not in self.table:
            if default is None:
                raise ProfileError(f"{self.name(key)}: missing ({n} numbers)")
            return default
        v = self.table[key]
        if (not isinstance(v, list) or len(v) != n
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) for x in v)):
            raise ProfileError(f"{self.name(key)}: must be {n} finite numbers (got {v!r})")
        return tuple(float(x) for x in v)

    def table_of(self, key: str) -> dict[str, Any] | None:
        v = self.table.get(key)
        if v is not None and not isinstance(v, dict):
            raise ProfileError(f"{self.name(key)}: must be a table")
        return v


@dataclass(frozen=True)
class Workspace:
    """Device frame -> scene frame: scene_i = offset_i + scale * sign_i * device[index_i]."""

    scale: float = 1.0                                  # scene metres per device metre
    offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # scene position of the device origin [m]
    axes: tuple[str, str, str] = ("x", "y", "z")        # device axis (with sign) for scene x, y, z
    index: tuple[int, int, int] = field(init=False, default=(0, 1, 2))
    sign: tuple[float, float, float] = field(init=False, default=(1.0, 1.0, 1.0))

    def __post_init__(self) -> None:
        index, sign = [], []
        for a in self.axes:
            s = -1.0 if a.startswith("-") else 1.0
            index.append(AXES.index(a.lstrip("+-")))
            sign.append(s)
        object.__setattr__(self, "index", tuple(index))
        object.__setattr__(self, "sign", tuple(sign))

    def to_scene(self, device_m: Any, out: list[float]) -> None:
        """Device position [m] (3) -> scene position [m], written into `out` (3)."""
        for i in range(3):
            out[i] = self.offset_m[i] + self.scale * self.sign[i] * device_m[self.index[i]]

    def to_device(self, scene_m: Any, out: list[float]) -> None:
        """Scene position [m] (3) -> device position [m], written into `out` (3)."""
        for i in range(3):
            out[self.index[i]] = self.sign[i] * (scene_m[i] - self.offset_m[i]) / self.scale

    def vector_to_device(self, scene: Any, out: list[float]) -> None:
        """A scene-frame vector (force) -> the device frame, without scale: out (3)."""
        for i in range(3):
            out[self.index[i]] = self.sign[i] * scene[i]

    def orientation_to_scene(self, q: Any, out: list[float]) -> None:
        """A device-frame orientation (w, x, y, z) -> the scene frame: R Q R^T for the axis map R.

        R may be a reflection (an axis map of odd sign or order); R Q R^T is a rotation all the same.
        """
        w, x, y, z = q[0], q[1], q[2], q[3]
        qm = ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
              (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
              (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))
        # (R Q R^T)_ij = sign_i sign_j Q[index_i][index_j]
        m = [[self.sign[i] * self.sign[j] * qm[self.index[i]][self.index[j]] for j in range(3)] for i in range(3)]
        tr = m[0][0] + m[1][1] + m[2][2]
        if tr > 0:
            s = 2.0 * (tr + 1.0) ** 0.5
            out[0], out[1], out[2], out[3] = 0.25 * s, (m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s  # noqa: E501 (the four cases read as one table)
        elif m[0][0] > m[1][1] and m[0][0] > m[2][2]:
            s = 2.0 * (1.0 + m[0][0] - m[1][1] - m[2][2]) ** 0.5
            out[0], out[1], out[2], out[3] = (m[2][1] - m[1][2]) / s, 0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s  # noqa: E501 (the four cases read as one table)
        elif m[1][1] > m[2][2]:
            s = 2.0 * (1.0 + m[1][1] - m[0][0] - m[2][2]) ** 0.5
            out[0], out[1], out[2], out[3] = (m[0][2] - m[2][0]) / s, (m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s  # noqa: E501 (the four cases read as one table)
        else:
            s = 2.0 * (1.0 + m[2][2] - m[0][0] - m[1][1]) ** 0.5
            out[0], out[1], out[2], out[3] = (m[1][0] - m[0][1]) / s, (m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s  # noqa: E501 (the four cases read as one table)

    def vector_to_scene(self, device: Any, out: list[float]) -> None:
        """A device-frame vector -> the scene frame, without scale: out (3)."""
        for i in range(3):
            out[i] = self.sign[i] * device[self.index[i]]


@dataclass(frozen=True)
class ForceLimits:
    """What the safety layer holds the force to (tactile_bridge.safety)."""

    max_N: float                 # never exceeded, any axis combined (magnitude)
    continuous_N: float          # the mean magnitude over any 10 s window stays within it
    slew_N_per_s: float          # the force vector changes no faster than this
    gain: float = 1.0            # device force per scene force
    engage_below_N: float = 0.0  # start-up: the command must stay under this...
    engage_ticks: int = 20       # ...for this many ticks before forces engage
    ramp_in_s: float = 0.25      # then the output ramps from 0 to the full command over this time
    # The stiffest contact the device renders stably (its Z-width), at the device: the extrapolate mode's
    # dF/dx, times gain and scale, is held within it [N/m]
    max_stiffness_N_per_m: float = 2000.0
    max_torque_Nm: float = 0.0   # the largest torque it renders [N m]; 0: it renders none (a 3-DoF arm)


@dataclass(frozen=True)
class Profile:
    path: str
    name: str
    driver: str                  # a registered driver's name (drivers/registry.py)
    channel: str                 # the server's device channel this device drives
    rate_hz: float               # tick rate of the bridge loop
    workspace: Workspace
    force: ForceLimits
    driver_config: Any           # the driver's own section, parsed by the driver module

    @property
    def period_ns(self) -> int:
        return round(1e9 / self.rate_hz)

    def scene_limits(self) -> tuple[float, float, float]:
        """What the device renders in scene terms, for the server's coupling (Hello.device_limits): the largest
        force [N] and torque [N m] and the stiffest spring [N/m]. A scene newton is `gain` device newtons and a
        scene metre 1/scale device metres (at gain 0, open loop, as at gain 1: what it would render)."""
        f, ws = self.force, self.workspace
        gain = f.gain if f.gain > 0 else 1.0
        return f.max_N / gain, f.max_torque_Nm / gain * ws.scale, f.max_stiffness_N_per_m / (gain * ws.scale)


# The time within which the safety layer must bring any force to zero (docs/design.md, issue 5: states that stop
# arriving reach zero within 50 ms of the last one, after at most 10 ms of hold), so the slew limit must
# allow max_N to fall to zero in 40 ms.
RAMP_DOWN_S = 0.040


def parse_workspace(f: Fields) -> Workspace:
    scale = f.number("scale", 1.0, low=0.0, low_open=True)
    offset = f.vector("offset_m", (0.0, 0.0, 0.0), 3)
    axes_v = f.table.get("axes", ["x", "y", "z"])
    if not isinstance(axes_v, list) or len(axes_v) != 3 or not all(isinstance(a, str) for a in axes_v):
        raise ProfileError(f"{f.name('axes')}: must be three of \"x\", \"y\", \"z\", each with an optional "
                           f"sign (got {axes_v!r})")
    base = [a.lstrip("+-") for a in axes_v]
    if sorted(base) != ["x", "y", "z"] or any(len(a) - len(a.lstrip("+-")) > 1 for a in axes_v):
        raise ProfileError(f"{f.name('axes')}: must name each of x, y, z once, each with an optional sign "
                           f"(got {axes_v!r})")
    return Workspace(scale=scale, offset_m=offset, axes=tuple(axes_v))  # type: ignore[arg-type]


def parse_force(f: Fields) -> ForceLimits:
    max_n = f.number("max_N", low=0.0, low_open=True)
    cont = f.number("continuous_N", low=0.0, low_open=True, high=max_n)
    slew = f.number("slew_N_per_s", low=0.0, low_open=True)
    if slew * RAMP_DOWN_S < max_n:
        raise ProfileError(f"{f.name('slew_N_per_s')}: must let max_N ({max_n:g} N) fall to zero within "
                           f"{RAMP_DOWN_S * 1e3:g} ms, so at least {max_n / RAMP_DOWN_S:g} N/s (got {slew:g})")
    return ForceLimits(
        max_N=max_n, continuous_N=cont, slew_N_per_s=slew,
        gain=f.number("gain", 1.0, low=0.0),
        engage_below_N=f.number("engage_below_N", 0.05 * max_n, low=0.0, high=max_n),
        engage_ticks=f.integer("engage_ticks", 20, low=1, high=100000),
        ramp_in_s=f.number("ramp_in_s", 0.25, low=0.0, high=10.0),
        max_stiffness_N_per_m=f.number("max_stiffness_N_per_m", 2000.0, low=0.0, low_open=True),
        max_torque_Nm=f.number("max_torque_Nm", 0.0, low=0.0),
    )


def parse_profile(table: dict[str, Any], path: str = "<profile>") -> Profile:
    """A profile from a parsed TOML table; ProfileError names `path` and the field at fault."""
    sections = registry.sections()  # each driver's own table, checked by the driver's module
    top = Fields(table, f"{path}:", ("name", "driver", "channel", "rate_hz", "workspace", "force", *sections))
    driver = top.string("driver", choices=registry.names())
    ws = Fields(top.table_of("workspace") or {}, f"{path}: workspace",
                ("scale", "offset_m", "axes"))
    if "force" not in table:
        raise ProfileError(f"{path}: force: missing (a table with max_N, continuous_N, slew_N_per_s)")
    fo = Fields(top.table_of("force"), f"{path}: force",
                ("max_N", "continuous_N", "slew_N_per_s", "gain", "engage_below_N", "engage_ticks", "ramp_in_s",
                 "max_stiffness_N_per_m", "max_torque_Nm"))
    spec = registry.get(driver)
    for other in sections:
        if other != spec.section and other in table:
            raise ProfileError(f"{path}: [{other}] given but driver is {driver!r}")
    return Profile(
        path=path,
        name=top.string("name", pathlib.Path(path).stem),
        driver=driver,
        channel=top.string("channel"),
        rate_hz=top.number("rate_hz", 1000.0, low=100.0, high=20000.0),
        workspace=parse_workspace(ws),
        force=parse_force(fo),
        driver_config=spec.load().parse_config(table.get(spec.section, {}), f"{path}: {spec.section}", Fields),
    )


def load_profile(path: str | pathlib.Path) -> Profile:
    """Reads and checks a profile file (TOML)."""
    p = pathlib.Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise ProfileError(f"{p}: cannot read: {e.strerror or e}") from None
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ProfileError(f"{p}: not valid TOML: {e}") from None
    return parse_profile(table, str(p))
