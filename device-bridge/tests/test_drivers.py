"""The driver registry (drivers/registry.py) is the one list of drivers: every registered driver is usable from
each place that names drivers (profile validation, the driver tables, make_device, --help, the package's
docstring), and a driver registered there alone is usable everywhere. Importing profile.py imports no driver
module, and the package's imports (function-level ones too) form no cycle: the dependency runs one way, from
the drivers to the profile."""

from __future__ import annotations

import ast
import copy
import graphlib
import pathlib
import subprocess
import sys
from typing import Any

import pytest

from tactile_bridge import cli, drivers
from tactile_bridge.drivers import registry
from tactile_bridge.drivers.sim_arm import SimArm
from tactile_bridge.profile import ProfileError, load_profile, parse_profile

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "tactile_bridge"
SHIPPED = sorted((PACKAGE / "profiles").glob("*.toml"))
IDS = [d.name for d in registry.REGISTRY]

BASE: dict[str, Any] = {
    "name": "test",
    "channel": "stylus",
    "force": {"max_N": 3.0, "continuous_N": 1.0, "slew_N_per_s": 300.0},
}


def with_driver(name: str, **tables: Any) -> dict[str, Any]:
    t = copy.deepcopy(BASE)
    t["driver"] = name
    t.update(tables)
    return t


