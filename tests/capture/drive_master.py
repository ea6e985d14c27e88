"""Drive a real master (pysoem or KickCAT) through bring-up and cycles on one interface,
and print, as one JSON line, what the master itself saw: the oracle that
``test_capture_masters.py`` compares ``capture analyze`` with.

Run as a script (the test starts it inside a network namespace):

    python3 tests/capture/drive_master.py pysoem IFACE --cycles 500 --period 0.001

Timeouts are generous on purpose: the emulator answers some frames slowly (issue #9,
being fixed), and these tests run on a loaded 2-core host; a late answer is still an
answer in the capture, and the verdicts checked here do not depend on the timeout.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

PYSOEM_TIMEOUT_US = 50_000  # pysoem's default (2 ms) loses replies of the slow emulator
INIT_ATTEMPTS = 30
KICKCAT_TIMEOUT_S = 0.05  # KickCAT waits this long for a frame; 20 ms loses slow answers, and more
#                          # trips the 100 ms watchdog (request_state waits it out)


def _pysoem(iface: str, cycles: int, period: float) -> dict:
    import pysoem

    master = pysoem.Master()
    master.open(iface)
    out: dict = {"master": "pysoem", "lost": 0, "bad_wkc": 0, "wkcs": {}}
    try:
        out["slaves"] = master.config_init()
        master.config_map()
        out["expected_wkc"] = master.expected_wkc
        master.config_dc()
        master.state_check(pysoem.SAFEOP_STATE, 5_000_000)
        master.state = pysoem.OP_STATE
        master.write_state()

        def cycle() -> None:
            master.send_processdata()
            wkc = master.receive_processdata(PYSOEM_TIMEOUT_US)
            out["wkcs"][wkc] = out["wkcs"].get(wkc, 0) + 1
            if wkc < 0:
                out["lost"] += 1
            elif wkc != master.expected_wkc:
                out["bad_wkc"] += 1

        reached = False
        for _ in range(200):
            cycle()
            if master.state_check(pysoem.OP_STATE, 1000) == pysoem.OP_STATE:
                reached = True
                break
        out["reached_op"] = reached
        next_t = time.perf_counter()
        for _ in range(cycles):
            cycle()
            next_t += period
            delay = next_t - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        master.read_state()
        out["states"] = [s.state for s in master.slaves]
        out["al_status"] = [s.al_status for s in master.slaves]
    finally:
        master.close()
    return out


def _kickcat(iface: str, cycles: int, period: float) -> dict:
    import kickcat

    out: dict = {"master": "kickcat", "errors": {}, "init_attempts": 0, "reached_op": False}
    link = kickcat.create_link(iface, "")
    link.set_timeout(KICKCAT_TIMEOUT_S)
    bus = kickcat.Bus(link)

    def note(exc: Exception) -> None:
        key = type(exc).__name__ + ": " + str(exc).split("\n")[0][:60]
        out["errors"][key] = out["errors"].get(key, 0) + 1

    # KickCAT gives up a bring-up on the first lost frame (--drop-p): start it again
    for _ in range(INIT_ATTEMPTS):
        out["init_attempts"] += 1
        try:
            bus.init(0.1)
            slaves = bus.slaves()
            out["slaves"] = len(slaves)
            bus.create_mapping()
            for s in slaves:
                s.set_output_bytes(bytes(s.output_size))
            # From SAFEOP on the slaves' sync-manager watchdog (100 ms) wants outputs;
            # KickCAT's wait_for_state sleeps 100 ms before its first callback: poll here
            out["reached_op"] = all(_to_state(bus, slaves, state, kickcat) for state in
                                    (kickcat.State.SAFE_OP, kickcat.State.OPERATIONAL))
            break
        except Exception as exc:  # noqa: BLE001
            note(exc)
    else:
        return out
    next_t = time.perf_counter()
    out["cycles"] = 0
    for _ in range(cycles):
        out["cycles"] += 1
        try:
            bus.process_data()  # raises on a lost frame or a working-counter mismatch
        except Exception as exc:  # noqa: BLE001
            note(exc)
        next_t += period
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    return out


def _to_state(bus, slaves, state, kickcat, timeout_s: float = 5.0) -> bool:  # noqa: ANN001
    bus.request_state(state)
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        bus.process_data_no_check()
        try:
            if all(bus.get_state(s) == state for s in slaves):
                return True
        except Exception:  # noqa: BLE001  (a slave refusing the state: AL error)
            return False
        time.sleep(0.002)
    return False


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("master", choices=("pysoem", "kickcat"))
    ap.add_argument("iface")
    ap.add_argument("--cycles", type=int, default=300)
    ap.add_argument("--period", type=float, default=0.002)
    args = ap.parse_args()
    run = _pysoem if args.master == "pysoem" else _kickcat
    result = run(args.iface, args.cycles, args.period)
    sys.stdout.write(json.dumps(result) + "\n")


if __name__ == "__main__":
    main()
