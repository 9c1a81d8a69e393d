"""`miro new`: every pattern scaffolds into a fresh project, passes ruff (with this repository's
settings, a project's and ruff's defaults) and mypy --strict (with miro-gen installed as a
package), and its own test passes against a naming service; `miro run` starts a service, which
parses its own options; bad names are refused."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import Miro
import pytest
import zmq
from loopback import NamingProcess, free_port
from miro_cli import REPO

PATTERNS = ["basic", "server", "client", "publisher", "subscriber", "device", "timed"]
THERMO = """
module Lab
{
  struct Reading { double celsius; string unit; sequence<long> history; };
  enum Mode { OFF, ON, AUTO };
  exception Broken { string why; };
  interface Thermometer
  {
    Reading read();
    void setMode(in Mode m);
    Mode getMode();
    void calibrate(in double offset, out double previous) raises (Broken);
    string name(in string prefix, inout long count);
  };
};
"""
RUFF_CONFIG = """
[tool.ruff]
line-length = 100
target-version = "py311"

[tool.ruff.lint]
select = ["E", "F", "W", "I", "B", "UP", "SIM", "RUF"]
ignore = ["RUF012"]
"""


def env() -> dict[str, str]:
    e = dict(os.environ)
    e["PYTHONPATH"] = os.pathsep.join([str(REPO / "generated"), str(REPO)])
    return e


def miro(project: Path, *args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "miro_gen.cli.main", *args],
        cwd=project,
        env=env(),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def tool(name: str) -> str:
    path = shutil.which(name) or str(Path(sys.executable).with_name(name))
    if not Path(path).exists():
        pytest.skip(f"{name} is not installed")
    return path


@pytest.fixture(scope="module")
def project(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh project with a service of every pattern, two of them on the user's own IDL."""
    root = tmp_path_factory.mktemp("project")
    (root / "pyproject.toml").write_text(RUFF_CONFIG)
    (root / "idl").mkdir()
    (root / "idl" / "Thermo.idl").write_text(THERMO)
    for pattern in PATTERNS:
        made = miro(root, "new", f"my_{pattern}", "--pattern", pattern)
        assert made.returncode == 0, made.stderr
        assert f"wrote services/my_{pattern}/__main__.py" in made.stdout
        assert f"miro run my_{pattern}" in made.stdout  # the next steps
    lab = ("--idl", "idl/Thermo.idl", "--interface", "Lab::Thermometer")
    made = miro(root, "new", "thermo", "--pattern", "server", *lab)
    assert made.returncode == 0, made.stderr
    made = miro(
        root, "new", "thermo_client", "--pattern", "client", "--interface", "Lab::Thermometer"
    )
    assert made.returncode == 0, made.stderr
    return root


@pytest.mark.parametrize(
    "settings",
    [
        [],  # the project's: as this repository's pyproject.toml, in a project of one's own
        ["--isolated"],  # ruff's defaults (line length 88)
        ["--config", str(REPO / "services" / "ruff.toml")],  # in services/ of this repository
    ],
    ids=["project", "defaults", "this-repository"],
)
def test_the_scaffolds_pass_ruff(project: Path, settings: list[str]) -> None:
    for args in (["check", "--no-cache"], ["format", "--check", "--no-cache"]):
        done = subprocess.run(
            [tool("ruff"), *args, *settings, "services"],
            cwd=project,
            capture_output=True,
            text=True,
        )
        assert done.returncode == 0, done.stdout + done.stderr


def test_the_generated_packages_are_typed() -> None:
    for package in ("Miro", "Miro__POA", "MiroNaming", "MiroNaming__POA", "_GlobalIDL"):
        assert (REPO / "generated" / package / "py.typed").is_file()
    assert (REPO / "miro_gen" / "py.typed").is_file()


def installed(site: Path) -> None:
    """miro_gen and the generated packages, as the wheel installs them (pyproject.toml:
    miro_gen, Miro*, _GlobalIDL*), in `site`: mypy checks against them only if they are
    typed packages (PEP 561)."""
    skip = shutil.ignore_patterns("__pycache__")
    shutil.copytree(REPO / "miro_gen", site / "miro_gen", symlinks=True, ignore=skip)
    for package in (REPO / "generated").iterdir():
        if package.name.startswith(("Miro", "_GlobalIDL")):
            shutil.copytree(package, site / package.name, ignore=skip)


