"""The report's joint sections: what the joints did behind their drives.

* ``joints``: a simulation run with ``--move``/``--trajectory`` — each moved joint's
  following error (the set-point the master sent minus the actual position it received,
  in the drive's increments) from ``bus simulate``'s ``moves``, and over time from its
  series.
* ``tracking``: ``joint track --format json`` (``lolacli.joint/1``) — seed 000's Table
  III, one row per case, and Fig. 9, the error over time, when the document carries each
  case's ``error_series`` (``joint track --series``).
* ``bandwidth``: ``joint bode --format json`` (``lolacli.joint-bode/1``) — Fig. 10, gain
  and phase against frequency with the -3 dB bandwidth.

As everywhere in the report, nothing is computed again: the numbers are the documents'.
The documents are checked when loaded (:func:`load_track`, :func:`load_bode`): anything
but what those commands write is an :class:`~lolacli.errors.InputError` (exit 3) naming
the file.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lolacli.errors import InputError
from lolacli.files import read_bounded
from lolacli.findings import Finding, Severity
from lolacli.text import number

#: the schemas of ``joint track`` and ``joint bode`` (lolacli/cli/joint.py writes them)
TRACK_SCHEMA = "lolacli.joint/1"
BODE_SCHEMA = "lolacli.joint-bode/1"
#: larger documents are not one of theirs (``joint track --series`` of 50 steps: ~30 MB)
MAX_BYTES = 256 * 1024 * 1024
#: joints drawn in the following error's figure at most (those with the largest RMS)
MAX_JOINTS_DRAWN = 6


@dataclass(frozen=True, slots=True)
class JointDoc:
    """A loaded ``joint track`` or ``joint bode`` document and the file it came from."""

    path: str
    doc: dict[str, Any]


# ---------------------------------------------------------------- loading


def _read(path: str | Path, schema: str, command: str) -> dict[str, Any]:
    name = str(path)
    raw = read_bounded(path, f"{command}'s JSON", MAX_BYTES)
    try:
        doc = json.loads(raw)
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"not JSON: {getattr(exc, 'msg', exc)}", path=name,
                         line=getattr(exc, "lineno", None)) from None
    if not isinstance(doc, dict) or doc.get("schema") != schema:
        found = doc.get("schema") if isinstance(doc, dict) else None
        raise InputError(f"not a {schema} document (what `lolacli {command} --format json` "
                         f"writes){f'; its schema is {found!r}' if found else ''}", path=name)
    return doc


def _num(obj: dict[str, Any], key: str, where: str, path: str, *, low: float | None = None,
         optional: bool = False, finite: bool = True) -> float | None:
    value = obj.get(key)
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or (
            finite and not math.isfinite(value)) or math.isnan(value):
        raise InputError(f"{where}{key}: expected a number, not {value!r}", path=path)
    if low is not None and value < low:
        raise InputError(f"{where}{key}: {value!r} is below {low:g}", path=path)
    return float(value)


def _str(obj: dict[str, Any], key: str, where: str, path: str) -> str:
    value = obj.get(key)
    if not isinstance(value, str) or not value:
        raise InputError(f"{where}{key}: expected a text, not {value!r}", path=path)
    return value


def load_track(path: str | Path) -> JointDoc:
    """``joint track --format json``'s document (its cases checked); InputError (exit 3)
    naming the file for anything else."""
    name = str(path)
    doc = _read(path, TRACK_SCHEMA, "joint track")
    _str(doc, "joint", "", name)
    cases = doc.get("cases")
    if not isinstance(cases, list) or not cases:
        raise InputError("cases: expected a list of the tracked cases", path=name)
    for i, case in enumerate(cases):
        where = f"cases[{i}]."
        if not isinstance(case, dict):
            raise InputError(f"cases[{i}]: expected an object", path=name)
        _str(case, "name", where, name)
        for key in ("control_hz", "bus_hz"):
            _num(case, key, where, name, low=1e-9)
        for key in ("k_e", "rms_error_rad", "max_error_rad"):
            _num(case, key, where, name, low=0.0 if key != "k_e" else None)
        if not isinstance(case.get("extrapolation"), bool):
            raise InputError(f"{where}extrapolation: expected true or false", path=name)
        series = case.get("error_series")
        if series is not None:
            if not isinstance(series, dict):
                raise InputError(f"{where}error_series: expected an object", path=name)
            _num(series, "sample_s", f"{where}error_series.", name, low=1e-12)
            values = series.get("error_rad")
            if not isinstance(values, list) or not all(
                    isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                    for v in values):
                raise InputError(f"{where}error_series.error_rad: expected a list of numbers",
                                 path=name)
    return JointDoc(name, doc)


def load_bode(path: str | Path) -> JointDoc:
    """``joint bode --format json``'s document (its points checked); InputError (exit 3)
    naming the file for anything else."""
    name = str(path)
    doc = _read(path, BODE_SCHEMA, "joint bode")
    _str(doc, "joint", "", name)
    _num(doc, "bus_hz", "", name, low=1e-9)
    _num(doc, "bandwidth_hz", "", name, low=0.0, optional=True)
    points = doc.get("points")
    if not isinstance(points, list) or not points:
        raise InputError("points: expected a list of the response's points", path=name)
    for i, p in enumerate(points):
        if not isinstance(p, dict):
            raise InputError(f"points[{i}]: expected an object", path=name)
        _num(p, "freq_hz", f"points[{i}].", name, low=1e-12)
        _num(p, "gain_db", f"points[{i}].", name, finite=False)  # -inf: no response
        _num(p, "phase_deg", f"points[{i}].", name)
    return JointDoc(name, doc)


# ---------------------------------------------------------------- sections


def mrad(rad: float) -> str:
    """An angle error as ``joint track`` shows it: mrad to four decimals."""
    return number(rad * 1e3, "mrad", 4)


def moves_rows(moves: list[dict[str, Any]]) -> list[list[str]]:
    """The joints table's rows: one a moved joint (``bus simulate``'s ``moves``)."""
    rows = []
    for m in moves:
        unit = "inc"
        if m["duration_s"] is None:
            rows.append([str(m["slave"]), m["joint"], number(m["distance"] or 0, unit),
                         "never started", "–", "–"])
            continue
        rows.append([str(m["slave"]), m["joint"], number(m["distance"], unit),
                     number(m["duration_s"], "s") + ("" if m["complete"] else " (cut)"),
                     number(m["following_error_rms"], unit, 1),
                     number(m["following_error_max"], unit, 0)])
    return rows


def joints_data(moves: list[dict[str, Any]]) -> dict[str, Any]:
    rms = [m["following_error_rms"] for m in moves if m["following_error_rms"] is not None]
    return {"unit": moves[0]["unit"] if moves else "increments", "moves": moves,
            "largest_following_error_rms": max(rms) if rms else None,
            "largest_following_error_max": max(
                (m["following_error_max"] for m in moves
                 if m["following_error_max"] is not None), default=None)}


def drawn_joints(following: dict[str, tuple[Any, Any]], moves: list[dict[str, Any]]
                 ) -> list[str]:
    """The joints whose error over time is drawn: those of the series with the largest
    RMS, at most :data:`MAX_JOINTS_DRAWN`, in slave order."""
    rms = {m["joint"]: m["following_error_rms"] or 0.0 for m in moves}
    order = [m["joint"] for m in moves if m["joint"] in following]
    biggest = sorted(order, key=lambda j: -rms.get(j, 0.0))[:MAX_JOINTS_DRAWN]
    return [j for j in order if j in biggest]


def tracking_rows(cases: list[dict[str, Any]]) -> list[list[str]]:
    """Table III: one row a case, the RMS error's change against the first case."""
    first = cases[0]["rms_error_rad"]
    rows = []
    for i, c in enumerate(cases):
        change = "–" if i == 0 or not first else \
            f"{100 * (c['rms_error_rad'] - first) / first:+.1f} %"
        ff = c.get("feedforward") or ""
        rows.append([c["name"], number(c["control_hz"], "Hz", 0), number(c["bus_hz"], "Hz", 0)
                     + (", extrapolated" if c["extrapolation"] else ""),
                     f"{c['k_e']:.1f}" + (f" ({ff})" if ff else ""),
                     mrad(c["rms_error_rad"]), mrad(c["max_error_rad"]), change])
    return rows


