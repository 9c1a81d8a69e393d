"""The options every service accepts (DESIGN.md, "Command line"), and Miro's logging."""

from __future__ import annotations

import io
import logging
import socket
from collections.abc import Iterator

import pytest

from miro_gen import log
from miro_gen.service.options import (
    DEFAULT_NAMING,
    UsageError,
    naming_endpoint,
    parse_common_options,
)


def test_defaults() -> None:
    opts, rest = parse_common_options([], {})
    assert opts.naming == DEFAULT_NAMING == "tcp://127.0.0.1:2809"
    assert opts.naming_context == socket.gethostname()
    assert (opts.log_level, opts.log_filter, opts.config_file, opts.host) == (4, [], None, None)
    assert rest == []


def test_the_manuals_command_line() -> None:
    """§5.1: `./exampleA $NSC -MLL 9 -MLF MIRO` with NSC the -ORBInitRef of the naming service."""
    argv = "-ORBInitRef NameService=iioploc://127.0.0.1:2809/NameService -MLL 9 -MLF MIRO"
    opts, rest = parse_common_options(argv.split(), {})
    assert opts.naming == "tcp://127.0.0.1:2809"
    assert (opts.log_level, opts.log_filter) == (9, ["MIRO"])
    assert rest == []


def test_service_arguments_are_left_in_order() -> None:
    opts, rest = parse_common_options(
        ["5", "-MNC", "robot1", "--verbose", "-MLF", "MIRO", "SICK", "-MCF", "r.xml", "x"], {}
    )
    assert rest == ["5", "--verbose", "x"]
    assert opts.naming_context == "robot1"
    assert opts.log_filter == ["MIRO", "SICK"]
    assert opts.config_file == "r.xml"


@pytest.mark.parametrize(
    ("argv", "field", "expected"),
    [
        (["--naming", "tcp://10.0.0.5:2810"], "naming", "tcp://10.0.0.5:2810"),
        (["--naming=tcp://host:1"], "naming", "tcp://host:1"),
        (["-MiroNamingContext", "/robot2/"], "naming_context", "robot2"),
        (["-MiroLogLevel", "0"], "log_level", 0),
        (["-MiroLogFilter", "A", "B"], "log_filter", ["A", "B"]),
        (["-MiroConfigFile", "c.xml"], "config_file", "c.xml"),
        (["--host", "192.0.2.7"], "host", "192.0.2.7"),
        (["--host=h"], "host", "h"),
    ],
)
def test_long_and_short_forms(argv: list[str], field: str, expected: object) -> None:
    opts, rest = parse_common_options(argv, {})
    assert getattr(opts, field) == expected
    assert rest == []


@pytest.mark.parametrize(
    ("text", "endpoint"),
    [
        ("tcp://127.0.0.1:2809", "tcp://127.0.0.1:2809"),
        ("iioploc://robot:5000/NameService", "tcp://robot:5000"),
        ("NameService=iioploc://robot:5000/NameService", "tcp://robot:5000"),
        ("corbaloc:iiop:192.0.2.1:2809/NameService", "tcp://192.0.2.1:2809"),
        ("corbaloc::192.0.2.1/NameService", "tcp://192.0.2.1:2809"),
        ("corbaloc:iiop:1.2@host:7/NameService", "tcp://host:7"),
    ],
)
def test_naming_addresses(text: str, endpoint: str) -> None:
    assert naming_endpoint(text) == endpoint


def test_environment_and_precedence() -> None:
    env = {"NameServiceIOR": "corbaloc:iiop:a:1/NameService", "MIRO_HOST": "h"}
    opts, _ = parse_common_options([], env)
    assert (opts.naming, opts.host) == ("tcp://a:1", "h")
    opts, _ = parse_common_options([], {**env, "MIRO_NAMING": "tcp://b:2"})
    assert opts.naming == "tcp://b:2"
    opts, _ = parse_common_options(["--naming", "tcp://c:3"], {**env, "MIRO_NAMING": "tcp://b:2"})
    assert opts.naming == "tcp://c:3"  # the command line wins


def test_other_orb_options_are_ignored_with_their_values() -> None:
    argv = ["-ORBDottedDecimalAddresses", "1", "-ORBDebug", "-ORBInitRef", "Other=x", "svc"]
    opts, rest = parse_common_options(argv, {})
    assert rest == ["svc"]
    assert opts.ignored == ["-ORBDottedDecimalAddresses 1", "-ORBDebug", "-ORBInitRef Other=x"]


def test_double_dash_ends_the_common_options() -> None:
    _, rest = parse_common_options(["--", "-MLL", "3"], {})
    assert rest == ["--", "-MLL", "3"]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["-MLL"], "-MLL needs a value"),
        (["-MLL", "x"], "from 0 to 9"),
        (["-MLL", "10"], "from 0 to 9"),
        (["-MLF"], "at least one category"),
        (["-MLF", "-MLL", "3"], "at least one category"),
        (["--naming", "http://x"], "naming service address"),
        (["-MNC", "/"], "empty"),
        (["-ORBInitRef"], "needs a value"),
    ],
)
def test_bad_values_are_usage_errors(argv: list[str], message: str) -> None:
    with pytest.raises(UsageError, match=message):
        parse_common_options(argv, {})


# ---- logging ------------------------------------------------------------------------------------


@pytest.fixture
def stream() -> Iterator[io.StringIO]:
    out = io.StringIO()
    yield out
    log.configure(log.LL_WARNING, (), io.StringIO())  # leave a quiet default behind


def test_level_and_filter_select_what_is_printed(stream: io.StringIO) -> None:
    log.configure(log.LL_DEBUG, ["MIRO"], stream)
    miro, sick = log.logger("MIRO"), log.logger("SICK")
    miro.log(log.LL_DEBUG, "Map Size: %d", 3)  # MIRO_DBG_OSTR(MIRO, LL_DEBUG, ...)
    miro.trace("too detailed for -MLL 7")
    sick.error("another category")
    miro.notice("n")
    assert stream.getvalue() == "[DEBUG MIRO] Map Size: 3\n[NOTICE MIRO] n\n"


def test_default_level_is_warning_and_every_category(stream: io.StringIO) -> None:
    log.configure(stream=stream)
    log.logger("SICK").warning("w")
    log.logger("MIRO").notice("not at level 4")
    log.logger("GPS").emergency("e")
    assert stream.getvalue() == "[WARNING SICK] w\n[EMERGENCY GPS] e\n"


def test_every_miro_level_is_a_named_python_level(stream: io.StringIO) -> None:
    log.configure(log.LL_PRATTLE, (), stream)
    cat = log.logger("T")
    for level in range(10):
        cat.log(level, "x")
    names = [line.split()[0][1:] for line in stream.getvalue().splitlines()]
    assert names == [
        "EMERGENCY",
        "ALERT",
        "CRITICAL",
        "ERROR",
        "WARNING",
        "NOTICE",
        "CTOR_DTOR",
        "DEBUG",
        "TRACE",
        "PRATTLE",
    ]
    levels = [log.python_level(i) for i in range(10)]
    assert levels == sorted(levels, reverse=True)  # 0 is the most urgent
    assert log.python_level(log.LL_WARNING) == logging.WARNING


def test_configure_again_replaces_the_handler(stream: io.StringIO) -> None:
    log.configure(log.LL_WARNING, (), io.StringIO())
    log.configure(log.LL_WARNING, (), stream)
    log.logger("MIRO").warning("once")
    assert stream.getvalue() == "[WARNING MIRO] once\n"
    with pytest.raises(ValueError, match="0 to 9"):
        log.python_level(10)