def test_the_scaffolds_pass_mypy_strict(project: Path, tmp_path: Path) -> None:
    """In a project of one's own: miro-gen installed (in a virtual environment whose other
    packages come from this one's), the project's generated code on mypy_path."""
    import site
    import venv

    venv.create(tmp_path / "env", with_pip=False)
    python = tmp_path / "env" / "bin" / "python"
    found = subprocess.run(
        [str(python), "-c", "import site; print(site.getsitepackages()[0])"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    packages = Path(found.stdout.strip())
    installed(packages)
    (packages / "others.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    done = subprocess.run(
        [sys.executable, "-m", "mypy", "--strict", "--explicit-package-bases",
         "--python-executable", str(python), "--cache-dir", str(tmp_path / "cache"),
         "services", "generated"],
        cwd=project,
        env=dict(os.environ, MYPYPATH=str(project / "generated")),
        capture_output=True,
        text=True,
        timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr


def test_the_scaffolded_tests_pass(project: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "services"],
        cwd=project,
        env=env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "9 passed" in done.stdout


def test_the_server_on_the_users_idl_implements_every_operation(project: Path) -> None:
    implementation = (project / "services" / "thermo" / "implementation.py").read_text()
    for signature in (
        "def read(self) -> Lab.Reading:",
        "def setMode(self, m: Lab.Mode) -> None:",
        "def calibrate(self, offset: float) -> float:",
        "def name(self, prefix: str, count: int) -> tuple[str, int]:",
    ):
        assert signature in implementation


def test_miro_run_starts_a_service_against_a_real_naming_service(project: Path) -> None:
    naming = NamingProcess()
    try:
        service = subprocess.Popen(
            [sys.executable, "-m", "miro_gen.cli.main", "run", "my_basic", "--naming",
             naming.endpoint],
            cwd=project,
            env=env(),
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        assert service.stdout is not None
        assert service.stdout.readline().strip() == "Hello from my_basic"
        service.send_signal(signal.SIGINT)
        assert service.wait(20) == 0
        assert "my_basic: stopped" in service.stdout.read()
    finally:
        naming.stop()


def test_a_server_starts_without_what_it_does_not_use(project: Path) -> None:
    """A `miro new` server, once it serves, has not loaded the compilers, lxml (no parameter
    document here), nor hashlib's OpenSSL (which pydantic's `secrets` would bring)."""
    unwanted = ("_hashlib", "hashlib", "lark", "jinja2", "lxml", "miro_gen.compile", "asyncio")
    code = (
        "import atexit, runpy, sys\n"
        f"unwanted = {unwanted!r}\n"
        "def report():\n"
        "    print('loaded:', sorted(m for m in sys.modules if m.startswith(unwanted)))\n"
        "sys.argv[0] = 'my_server'\n"
        "atexit.register(report)\n"
        "runpy.run_module('services.my_server', run_name='__main__', alter_sys=True)\n"
    )
    naming = NamingProcess()
    try:
        service = subprocess.Popen(
            [sys.executable, "-c", code, "--naming", naming.endpoint],
            cwd=project,
            env=env(),
            stdout=subprocess.PIPE,
            text=True,
        )
        assert service.stdout is not None
        assert "my_server serves" in service.stdout.readline()
        service.send_signal(signal.SIGINT)
        service.wait(20)
        assert "loaded: []" in service.stdout.read()
    finally:
        naming.stop()


@pytest.mark.parametrize(
    ("name", "message"),
    [
        (
            "GpsLogger",
            "is not a service name: use lower-case letters, digits and single "
            "underscores, starting with a letter (gps_logger would do)",
        ),
        ("1gps", "is not a service name"),
        ("class", "'class' is a Python keyword, and a service's name is a module's"),
        ("gps__logger", "is not a service name"),
        ("a_name_that_is_far_too_long", "at most 20 characters"),
        ("my_basic", "exists already: nothing was written"),
    ],
)
def test_bad_names_are_refused(project: Path, name: str, message: str) -> None:
    before = sorted(p.name for p in (project / "services").iterdir())
    done = miro(project, "new", name)
    assert done.returncode == 1
    assert message in done.stderr and "Traceback" not in done.stderr
    assert sorted(p.name for p in (project / "services").iterdir()) == before


def test_an_unknown_interface_is_refused(project: Path) -> None:
    done = miro(project, "new", "nowhere", "--pattern", "server", "--interface", "Lab::Missing")
    assert done.returncode == 1
    assert "no generated code for interface Lab::Missing" in done.stderr
    assert not (project / "services" / "nowhere").exists()


def test_a_scaffolded_service_parses_its_own_options(project: Path) -> None:
    helped = miro(project, "run", "my_server", "--help")
    assert helped.returncode == 0 and helped.stdout.startswith("usage: my_server")
    assert "common options" in helped.stdout
    wrong = miro(project, "run", "my_server", "--colour", "blue")
    assert wrong.returncode == 2
    assert "my_server: error: unrecognized arguments: --colour blue" in wrong.stderr


def test_a_scaffolded_server_told_not_to_wait_for_its_naming_service_is_one_line(
    project: Path,
) -> None:
    naming = f"tcp://127.0.0.1:{free_port()}"
    done = miro(project, "run", "my_server", "--naming", naming, "--wait-naming", "0")
    assert done.returncode == 1
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    assert done.stderr.startswith("my_server: cannot bind ")
    assert "is `miro naming` running? see --naming / MIRO_NAMING" in done.stderr


def test_a_scaffolded_client_waits_for_its_server(project: Path) -> None:
    """Started before its server, the client waits for the name, then polls."""
    import Miro__POA

    from miro_gen import Server

    class Example(Miro__POA.Example):
        def setData(self, a: float, b: float) -> None:
            pass

        def getData(self) -> Miro.ExampleStructIDL:
            return Miro.ExampleStructIDL(4.0, 2.0)

    naming = NamingProcess()
    args = ["--naming", naming.endpoint, "-MNC", "waiting"]
    client = subprocess.Popen(
        [sys.executable, "-m", "miro_gen.cli.main", "run", "my_client", *args, "-MLL", "5"],
        cwd=project,
        env=env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    server = None
    try:
        assert client.stdout is not None
        lines = iter(client.stdout.readline, "")
        assert any("waiting for Example" in line for line in lines)  # after other notices
        server = Server(["test", *args], context=zmq.Context())
        server.add_to_name_service(Example(), "Example")
        assert next(lines).strip() == "my_client found Example"
        assert next(lines).strip() == "getData: ExampleStructIDL(a=4.0, b=2.0)"
    finally:
        client.send_signal(signal.SIGINT)
        assert client.wait(20) == 0
        if server is not None:
            server.shutdown()
            server._cleanup()
        naming.stop()