def tracking_data(track: JointDoc) -> dict[str, Any]:
    d = track.doc
    cases = [{k: v for k, v in c.items() if k != "error_series"} for c in d["cases"]]
    first = cases[0]["rms_error_rad"]
    for c in cases:
        c["rms_change_percent"] = (round(100 * (c["rms_error_rad"] - first) / first, 3)
                                   if first else None)
    return {"file": track.path, "joint": d["joint"], "trajectory": d.get("trajectory"),
            "cases": cases, "learning": d.get("learning"),
            "error_series": all("error_series" in c for c in d["cases"])}


def tracking_findings(track: JointDoc) -> list[Finding]:
    """A case that tracks no better than the first (the standard feed-forward at the
    control rate): the feed-forward or the faster bus did not pay off."""
    cases = track.doc["cases"]
    first = cases[0]
    out = []
    for c in cases[1:]:
        if c["rms_error_rad"] >= first["rms_error_rad"]:
            out.append(Finding("joint-tracking", Severity.WARNING, (
                f"{track.doc['joint']}, {c['name']}: RMS error {mrad(c['rms_error_rad'])} is "
                f"not below {first['name']}'s {mrad(first['rms_error_rad'])}")))
    return out


def bandwidth_rows(bode: JointDoc) -> list[list[str]]:
    d = bode.doc
    c = d.get("chirp") or {}
    bw = d.get("bandwidth_hz")
    top = d["points"][-1]["freq_hz"]
    rows = [["joint", d["joint"]], ["bus rate", number(d["bus_hz"], "Hz", 0)]]
    if c:
        rows.append(["chirp", f"{number(c['start_hz'], 'Hz')} to {number(c['stop_hz'], 'Hz')},"
                     f" {mrad(c['amplitude_rad'])}, {number(c['duration_s'], 's')}"])
    rows += [["feed-forward", f"{d.get('feedforward', '–')}, k_e {d.get('k_e', 0):g}"],
             ["points", f"{len(d['points'])} (1/24-octave bands)"],
             ["-3 dB bandwidth", number(bw, "Hz", 1) if bw is not None else
              f"above {number(top, 'Hz', 1)} (not reached)"]]
    return rows


def bandwidth_data(bode: JointDoc) -> dict[str, Any]:
    d = bode.doc

    def finite(v: float) -> float | None:
        return v if math.isfinite(v) else None

    return {"file": bode.path, "joint": d["joint"], "bus_hz": d["bus_hz"],
            "chirp": d.get("chirp"), "feedforward": d.get("feedforward"), "k_e": d.get("k_e"),
            "bandwidth_hz": d.get("bandwidth_hz"),
            "points": [{"freq_hz": p["freq_hz"], "gain_db": finite(p["gain_db"]),
                        "phase_deg": p["phase_deg"]} for p in d["points"]]}


def bandwidth_findings(bode: JointDoc) -> list[Finding]:
    d = bode.doc
    if d.get("bandwidth_hz") is not None:
        return []
    top = d["points"][-1]["freq_hz"]
    return [Finding("joint-bandwidth", Severity.INFO, (
        f"{d['joint']}: the gain did not fall below -3 dB up to "
        f"{number(top, 'Hz', 1)}; the bandwidth is above the chirp's band"))]


__all__ = ["BODE_SCHEMA", "TRACK_SCHEMA", "JointDoc", "load_bode", "load_track"]
