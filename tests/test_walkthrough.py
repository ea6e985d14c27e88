"""docs/walkthrough.md and docs/ci.md run as written: every ```console block's commands,
in order, from an empty folder, with ``lolacli`` this checkout's; the walkthrough inside a
network namespace of its own (its veth pair is made there by the page's own ``ip link``
commands, so nothing of it touches the host's interfaces). And the README's first
command writes its report.

How a page's block is read (the page says the same to its reader):

* ``$ CMD`` is a command; a line ending in ``\\`` continues it, a here-document
  (``<<'EOF'``) runs to its end marker; the lines after it up to the next ``$`` are
  its output as shown (``…`` where cut).
* A command ending in `` &`` is a job: started in the background and taken as ready once it
  printed its first line; ``kill [-SIG] %N`` stops job N (started N-th) and waits for it.
* A trailing ``# exit 0 or 1 …`` comment names the exit codes the step may end with (a
  verdict that depends on the host's timing, which must then say PASS for 0 and FAIL for
  1; ``# exit 1``: it must fail); any other
  command must exit 0. Where one exit code is allowed, the output the page shows after
  its last ``…`` must be in what the command printed (words compared, so wrapping does
  not matter).

Needs root, iproute2 and dumpcap (the tshark package); skipped with the reason otherwise.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tests.live import PREFIX, ROOT, ip, need_root

PAGE = ROOT / "docs" / "walkthrough.md"
_BLOCK = re.compile(r"```console\n(.*?)```", re.S)
_EXIT = re.compile(r"\s#\s*exit\s+(\d+(?:\s+or\s+\d+)*)\b")
_KILL = re.compile(r"^kill(?:\s+-(\w+))?\s+%(\d+)$")
_HEREDOC = re.compile(r"<<-?\s*'?\"?(\w+)'?\"?")
#: a job's first line, at most this long after its start
READY_S = 30.0
#: a step, at most
STEP_S = 180.0


@dataclass
class Step:
    command: str
    output: list[str] = field(default_factory=list)

    @property
    def exits(self) -> set[int]:
        m = _EXIT.search(self.command.splitlines()[0])
        return {int(n) for n in m.group(1).split(" or ")} if m else {0}

    @property
    def job(self) -> bool:
        return self.command.rstrip().endswith("&") and "\n" not in self.command


def steps(text: str) -> list[Step]:
    """The page's commands in order, each with the output it shows."""
    out: list[Step] = []
    for block in _BLOCK.findall(text):
        lines = block.splitlines()
        i = 0
        while i < len(lines):
            line = lines[i]
            i += 1
            if not line.startswith("$ "):
                if out and line.strip():
                    out[-1].output.append(line)
                continue
            command = [line[2:]]
            while command[-1].endswith("\\") and i < len(lines):
                command.append(lines[i])
                i += 1
            if m := _HEREDOC.search(command[0]):
                while i < len(lines):
                    command.append(lines[i])
                    i += 1
                    if command[-1].strip() == m.group(1):
                        break
            out.append(Step("\n".join(command)))
    return out


def test_the_page_has_every_step() -> None:
    """The walkthrough's arc, each step a command the test below runs."""
    commands = [s.command for s in steps(PAGE.read_text(encoding="utf-8"))]
    for needle in ("lolacli eni inspect", "ip link add", "lolacli bus emulate", "lolacli bus scan",
                   "lolacli sdo read", "lolacli sdo check", "lolacli bus simulate --eni",
                   "dumpcap", "lolacli bus simulate --iface", "lolacli capture analyze",
                   "lolacli report"):
        assert any(c.startswith(needle) for c in commands), needle
    jobs = [s for s in steps(PAGE.read_text(encoding="utf-8")) if s.job]
    kills = [c for c in commands if _KILL.match(c)]
    assert len(jobs) == len(kills) == 2, "every job the page starts, it stops"


class Job:
    """A background command: its output read as it comes (a full pipe would stall it)."""

    def __init__(self, argv: list[str], cwd: Path, env: dict[str, str]) -> None:
        self.proc = subprocess.Popen(argv, cwd=cwd, env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, bufsize=0)
        self.text = b""
        self.first_line = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        while chunk := self.proc.stdout.read(256):
            self.text += chunk
            if b"\n" in self.text:
                self.first_line.set()
        self.first_line.set()

    def stop(self, sig: int) -> int:
        self.proc.send_signal(sig)
        try:
            code = self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            raise AssertionError(f"still running 30 s after signal {sig}: {self.output}"
                                 ) from None
        self._reader.join(timeout=5)
        return code

    @property
    def output(self) -> str:
        return self.text.decode(errors="replace")


def _words(text: str) -> str:
    return " ".join(text.split())


def _shown_tail(step: Step) -> str:
    """The output the page shows after its last ``…`` (all of it without one), words only:
    a wrapped line reads the same as the terminal's."""
    tail: list[str] = []
    for line in step.output:
        tail = [] if line.strip() == "…" else [*tail, line]
    return _words("\n".join(tail))


