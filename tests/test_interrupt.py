"""Signals are handled in one place (lolacli.interrupt.stop_signals) and the previous
handlers come back, however a command ends: importing or calling lolacli never leaves a
handler behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading

import pytest

from lolacli.cli.main import main
from lolacli.interrupt import Interrupted, exit_code, stop_signals


def _mine(_signum: int, _frame: object) -> None:
    raise AssertionError("the test's own handler must not be called")


@pytest.fixture
def own_handlers():
    """Handlers of the test's own in place of the default ones, put back afterwards."""
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in before:
        signal.signal(s, _mine)
    yield
    for s, h in before.items():
        signal.signal(s, h)


def _handlers() -> tuple[object, object]:
    return signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)


@pytest.mark.parametrize(
    "argv",
    [
        ["eni", "inspect", "-f", "json"],  # ends well
        ["eni", "inspect", "/nonexistent.xml"],  # a LolaError (exit 3)
        ["bus", "simulate", "--rate", "0"],  # a usage error (exit 2)
        ["bus", "simulate", "--cycles", "20", "-q", "-f", "json"],  # nests its own
    ],
)
def test_a_command_leaves_the_previous_handlers_in_place(own_handlers, argv, capsys) -> None:
    with pytest.raises(SystemExit):
        main(argv)
    assert _handlers() == (_mine, _mine)


def test_importing_lolacli_installs_no_handler() -> None:
    probe = (
        "import signal\n"
        "before = [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)]\n"
        "import lolacli.cli.main, lolacli.simulate, lolacli.emulator.run\n"
        "import lolacli.capture.analyze, lolacli.sdo.session\n"
        "assert [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)] == before\n"
    )
    subprocess.run([sys.executable, "-c", probe], check=True, timeout=60)


def test_a_signal_inside_raises_interrupted_and_the_handler_goes_back(own_handlers) -> None:
    with pytest.raises(Interrupted) as stopped, stop_signals():
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the handler runs between bytecodes
            pass
    assert stopped.value.signum == signal.SIGTERM and exit_code(stopped.value) == 143
    assert _handlers() == (_mine, _mine)


def test_polled_code_sees_the_first_signal_and_a_second_one_raises(own_handlers) -> None:
    with stop_signals() as stop:
        with stop.polled():
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):
                pass
            assert stop() and stop.exit_code == 130
            with pytest.raises(Interrupted):
                os.kill(os.getpid(), signal.SIGINT)
                for _ in range(1000):
                    pass
    assert _handlers() == (_mine, _mine)


def test_nested_blocks_restore_each_other(own_handlers) -> None:
    with stop_signals() as outer:
        with stop_signals() as inner:
            assert signal.getsignal(signal.SIGINT) == inner.handle
        assert signal.getsignal(signal.SIGINT) == outer.handle
    assert _handlers() == (_mine, _mine)


def test_outside_the_main_thread_nothing_is_installed(own_handlers) -> None:
    seen = []

    def run() -> None:
        with stop_signals() as stop:
            seen.append((stop(), _handlers()))

    t = threading.Thread(target=run)
    t.start()
    t.join()
    assert seen == [(False, (_mine, _mine))]
