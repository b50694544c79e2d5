"""The serial driver (drivers/serial_link.py) against the firmware emulator on a pseudo-terminal."""

from __future__ import annotations

import pathlib
import statistics
import struct
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest
import serial

from tactile_bridge.drivers import DeviceError, DeviceSample, make_device
from tactile_bridge.drivers import serial_protocol as sp
from tactile_bridge.drivers.serial_link import SerialConfig, SerialDevice
from tactile_bridge.emulator import FirmwareEmulator
from tactile_bridge.profile import ProfileError, load_profile, parse_profile

PROFILES = pathlib.Path(__file__).resolve().parents[1] / "src" / "tactile_bridge" / "profiles"
K_HAND = 300.0  # the emulator's default hand stiffness [N/m] (ArmParams)


def f32(x: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", x))[0])


def profile_table(port: str, **serial: Any) -> dict[str, Any]:
    return {
        "driver": "serial", "channel": "stylus",
        "force": {"max_N": 3.0, "continuous_N": 1.0, "slew_N_per_s": 300.0},
        "serial": {"port": port, "reconnect_s": 0.05, "handshake_s": 0.5, **serial},
    }


def make(port: str, **serial: Any) -> SerialDevice:
    device = make_device(parse_profile(profile_table(port, **serial), "test.toml"))
    assert isinstance(device, SerialDevice)
    return device


def wait_for(condition: Callable[[], bool], timeout_s: float, what: str) -> float:
    """Polls `condition` every 0.5 ms; the seconds it took, or a failure naming `what`."""
    t0 = time.monotonic()
    while not condition():
        if time.monotonic() - t0 > timeout_s:
            pytest.fail(f"{what}: not within {timeout_s:g} s")
        time.sleep(0.0005)
    return time.monotonic() - t0


def tick(device: SerialDevice, sample: DeviceSample, force_N: tuple[float, float, float] | None,
         duration_s: float) -> int:
    """A 1 kHz bridge tick for `duration_s`: read, then write `force_N` (None: write nothing). Good reads."""
    good = 0
    end = time.monotonic() + duration_s
    while time.monotonic() < end:
        now = time.monotonic_ns()
        good += device.read(now, sample)
        if force_N is not None:
            device.write_force(now, force_N)
        time.sleep(0.001)
    return good


@pytest.fixture
def emulator(tmp_path: pathlib.Path) -> Iterator[FirmwareEmulator]:
    emu = FirmwareEmulator(tmp_path / "usb-tactile-arm-if00", name="hapkit-emu", max_force_N=4.0)
    emu.start()
    yield emu
    emu.stop()


@pytest.fixture
def device(emulator: FirmwareEmulator) -> Iterator[SerialDevice]:
    dev = make(emulator.link)
    dev.open()
    yield dev
    dev.close()


@pytest.fixture(autouse=True)
def no_leftover_threads() -> Iterator[None]:
    before = set(threading.enumerate())
    yield
    left = [t for t in threading.enumerate() if t not in before and t.is_alive()]
    assert not left, f"threads left running: {left}"


# -- configuration ---------------------------------------------------------------------------------------


def test_the_example_profile_loads() -> None:
    profile = load_profile(PROFILES / "serial_hapkit.toml")
    assert profile.driver == "serial"
    assert profile.driver_config == SerialConfig(port="/dev/ttyACM0", baud=1_000_000, reconnect_s=0.5,
                                                 stale_ms=20.0, handshake_s=1.0)


def test_parse_config_defaults() -> None:
    config = parse_profile(profile_table("/dev/ttyACM1") | {"serial": {"port": "/dev/ttyACM1"}}).driver_config
    assert config == SerialConfig(port="/dev/ttyACM1", baud=1_000_000, reconnect_s=0.5, stale_ms=20.0,
                                  handshake_s=1.0)


@pytest.mark.parametrize("serial, message", [
    ({}, r"serial\.port: missing"),
    ({"port": ""}, r"serial\.port: must be a non-empty string"),
    ({"port": "/dev/x", "baud": 115200.5}, r"serial\.baud: must be an integer"),
    ({"port": "/dev/x", "baud": 10}, r"serial\.baud: must be in"),
    ({"port": "/dev/x", "reconnect_s": 0}, r"serial\.reconnect_s: must be >= 0.01"),
    ({"port": "/dev/x", "stale_ms": 80}, r"serial\.stale_ms: must be <= 50"),
    ({"port": "/dev/x", "handshake_s": "1"}, r"serial\.handshake_s: must be a finite number"),
    ({"port": "/dev/x", "speed": 9600}, r"serial: unknown field\(s\) speed"),
])
def test_parse_config_refusals_name_the_field(serial: dict[str, Any], message: str) -> None:
    table = profile_table("unused")
    table["serial"] = serial
    with pytest.raises(ProfileError, match=message) as e:
        parse_profile(table, "arm.toml")
    assert str(e.value).startswith("arm.toml: serial")


# -- connecting ------------------------------------------------------------------------------------------


def test_handshake(emulator: FirmwareEmulator, device: SerialDevice) -> None:
    assert device.info == sp.Info(sp.PROTOCOL_VERSION, 3, 4.0, 50, "hapkit-emu")
    assert device.connected  # open() returns with a first STATE in hand
    assert emulator.hellos >= 1
    sample = DeviceSample()
    assert device.read(time.monotonic_ns(), sample)
    line = device.describe()
    assert emulator.link in line and "'hapkit-emu': connected" in line and "0 CRC errors" in line


def test_positions_are_the_models(emulator: FirmwareEmulator, device: SerialDevice) -> None:
    target = (0.012, -0.034, 0.056)
    emulator.set_hand_target(target)
    sample = DeviceSample()
    # The hand pulls the free arm to its target (critically damped: tens of milliseconds).
    wait_for(lambda: device.read(time.monotonic_ns(), sample)
             and max(abs(sample.position[i] - target[i]) for i in range(3)) < 1e-5, 1.0, "arm at the target")
    now = time.monotonic_ns()
    assert device.read(now, sample)
    # The reading is exactly what the firmware sent under that sequence number.
    sent = dict(emulator.sent_states)
    assert sent[sample.sequence & 0xFFFF] == tuple(sample.position)
    assert now - sample.time_ns <= 20e6 and sample.time_ns <= time.monotonic_ns()
    first = sample.sequence
    tick(device, sample, None, 0.02)
    assert sample.sequence > first


def test_forces_reach_the_firmware_and_move_the_arm(emulator: FirmwareEmulator, device: SerialDevice) -> None:
    emulator.set_hand_target((0.0, 0.0, 0.0))
    force = (0.6, -0.3, 0.15)
    sample = DeviceSample()
    good = tick(device, sample, force, 0.3)
    assert good > 30 and device.forces_sent > 30
    assert emulator.received_forces[-1] == tuple(f32(f) for f in force)
    # Static equilibrium against the hand's spring: x = F / k.
    for i in range(3):
        assert sample.position[i] == pytest.approx(force[i] / K_HAND, abs=2e-5)
    assert emulator.watchdog_trips == 0


@pytest.mark.parametrize("options, message", [
    ({"answer": "nothing"}, r"no answer to HELLO within 0.5 s \(nothing received\)"),
    ({"answer": "garbage"}, r"no valid frame within 0.5 s \(\d+ bytes received.*wrong baud rate \(1000000\)"),
    ({"protocol_version": 2}, r"speaks serial protocol version 2; this bridge speaks 1"),
    ({"max_force_N": 1.5}, r"renders at most 1.5 N but the profile's force.max_N is 3 N"),
    ({"watchdog_ms": 500}, r"force watchdog of 500 ms"),
])
def test_a_wrong_device_is_refused_naming_the_port(tmp_path: pathlib.Path, options: dict[str, Any],
                                                    message: str) -> None:
    with FirmwareEmulator(tmp_path / "arm", **options) as emu:
        dev = make(emu.link, handshake_s=0.5)
        with pytest.raises(DeviceError, match=message) as e:
            dev.open()
        assert str(e.value).startswith(f"{emu.link}: ")
        assert not dev.connected
        dev.close()  # harmless after a failed open
    assert "closed" in dev.describe()


def test_a_missing_port_is_refused(tmp_path: pathlib.Path) -> None:
    dev = make(str(tmp_path / "ttyACM9"))
    with pytest.raises(DeviceError, match=r"ttyACM9: cannot open: no such file"):
        dev.open()


def test_a_port_in_use_is_refused(emulator: FirmwareEmulator, device: SerialDevice) -> None:
    with pytest.raises(DeviceError, match=r"cannot open: in use by another program"):
        make(emulator.link).open()
    assert device.connected


# -- running ---------------------------------------------------------------------------------------------


def test_unplug_then_replug_reconnects_by_itself(emulator: FirmwareEmulator, device: SerialDevice) -> None:
    sample = DeviceSample()
    assert tick(device, sample, (0.1, 0.0, 0.0), 0.02) > 0
    before = sample.sequence
    emulator.unplug()
    # Not connected within stale_ms (the driver sees end-of-file at once; staleness is the backstop, and
    # test_read_turns_false_exactly_stale_ms_after_the_newest_state pins it to the nanosecond).
    wait_for(lambda: not device.read(time.monotonic_ns(), sample), 0.020 + 0.030, "read False after unplug")
    assert not device.connected
    # The tick keeps writing: no exception, no waiting.
    durations = []
    for _ in range(50):
        t0 = time.perf_counter()
        device.write_force(time.monotonic_ns(), (0.1, 0.0, 0.0))
        durations.append(time.perf_counter() - t0)
    assert statistics.median(durations) < 50e-6 and max(durations) < 0.1
    assert "unplugged, retrying every 0.05 s" in device.describe()
    # Unplugged for several retry intervals: it stays not connected, and the sample is left as it was.
    last = (sample.sequence, list(sample.position), sample.time_ns)
    assert tick(device, sample, (0.1, 0.0, 0.0), 0.15) == 0
    assert (sample.sequence, sample.position, sample.time_ns) == last
    assert device.reconnects == 0
    emulator.replug()
    # Bounded: a retry interval (0.05 s) plus a handshake (milliseconds here), with room for a busy machine.
    wait_for(lambda: device.read(time.monotonic_ns(), sample), 2.0, "reconnected after replug")
    assert device.reconnects == 1 and device.connected
    assert sample.sequence > before
    n = len(emulator.received_forces)
    tick(device, sample, (0.0, 0.2, 0.0), 0.03)
    assert len(emulator.received_forces) > n and emulator.received_forces[-1] == (0.0, f32(0.2), 0.0)


def test_a_different_device_on_replug_is_refused(emulator: FirmwareEmulator, device: SerialDevice) -> None:
    sample = DeviceSample()
    emulator.unplug()
    emulator.replug(name="someone else's arm")
    wait_for(lambda: "a different device answered" in device.last_error, 2.0, "the stranger refused")
    assert not device.read(time.monotonic_ns(), sample) and device.reconnects == 0
    emulator.unplug()
    emulator.replug(name="hapkit-emu")
    wait_for(lambda: device.read(time.monotonic_ns(), sample), 2.0, "reconnected to the right arm")
    assert device.reconnects == 1


def test_a_firmware_reset_reads_stale_then_resumes_after_hello(emulator: FirmwareEmulator,
                                                               device: SerialDevice) -> None:
    sample = DeviceSample()
    assert tick(device, sample, None, 0.01) > 0
    hellos = emulator.hellos
    emulator.reboot()  # quiet until the next HELLO; the port stays open
    wait_for(lambda: not device.read(time.monotonic_ns(), sample), 0.1, "stale after the reset")
    # The driver says HELLO again (every reconnect_s while quiet) and the stream comes back on the same port.
    wait_for(lambda: device.read(time.monotonic_ns(), sample), 2.0, "STATE again after HELLO")
    assert emulator.hellos > hellos
    assert device.reconnects == 0 and device.connected


def test_read_turns_false_exactly_stale_ms_after_the_newest_state(emulator: FirmwareEmulator) -> None:
    dev = make(emulator.link, stale_ms=20, reconnect_s=5.0)  # no keep-alive HELLO during this test
    dev.open()
    try:
        sample = DeviceSample()
        emulator.reboot()  # the stream stops, the port stays open
        wait_for(lambda: not dev.read(time.monotonic_ns(), sample), 0.5, "the stream stopped")
        newest = (sample.time_ns, sample.sequence, list(sample.position))
        probe = DeviceSample()
        assert dev.read(newest[0] + 20_000_000, probe)
        assert (probe.time_ns, probe.sequence, probe.position) == newest
        untouched = DeviceSample()
        untouched.sequence = -7
        assert not dev.read(newest[0] + 20_000_001, untouched)
        assert untouched.sequence == -7 and untouched.position == [0.0, 0.0, 0.0]
        assert not dev.connected and "open, no STATE for over 20 ms" in dev.describe()
    finally:
        dev.close()


def test_the_firmware_watchdog_zeroes_the_force(emulator: FirmwareEmulator, device: SerialDevice) -> None:
    sample = DeviceSample()
    tick(device, sample, (1.0, 0.0, 0.0), 0.03)
    assert emulator.applied_force_N == (1.0, 0.0, 0.0)
    # The host stops sending (hung, crashed, cable cut on its side); the firmware zeroes the force by itself.
    wait_for(lambda: emulator.applied_force_N == (0.0, 0.0, 0.0), 0.5, "the watchdog zeroing the force")
    assert emulator.watchdog_trips == 1
    assert 0.050 <= emulator.last_trip_s - emulator.last_force_s < 0.250
    # It says so, and the driver shows it.
    wait_for(lambda: device.last_fault is not None, 0.2, "the FAULT frame")
    assert device.last_fault is not None and device.last_fault.code == sp.FAULT_WATCHDOG
    assert device.faults == 1


def test_close_commands_zero_force(emulator: FirmwareEmulator) -> None:
    dev = make(emulator.link)
    dev.open()
    tick(dev, DeviceSample(), (0.5, 0.5, 0.0), 0.02)
    assert emulator.applied_force_N == (0.5, 0.5, 0.0)
    dev.close()
    wait_for(lambda: emulator.applied_force_N == (0.0, 0.0, 0.0), 0.5, "zero force after close")
    assert emulator.received_forces[-1] == (0.0, 0.0, 0.0)
    assert emulator.watchdog_trips == 0  # zeroed by the last FORCE, not by the watchdog
    assert not dev.connected and not dev.read(time.monotonic_ns(), DeviceSample())


def test_line_noise_and_a_cut_frame_are_skipped(emulator: FirmwareEmulator, device: SerialDevice) -> None:
    sample = DeviceSample()
    emulator.inject_garbage(sp.encode_state(999, 0, (9.0, 9.0, 9.0))[:13] + b"\x00\xa5\x5a\xff noise")
    wait_for(lambda: device.crc_errors >= 1, 0.5, "the cut frame seen")
    assert device.read(time.monotonic_ns(), sample)
    after = sample.sequence
    wait_for(lambda: device.read(time.monotonic_ns(), sample) and sample.sequence >= after + 10, 0.5,
             "STATE flowing after the noise")
    assert device.dropped_bytes >= 13 and sample.position != [9.0, 9.0, 9.0]
    assert device.reconnects == 0


def test_write_force_drops_rather_than_blocks_when_the_firmware_stops_reading(
        emulator: FirmwareEmulator, device: SerialDevice) -> None:
    emulator.set_stalled(True)
    durations: list[float] = []

    def hammer() -> None:
        for _ in range(3000):  # 60 kB: more than the OS buffer holds
            t0 = time.perf_counter()
            device.write_force(time.monotonic_ns(), (0.3, 0.0, 0.0))
            durations.append(time.perf_counter() - t0)

    writer = threading.Thread(target=hammer)
    writer.start()
    writer.join(timeout=5.0)
    assert not writer.is_alive(), "write_force blocked"
    assert len(durations) == 3000 and device.forces_dropped > 0
    assert statistics.median(durations) < 1e-3  # a few microseconds when the machine is not busy
    # The firmware reads again: it finds its way through the cut frames and takes the new force.
    emulator.set_stalled(False)
    tick(device, DeviceSample(), (0.0, 0.0, -0.4), 0.03)
    wait_for(lambda: emulator.received_forces[-1] == (0.0, 0.0, f32(-0.4)), 2.0, "a force after the stall")


def test_non_finite_forces_go_out_as_zero(emulator: FirmwareEmulator, device: SerialDevice) -> None:
    tick(device, DeviceSample(), (1.0, float("nan"), 1.0), 0.01)
    wait_for(lambda: len(emulator.received_forces) > 0, 0.1, "a FORCE")
    assert set(emulator.received_forces) == {(0.0, 0.0, 0.0)}  # as sent, before the firmware's own rule


def test_the_firmware_clamps_to_its_maximum(tmp_path: pathlib.Path) -> None:
    with FirmwareEmulator(tmp_path / "arm", max_force_N=4.0, axes=2) as emu:
        dev = make(emu.link)
        dev.open()
        try:
            tick(dev, DeviceSample(), (6.0, 8.0, 5.0), 0.01)  # |(6, 8)| = 10 N on a 2-axis, 4 N device
            wait_for(lambda: emu.applied_force_N != (0.0, 0.0, 0.0), 0.1, "a force applied")
            assert emu.applied_force_N == pytest.approx((2.4, 3.2, 0.0), abs=1e-6)
            wait_for(lambda: dev.last_fault is not None, 0.1, "the FAULT frame")
            assert dev.last_fault is not None and dev.last_fault.code == sp.FAULT_FORCE_LIMIT
            assert dev.faults == 1  # once for the episode, not once per FORCE
        finally:
            dev.close()


def test_the_emulated_firmware_takes_a_non_finite_force_as_zero(emulator: FirmwareEmulator) -> None:
    port = serial.Serial(emulator.link, 1_000_000, timeout=0)
    try:
        port.write(sp.encode_hello(0) + sp.encode_force(1, 1.0, 0.0, 0.0))
        wait_for(lambda: emulator.applied_force_N == (1.0, 0.0, 0.0), 0.1, "the first force")
        port.write(sp.encode_force(2, 1.0, float("nan"), 0.0))
        wait_for(lambda: len(emulator.received_forces) == 2, 0.1, "the second force")
        assert emulator.applied_force_N == (0.0, 0.0, 0.0)
    finally:
        port.close()