def help_text(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setenv("COLUMNS", "10000")   # one line per paragraph: nothing wrapped mid-name
    with pytest.raises(SystemExit) as e:
        cli.parse_args(["--help"])
    assert e.value.code == 0
    return capsys.readouterr().out


def test_the_registry_lists_each_driver_once_in_the_documented_order() -> None:
    assert registry.names() == ("sim", "serial", "hid")          # the order of error messages and listings
    assert len(set(registry.names())) == len(registry.REGISTRY)
    assert len(set(registry.sections())) == len(registry.REGISTRY)
    assert len({d.module for d in registry.REGISTRY}) == len(registry.REGISTRY)
    for d in registry.REGISTRY:
        assert registry.get(d.name) is d
    with pytest.raises(KeyError):
        registry.get("usb")


@pytest.mark.parametrize("driver", registry.REGISTRY, ids=IDS)
def test_every_registered_driver_module_imports_and_provides_its_factories(driver: registry.Driver) -> None:
    assert (PACKAGE / "drivers" / f"{driver.module}.py").is_file()
    module = driver.load()
    assert module.__name__ == f"tactile_bridge.drivers.{driver.module}"
    assert callable(module.parse_config)
    assert callable(module.make_device)


@pytest.mark.parametrize("driver", registry.REGISTRY, ids=IDS)
def test_every_registered_driver_is_accepted_by_profile_validation(driver: registry.Driver) -> None:
    # Its name is a value `driver` may take: any refusal is about its own table, not the name.
    try:
        p = parse_profile(with_driver(driver.name), "x.toml")
    except ProfileError as refused:
        assert str(refused).startswith(f"x.toml: {driver.section}"), refused
        assert "must be one of" not in str(refused)
    else:
        assert p.driver == driver.name
    # Its table is known to the profile: given under another driver it is refused as that, not as unknown.
    other = next(d for d in registry.REGISTRY if d is not driver)
    with pytest.raises(ProfileError) as e:
        parse_profile(with_driver(other.name, **{driver.section: {}}), "x.toml")
    assert str(e.value) == f"x.toml: [{driver.section}] given but driver is {other.name!r}"


@pytest.mark.parametrize("driver", registry.REGISTRY, ids=IDS)
def test_every_registered_driver_has_a_shipped_profile_that_loads(driver: registry.Driver) -> None:
    profiles = [p for p in map(load_profile, SHIPPED) if p.driver == driver.name]
    assert profiles, f"no profile in {PACKAGE / 'profiles'} has driver = {driver.name!r}"
    module = driver.load()
    for p in profiles:
        assert type(p.driver_config).__module__ == module.__name__      # parsed by the driver's own module


def test_an_unknown_driver_is_refused_naming_the_registered_ones() -> None:
    with pytest.raises(ProfileError) as e:
        parse_profile(with_driver("usb"), "x.toml")
    assert str(e.value) == f"x.toml: driver: must be one of {', '.join(registry.names())} (got 'usb')"


def test_every_registered_driver_is_listed_in_help_and_in_the_package_docstring(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    text = help_text(capsys, monkeypatch)
    doc = drivers.__doc__ or ""
    for d in registry.REGISTRY:
        assert f"{d.name}, {d.summary}" in text
        assert d.module_name in doc and d.summary in doc


def test_a_driver_registered_in_the_registry_alone_is_usable_everywhere(
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    # A new driver, "echo", written once: the registry entry (its module is the simulated arm's, so that
    # this test needs no module of its own).
    echo = registry.Driver("echo", "sim_arm", "a test driver, registered in one place")
    monkeypatch.setattr(registry, "REGISTRY", (*registry.REGISTRY, echo))
    p = parse_profile(with_driver("echo", echo={"script": "hold"}), "x.toml")
    assert p.driver == "echo" and p.driver_config.script == "hold"
    with pytest.raises(ProfileError) as e:
        parse_profile(with_driver("sim", echo={}), "x.toml")
    assert str(e.value) == "x.toml: [echo] given but driver is 'sim'"
    with pytest.raises(ProfileError) as e:
        parse_profile(with_driver("echo", echo={"bogus": 1}), "x.toml")
    assert str(e.value).startswith("x.toml: echo: unknown field(s) bogus")
    assert isinstance(drivers.make_device(p), SimArm)
    assert "echo, a test driver, registered in one place" in help_text(capsys, monkeypatch)


def imports_of(path: pathlib.Path, module: str, known: set[str]) -> set[str]:
    """The package's modules that `module` (at `path`) imports at run time, function-level imports included and
    `if TYPE_CHECKING:` blocks left out. Importing a.b.c runs a.b's __init__ too: that counts as importing a.b."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()

    def add(name: str) -> None:
        while name:
            if name in known and name != module:
                found.add(name)
            name = name.rpartition(".")[0]

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            for a in node.names:
                add(a.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:                                                # relative: from .. / from .x
                base = package
                for _ in range(node.level - 1):
                    base = base.rpartition(".")[0]
                source = f"{base}.{node.module}" if node.module else base
            else:
                source = node.module or ""
            add(source)
            for a in node.names:
                add(f"{source}.{a.name}")                                 # `from . import registry`: a module
        for inner in ast.iter_child_nodes(node):
            visit(inner)

    visit(ast.parse(path.read_text(encoding="utf-8")))
    return found


def test_the_bridge_has_no_import_cycle() -> None:
    files = {".".join(("tactile_bridge", *p.relative_to(PACKAGE).with_suffix("").parts)).removesuffix(".__init__"): p
             for p in PACKAGE.rglob("*.py")}
    graph = {m: imports_of(p, m, set(files)) for m, p in files.items()}
    assert "tactile_bridge.drivers.registry" in graph["tactile_bridge.profile"]
    assert graph["tactile_bridge.drivers.registry"] == set()               # a leaf: nothing of the bridge's own
    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as e:
        pytest.fail(f"import cycle: {' -> '.join(e.args[1])}")


def run_python(code: str) -> str:
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_importing_profile_imports_no_driver_module() -> None:
    # In a fresh interpreter: profile.py reaches the drivers through their registry only.
    out = run_python(
        "import sys, tactile_bridge.profile\n"
        "print(sorted(m for m in sys.modules if m.startswith('tactile_bridge.drivers.')))\n"
        "print('serial' in sys.modules, 'hid' in sys.modules)\n")
    assert out.splitlines() == ["['tactile_bridge.drivers.registry']", "False False"]


def test_a_profile_imports_the_one_driver_module_it_names() -> None:
    out = run_python(
        "import sys, tactile_bridge.profile as p\n"
        f"p.load_profile({str(PACKAGE / 'profiles' / 'sim.toml')!r})\n"
        "print(sorted(m for m in sys.modules if m.startswith('tactile_bridge.drivers.')))\n")
    assert out.splitlines() == ["['tactile_bridge.drivers.registry', 'tactile_bridge.drivers.sim_arm']"]


@pytest.mark.parametrize("driver", registry.REGISTRY, ids=IDS)
def test_each_driver_module_imports_first_in_a_fresh_interpreter(driver: registry.Driver) -> None:
    # Imported before profile.py (as a test or the CLI may), a driver module still finds the profile's names:
    # the import runs one way and is no cycle.
    out = run_python(f"import {driver.module_name}, tactile_bridge.profile as p, tactile_bridge.drivers.registry as r\n"
                     "print(r.names())\n")
    assert out.strip() == repr(registry.names())


def test_tick_rate_overrides_every_profiles_rate_and_refuses_one_out_of_range(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["--check", "--profile", "sim", "--profile", "sim_pinch_left", "--tick-rate", "4000"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and all(", 4000 Hz," in line for line in lines), lines
    assert cli.main(["--check", "--profile", "sim"]) == 0
    assert ", 1000 Hz," in capsys.readouterr().out, "the profile's own rate without it"
    assert cli.main(["--check", "--tick-rate", "50"]) == 2
    assert "--tick-rate must be 100 to 20000 Hz, got 50" in capsys.readouterr().err
