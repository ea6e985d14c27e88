"""Moves through the bus (``bus simulate --move`` / ``--trajectory``): jerk-limited S-curves
(:mod:`lolacli.motion.scurve`, seed 003) streamed to the drives in cyclic synchronous
position through the Bus Variables, one set-point a cycle.

Units: every distance, velocity, acceleration and jerk is in the drive's own position
unit (*increments*: 0x607A/0x6064 counts) and its time derivatives, increments/s, /s²,
/s³. No joint model here knows an encoder resolution, so there is no radian to convert
to; the report says the unit (``unit: "increments"``).

A *goal* moves one drive to its start position plus ``distance`` (the start: its actual
position when the moves begin, the first cycle every drive is enabled). ``--move
JOINT:DISTANCE[:V:A:J]`` is a goal at 0 s; a trajectory file lists goals at any time,
and a goal interrupts the drive's running profile: the new one starts from the current
position and velocity (:class:`~lolacli.motion.scurve.OnTheFly`, seed 003 §4).

The planner plans at the goal's cycle and samples the whole new profile on the cycle grid
(numpy) into a table of set-points; every cycle it writes that cycle's row into the
outputs (one scatter of bytes) and keeps the actual positions the drives sent back. The
``planner`` section of the cycle times both. After the run, :meth:`Moves.report` gives
each moved joint's *following error*: the set-point the master sent in a cycle minus the
actual position it received in the same cycle (the master's view, so it includes the
bus's delay: the frame that carries a set-point brings back the position of before it),
RMS and largest magnitude over the joint's motion (from its first goal until its last
profile has ended and the error is back at 0).
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lolacli.errors import InputError, UsageError

UNIT = "increments"
#: the limits of a goal that gives none (increments/s, /s², /s³): a 20 000-increment move
#: (the default back-and-forth's amplitude) in about 0.33 s
DEFAULT_V = 100_000.0
DEFAULT_A = 1_000_000.0
DEFAULT_J = 20_000_000.0
#: the largest distance or limit accepted (the target is an INTEGER32)
MAX_DISTANCE = 2.0**31 - 1
ALL = "all"


@dataclass(frozen=True, slots=True)
class Goal:
    """One goal: at ``t_s`` seconds after the moves begin, ``joint`` (a slave name, its
    short name, a position, or ``all``) to its start position plus ``distance``, with
    the limits ``v``, ``a``, ``j``. ``source``/``line``: where it was given (None: the
    command line)."""

    joint: str
    distance: float
    v: float = DEFAULT_V
    a: float = DEFAULT_A
    j: float = DEFAULT_J
    t_s: float = 0.0
    source: str | None = None
    line: int | None = None

    def error(self, message: str) -> Exception:
        """The error for this goal: UsageError for --move, InputError with file and line
        for a trajectory file's row."""
        if self.source is None:
            return UsageError(f"--move {self.joint}:{self.distance:g}: {message}")
        return InputError(message, path=self.source, line=self.line)


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{what} {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ValueError(f"{what} must be a finite number, not {text}")
    return value


def _goal(joint: str, distance: Any, v: Any, a: Any, j: Any, t_s: Any = 0.0,
          source: str | None = None, line: int | None = None) -> Goal:
    """A checked goal; ValueError with the reason."""
    if not str(joint).strip():
        raise ValueError("no joint given")
    d = _number(str(distance), "distance")
    if abs(d) > MAX_DISTANCE:
        raise ValueError(f"distance {d:g} is over {MAX_DISTANCE:,.0f} {UNIT}")
    limits = []
    for name, value in (("velocity", v), ("acceleration", a), ("jerk", j)):
        x = _number(str(value), name)
        if x <= 0 or x > 1e12:
            raise ValueError(f"{name} limit must be > 0 and at most 1e12, not {x:g}")
        limits.append(x)
    t = _number(str(t_s), "time")
    if t < 0:
        raise ValueError(f"time must be >= 0, not {t:g}")
    v_, a_, j_ = limits
    return Goal(str(joint).strip(), d, v_, a_, j_, t_s=t, source=source, line=line)


def parse_move(text: str) -> Goal:
    """``JOINT:DISTANCE[:V:A:J]`` (the joint may hold colons; the numbers are the last one
    or four fields). UsageError (exit 2) for what does not parse."""
    parts = text.split(":")
    try:
        if len(parts) >= 5 and _all_numbers(parts[-4:]):
            joint, numbers = ":".join(parts[:-4]), parts[-4:]
        elif len(parts) in (3, 4) and _all_numbers(parts[1:]):
            raise ValueError("V, A and J go together, or none")
        elif len(parts) >= 2:
            joint, numbers = ":".join(parts[:-1]), parts[-1:] + [
                str(DEFAULT_V), str(DEFAULT_A), str(DEFAULT_J)]
        else:
            raise ValueError("no distance")
        return _goal(joint, numbers[0], numbers[1], numbers[2], numbers[3])
    except ValueError as exc:
        hint = " (JOINT:DISTANCE[:V:A:J])" if len(str(exc)) < 24 else ""
        said = f" {text!r}" if hint else ""  # else the message names the value
        raise UsageError(f"--move{said}: {exc}{hint}") from None


def _all_numbers(fields: list[str]) -> bool:
    try:
        for f in fields:
            float(f)
    except ValueError:
        return False
    return True


#: the largest trajectory file read (a goal a line: ~100 000 goals)
MAX_TRAJECTORY_BYTES = 4 << 20
#: the columns of a trajectory file (the last three optional)
COLUMNS = ("time_s", "joint", "distance", "v", "a", "j")


def parse_trajectory(path: Path) -> list[Goal]:
    """The goals of a trajectory file: CSV with the header ``time_s,joint,distance`` and
    optionally ``v,a,j`` (one goal a row; ``#`` starts a comment line), or JSON: a list of
    objects with those keys (or ``{"goals": [...]}``). InputError (exit 3) with the file
    and line for what does not parse."""
    source = str(path)
    from lolacli.files import read_bounded

    try:
        text = read_bounded(path, "a trajectory file", MAX_TRAJECTORY_BYTES).decode("utf-8")
    except UnicodeDecodeError:
        raise InputError("not UTF-8 text", path=source) from None
    if text.lstrip().startswith(("[", "{")):
        rows = _json_rows(text, source)
    else:
        rows = _csv_rows(text, source)
    goals = []
    for line, row in rows:
        try:
            goals.append(_goal(
                row.get("joint", ""), row.get("distance", ""), row.get("v", DEFAULT_V),
                row.get("a", DEFAULT_A), row.get("j", DEFAULT_J), row.get("time_s", 0.0),
                source, line))
        except ValueError as exc:
            raise InputError(str(exc), path=source, line=line) from None
    if not goals:
        raise InputError("no goals (expected rows of time_s,joint,distance[,v,a,j])",
                         path=source)
    return goals


def _csv_rows(text: str, source: str) -> list[tuple[int, dict[str, Any]]]:
    lines = [(n, line) for n, line in enumerate(text.splitlines(), 1)
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise InputError("empty: expected a header time_s,joint,distance[,v,a,j]", path=source)
    header_line, header = lines[0]
    names = [h.strip() for h in next(csv.reader(io.StringIO(header)))]
    missing = [c for c in COLUMNS[:3] if c not in names]
    unknown = [c for c in names if c not in COLUMNS]
    if missing or unknown:
        what = f"missing {', '.join(missing)}" if missing else f"unknown {', '.join(unknown)}"
        raise InputError(f"header: {what} (expected time_s,joint,distance[,v,a,j])",
                         path=source, line=header_line)
    out = []
    for n, line in lines[1:]:
        values = next(csv.reader(io.StringIO(line)))
        if len(values) != len(names):
            raise InputError(f"{len(values)} fields, the header has {len(names)}",
                             path=source, line=n)
        out.append((n, {k: v.strip() for k, v in zip(names, values, strict=True)}))
    return out


def _json_rows(text: str, source: str) -> list[tuple[int, dict[str, Any]]]:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(exc.msg, path=source, line=exc.lineno) from None
    if isinstance(doc, dict):
        doc = doc.get("goals")
    if not isinstance(doc, list) or not all(isinstance(g, dict) for g in doc):
        raise InputError('expected a list of goals (or {"goals": [...]}), each an object '
                         "with time_s, joint, distance[, v, a, j]", path=source)
    out = []
    for i, g in enumerate(doc):
        unknown = [k for k in g if k not in COLUMNS]
        if unknown:
            raise InputError(f"goal {i + 1}: unknown {', '.join(unknown)}", path=source)
        out.append((i + 1, g))
    return out


def resolve(goals: tuple[Goal, ...], slaves: list[tuple[int, str]],
            drives: list[str]) -> list[tuple[int, Goal]]:
    """(drive index, goal) for every goal: ``joint`` a slave's position, its full name, or
    (ignoring case and spaces) its name without the number ("L Knee") or the number alone
    ("Joint04"); ``all`` every drive. The error of the goal for a joint that is not there
    or not a CiA 402 drive."""
    def key(text: str) -> str:
        return "".join(text.lower().split())

    index = {name: i for i, name in enumerate(drives)}
    out: list[tuple[int, Goal]] = []
    for goal in goals:
        if key(goal.joint) == ALL:
            if not drives:
                raise goal.error("no CiA 402 drive on this bus to move")
            out += [(i, goal) for i in range(len(drives))]
            continue
        wanted = key(goal.joint)
        found = None
        for position, name in slaves:
            number, _, rest = name.partition(" ")
            if wanted in (str(position), key(name)) or (rest and wanted in (key(rest),
                                                                            key(number))):
                found = (position, name)
                break
        if found is None:
            raise goal.error(f"no slave {goal.joint!r} (a name, 1 to {len(slaves)}, or all)")
        if found[1] not in index:
            raise goal.error(f"slave {found[0]} is not a CiA 402 drive")
        out.append((index[found[1]], goal))
    return out


def _int32s(buffer: bytearray, at: list[int]) -> Any:
    """The little-endian INTEGER32s at byte offsets ``at`` of ``buffer`` as one numpy
    view (no copy): a strided array where the offsets are evenly spaced (a drive's
    variables repeat with the same layout), else a small object that gathers and
    scatters their bytes."""
    import numpy as np

    n = len(at)
    steps = {b - a for a, b in zip(at, at[1:], strict=False)}
    if n == 1 or (len(steps) == 1 and min(steps) >= 4):
        stride = at[1] - at[0] if n > 1 else 4
        return np.ndarray((n,), dtype="<i4", buffer=buffer, offset=at[0], strides=(stride,))
    return _Scattered(buffer, at)


class _Scattered:
    """INTEGER32s at offsets that are not evenly spaced: ``view[:] = values`` writes them,
    ``numpy.asarray(view)`` reads them."""

    def __init__(self, buffer: bytearray, at: list[int]) -> None:
        import numpy as np

        self.bytes = np.frombuffer(buffer, dtype=np.uint8)
        self.index = np.asarray([a + b for a in at for b in range(4)], dtype=np.intp)

    def __setitem__(self, key: Any, values: Any) -> None:
        import numpy as np

        self.bytes[self.index] = np.asarray(values, dtype="<i4").view(np.uint8)

    def __array__(self, dtype: Any = None, copy: Any = None) -> Any:
        return self.bytes[self.index].view("<i4")


class Moves:
    """The planner of a simulation's moves (module docstring): ``goals`` as (drive index,
    goal), ``n`` drives, ``cycles`` the run's cycles, ``cycle_s`` the cycle time."""

    def __init__(self, goals: list[tuple[int, Goal]], n: int, cycles: int,
                 cycle_s: float) -> None:
        import numpy as np

        from lolacli.motion.scurve import OnTheFly

        self.n = n
        self.cycle_s = cycle_s
        self.rows = cycles + 2  # set-points of cycles 0 .. rows-1 of the moves
        by_cycle: dict[int, list[tuple[int, Goal]]] = {}
        for i, goal in goals:
            k = max(0, math.ceil(goal.t_s / cycle_s - 1e-9))
            by_cycle.setdefault(k, []).append((i, goal))
        self.pending = sorted(by_cycle.items())
        self.goals = goals
        self.moved = sorted({i for i, _ in goals})
        self.kernels = {i: OnTheFly(DEFAULT_V, DEFAULT_A, DEFAULT_J, cycle_s)
                        for i in self.moved}
        self.first: dict[int, int] = {}  # drive -> cycle of its first goal
        self.end: dict[int, int] = {}  # drive -> cycle its last profile ends
        self.offset: dict[int, float] = {}  # drive -> its last goal's distance
        self.targets = np.zeros((self.rows, n), dtype="<i4")
        self.actual = np.zeros((self.rows, n), dtype="<i4")
        self.homes: Any = None
        self.k = 0  # cycles since the moves began (the row written next)
        self.started = False
        self._out: Any = None  # the targets in the outputs (an int32 view)
        self._in: Any = None  # the actual positions in the inputs (an int32 view)

    def begin(self, homes: list[int], inputs: bytearray, outputs: bytearray,
              in_at: list[int], out_at: list[int]) -> None:
        """The moves start: every drive's start position (``homes``), the process image's
        inputs and outputs (read and written in place every cycle) and the byte offsets of
        each drive's actual and target position in them."""
        import numpy as np

        self.homes = np.asarray(homes, dtype=np.int64)
        self.targets[:] = self.homes.astype("<i4")
        self._in, self._out = _int32s(inputs, in_at), _int32s(outputs, out_at)
        self.started = True

    def cycle(self) -> None:
        """One cycle: new goals planned, this cycle's set-points written to the outputs,
        the actual positions received (the inputs of this cycle) kept."""
        k = self.k
        pending = self.pending
        if pending and pending[0][0] <= k:
            for i, goal in pending.pop(0)[1]:
                self._plan(k, i, goal)
        row = min(k, self.rows - 1)
        self._out[:] = self.targets[row]
        self.actual[row] = self._in
        self.k = k + 1

    def _plan(self, k: int, i: int, goal: Goal) -> None:
        import numpy as np

        kernel = self.kernels[i]
        kernel.vmax, kernel.amax, kernel.jmax = goal.v, goal.a, goal.j
        kernel.k = k
        try:
            profile = kernel.goal(goal.distance)
        except UsageError as exc:  # a goal the planner cannot reach from where it is
            raise goal.error(str(exc)) from None
        origin = kernel._origin  # noqa: SLF001 - where the new profile starts
        pos = profile.sample()["position"]
        home = int(self.homes[i])
        lo, hi = home + origin + float(pos.min()), home + origin + float(pos.max())
        if lo < -(2**31) or hi > 2**31 - 1:
            raise goal.error(f"the move from {home + origin:.0f} reaches {lo if lo < 0 else hi:.0f}"
                             ", outside the drive's INTEGER32 target position")
        stop = min(self.rows, k + len(pos))
        self.targets[k:stop, i] = np.rint(home + origin + pos[: stop - k]).astype(np.int64)
        self.targets[stop:, i] = round(home + origin + profile.end_position)
        self.first.setdefault(i, k)
        self.end[i] = k + len(pos) - 1
        self.offset[i] = goal.distance

    def last_targets(self) -> list[int]:
        """The set-points written last."""
        return [int(x) for x in self.targets[max(0, min(self.k, self.rows) - 1)]]

    def report(self, names: list[str], positions: list[int]) -> list[dict[str, Any]]:
        """Each moved drive's move and following error (module docstring)."""
        import numpy as np

        out = []
        done = min(self.k, self.rows)
        for i in self.moved:
            first = self.first.get(i)
            entry: dict[str, Any] = {
                "joint": names[i],
                "slave": positions[i],
                "unit": UNIT,
                "goals": sum(1 for j, _ in self.goals if j == i),
                "distance": self.offset.get(i),
                "start_position": int(self.homes[i]) if self.started else None,
                "target_position": None,
                "end_position": None,
                "duration_s": None,
                "complete": False,
                "following_error_rms": None,
                "following_error_max": None,
            }
            if first is not None and done > first:
                end = self.end[i]
                err = self._error(i)
                entry.update({
                    "target_position": int(self.targets[-1, i]),
                    "end_position": int(self.actual[done - 1, i]),
                    "duration_s": round((end - first) * self.cycle_s, 9),
                    "complete": done - 1 >= end,
                    "following_error_rms": round(float(np.sqrt(np.mean(err.astype(float) ** 2))),
                                                 3),
                    "following_error_max": int(np.abs(err).max()),
                })
            out.append(entry)
        return out

    def _error(self, i: int) -> Any:
        """Drive ``i``'s following error per cycle over its motion (module docstring)."""
        import numpy as np

        first, done = self.first[i], min(self.k, self.rows)
        err = (self.targets[first:done, i].astype(np.int64)
               - self.actual[first:done, i].astype(np.int64))
        nonzero = np.flatnonzero(err)
        # the motion: until the profile's end, then while the error lasts
        last = max(self.end[i] - first, int(nonzero[-1]) if nonzero.size else 0)
        return err[: last + 1]

    def errors(self, names: list[str]) -> dict[str, tuple[Any, Any]]:
        """Each moved drive's following error over its motion as (seconds since the moves
        began, error in increments) per cycle, by drive name (for ``lolacli report``)."""
        import numpy as np

        out = {}
        for i in self.moved:
            first = self.first.get(i)
            if first is None or min(self.k, self.rows) <= first:
                continue
            err = self._error(i)
            out[names[i]] = ((first + np.arange(err.size)) * self.cycle_s, err)
        return out