def run_page(page: Path, tmp_path: Path, netns: str | None = None) -> Path:
    """Run ``page``'s commands in order from an empty folder (inside ``netns`` when given),
    ``lolacli`` this checkout's as ``pip install -e .`` makes it; the folder."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    wrapper = bin_dir / "lolacli"
    wrapper.write_text(f"#!/bin/sh\nexec {shlex.quote(sys.executable)} -m lolacli \"$@\"\n")
    wrapper.chmod(0o755)
    env = dict(os.environ)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    env["COLUMNS"] = "80"
    work = tmp_path / "work"
    work.mkdir()
    (work / "eni_examples").symlink_to(ROOT / "eni_examples")  # the pages run in the checkout
    shell = ["ip", "netns", "exec", netns, "bash", "-c"] if netns else ["bash", "-c"]
    jobs: list[Job] = []
    log: list[str] = []
    try:
        for step in steps(page.read_text(encoding="utf-8")):
            if kill := _KILL.match(step.command):
                job = jobs[int(kill.group(2)) - 1]
                sig = signal.Signals[f"SIG{kill.group(1) or 'TERM'}"]
                time.sleep(0.5)  # what was sent lands in a capture before it stops
                code = job.stop(sig)
                log.append(f"$ {step.command} -> {code}")
                assert code in (0, 128 + sig), (step.command, code, job.output[-3000:])
                assert "Traceback" not in job.output, job.output[-3000:]
                continue
            if step.job:
                command = step.command.rstrip().removesuffix("&").rstrip()
                job = Job([*shell, f"exec {command}"], work, env)
                jobs.append(job)
                ready = job.first_line.wait(READY_S)
                assert ready and job.proc.poll() is None, (step.command, job.output[-3000:])
                time.sleep(0.5)  # its socket open, its file begun
                log.append(f"$ {step.command} -> {job.output.splitlines()[0]}")
                continue
            t0 = time.monotonic()
            done = subprocess.run([*shell, step.command], cwd=work, env=env,
                                  capture_output=True, text=True, timeout=STEP_S)
            log.append(f"$ {step.command.splitlines()[0]} -> {done.returncode} "
                       f"({time.monotonic() - t0:.1f} s)")
            printed = done.stdout + done.stderr
            assert done.returncode in step.exits, (step.command, done.returncode,
                                                   printed[-3000:], log)
            assert "Traceback" not in printed, printed[-3000:]
            if len(step.exits) == 1 and (tail := _shown_tail(step)):
                assert tail in _words(printed), (step.command, tail, printed[-3000:])
            elif len(step.exits) > 1:  # a verdict that depends on the host: the one it says
                verdict = "Verdict: PASS" if done.returncode == 0 else "Verdict: FAIL"
                assert verdict in printed, (step.command, done.returncode, printed[-3000:])
    finally:
        for job in jobs:
            if job.proc.poll() is None:
                job.proc.kill()
                job.proc.wait()
    return work


@pytest.mark.root
@pytest.mark.timeout(400)
def test_the_walkthrough_runs(tmp_path: Path) -> None:
    need_root("the walkthrough's veth pair")
    if shutil.which("dumpcap") is None:
        pytest.skip("needs dumpcap (Debian package tshark / wireshark-common)")
    netns = f"{PREFIX}w{os.getpid() % 100000:05d}{time.monotonic_ns() % 100:02d}"
    ip("netns", "add", netns)
    try:
        work = run_page(PAGE, tmp_path, netns)
    finally:
        subprocess.run(["ip", "netns", "del", netns], capture_output=True, check=False)
    # what the page's last steps made: the report over the ENI, the capture and a simulation
    doc = json.loads((work / "report" / "lola.json").read_text())
    assert doc["schema"] == "lolacli.report/1"
    assert {"verdict", "network", "timing", "bus", "comparison"} <= set(doc["sections"])
    assert set(doc["headline"]) == {"bus.pcapng", "simulation"}
    assert doc["headline"]["bus.pcapng"]["round_trip_p50_us"] > 0
    html = (work / "report" / "lola.html").read_text()
    assert html.startswith("<!DOCTYPE html>") and "<svg" in html


def test_the_ci_page_runs(tmp_path: Path) -> None:
    """docs/ci.md's commands (no bus: the simulation, sdo check in process, the gate)."""
    work = run_page(ROOT / "docs" / "ci.md", tmp_path)
    worse = json.loads((work / "worse" / "lola.json").read_text())
    assert {r["figure"] for r in worse["regressions"]} == {
        "simulation: round trip p50", "simulation: round trip p99",
        "simulation: max rate, round trip only"}
    now = json.loads((work / "now" / "lola.json").read_text())
    assert now["gate"]["compared"] and not now["regressions"]


def test_the_readme_first_command_writes_its_report(tmp_path: Path) -> None:
    """The README's first command, its set-up left out (the package is installed): the
    LOLA chain simulated at 2 kHz and its report, where the README says."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = text.split("```bash\n", 1)[1].split("```", 1)[0]
    first = next(line for line in block.splitlines() if line and not line.startswith("#"))
    setup, command = first.split(" && ", 1)
    assert setup == "python3 -m pip install -e ."
    argv = shlex.split(command)
    assert argv[:2] == ["lolacli", "report"] and "--rate" in argv and "2000" in argv
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    done = subprocess.run([sys.executable, "-m", "lolacli", *argv[1:]], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "Verdict: PASS" in done.stdout and "wrote lola.html" in done.stdout
    doc = json.loads((tmp_path / "lola.json").read_text())
    assert doc["inputs"]["simulation"]["rate_hz"] == 2000
    assert doc["inputs"]["simulation"]["host_latency_us"]["mean"] == 31.2
    assert set(doc["sections"]) == {"verdict", "network", "timing", "bus", "dc", "software"}
    assert (tmp_path / "lola.html").stat().st_size < 3_000_000
