"""The LOLA CAN gateway's sensors on a live CAN bus: their TPDOs, and the gateway's side.

Seed 000 §III: the IMU (200 Hz) and the two foot force/torque sensors are CANopen nodes
behind a CAN gateway that maps their samples into the EtherCAT process data.
:mod:`lolacli.devices.can` models that in virtual time; here it runs on a python-can bus
(any interface; ``virtual`` within one process, ``udp_multicast`` between processes):

* :class:`SensorTransmitter` — the nodes' side (``sdo serve --gateway --pdo``): a thread
  takes sensor ``s``'s sample ``k`` at ``epoch + phase + k * period`` (monotonic clock,
  each sensor at its own rate) and sends it as the model's TPDOs
  (:func:`~lolacli.devices.can.sample_frames`: the REAL32 values of
  :func:`~lolacli.devices.can.sample_values` in order, at most 8 bytes a frame, COB-IDs
  :func:`~lolacli.devices.can.tpdo_cob_id`). A sample the thread is too late for is
  skipped (counted), as a sensor's clock does not wait either.
* :class:`SensorBridge` — the gateway's side (``bus emulate --can``): python-can's
  Notifier thread hands every frame to :class:`~lolacli.devices.can.LiveSamples` at its
  arrival (monotonic), which the emulated gateway's cycle takes in (sample and hold) and
  which measures each sensor's age at the master.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from lolacli.devices.can import CanConfig, LiveSamples, sample_frames, sample_values
from lolacli.errors import TransportError
from lolacli.sdo.canopen_client import NOTIFIER_CYCLE_S, open_bus, quiet_canopen

#: the longest a transmitter waits at once, so that :meth:`SensorTransmitter.close` is
#: quick
WAIT_SLICE_S = 0.05


class SensorTransmitter:
    """The sensors of ``config`` sending their samples as TPDOs through ``send(cob_id,
    data)`` (canopen's ``Network.send_message``, which locks the bus) from
    :meth:`start` until :meth:`close`; sample instants count from ``epoch_ns`` on the
    ``clock`` (monotonic ns). :attr:`sent` and :attr:`skipped` per sensor;
    :attr:`error`: why sending stopped (a bus that went away), else None."""

    def __init__(
        self,
        send: Callable[[int, bytes], None],
        config: CanConfig,
        epoch_ns: int,
        *,
        clock: Callable[[], int] = time.monotonic_ns,
    ) -> None:
        config.check_rates()
        self.send = send
        self.config = config
        self.epoch_ns = epoch_ns
        self.clock = clock
        n = len(config.sensors)
        self.sent = [0] * n
        self.skipped = [0] * n
        self.error: str | None = None
        self._next = [0] * n  # the next sample to take
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lolacli-tpdo", daemon=True)

    def start(self) -> SensorTransmitter:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=1.0)

    def _run(self) -> None:
        sensors, nxt = self.config.sensors, self._next
        due = [self.epoch_ns + s.sample_ns(0) for s in sensors]
        while not self._stop.is_set():
            now = self.clock()
            first = min(due)
            if first > now:
                self._stop.wait(min((first - now) / 1e9, WAIT_SLICE_S))
                continue
            for i, s in enumerate(sensors):
                if due[i] > now:
                    continue
                k = (now - self.epoch_ns - s.phase_ns) // s.period_ns  # the latest due
                self.skipped[i] += k - nxt[i]
                values = sample_values(s, s.sample_ns(k))
                try:
                    for cob_id, data in sample_frames(self.config, i, values):
                        self.send(cob_id, data)
                except Exception as exc:  # can.CanError, OSError: the bus went away
                    self.error = f"cannot send the {s.name}'s TPDO: {exc}"
                    return
                self.sent[i] += 1
                nxt[i] = k + 1
                due[i] = self.epoch_ns + s.sample_ns(k + 1)

    def report(self) -> list[dict[str, Any]]:
        """Per sensor: name, node ID, rate (Hz), samples sent and skipped."""
        return [
            {"name": s.name, "node_id": s.node_id, "rate_hz": s.rate_hz,
             "samples_sent": self.sent[i], "samples_skipped": self.skipped[i]}
            for i, s in enumerate(self.config.sensors)
        ]


class SensorBridge:
    """The gateway's CAN side: a python-can bus on ``channel`` (``interface``; or
    ``bus``) whose frames python-can's Notifier thread hands to ``live`` as they arrive,
    until :meth:`close` (the thread stopped, the bus shut down). TransportError when the
    bus cannot be opened, UsageError for an unknown interface; :attr:`error`: why
    receiving stopped early, else None."""

    def __init__(
        self,
        channel: str,
        live: LiveSamples,
        *,
        interface: str | None = None,
        bus: Any = None,
        **bus_options: Any,
    ) -> None:
        import can

        quiet_canopen()  # python-can's own log lines too
        self.live = live
        self.where = f"{interface or 'CAN'} {channel}"
        self.error: str | None = None
        self.bus = bus if bus is not None else open_bus(channel, interface, **bus_options)
        bridge, clock = self, live.clock

        class _Receiver(can.Listener):
            def on_message_received(self, msg: can.Message) -> None:
                now = clock()  # its arrival at the gateway
                if msg.is_error_frame or msg.is_remote_frame:
                    live.ignored += 1
                    return
                live.frame(msg.arbitration_id, bytes(msg.data), now, extended=msg.is_extended_id)

            def on_error(self, exc: Exception) -> None:
                # said by the caller (one line, exit 4), not as a thread's traceback; the
                # Notifier tries again: not too often
                bridge.error = f"CAN bus {bridge.where}: {exc}"
                time.sleep(NOTIFIER_CYCLE_S)

        try:
            self.notifier = can.Notifier(self.bus, [_Receiver()], timeout=NOTIFIER_CYCLE_S)
        except Exception as exc:
            self.bus.shutdown()
            raise TransportError(f"CAN bus {self.where}: {exc}") from None

    def close(self) -> None:
        try:
            self.notifier.stop(timeout=1.0)
        finally:
            try:
                self.bus.shutdown()
            except Exception:  # a bus that failed half-way: nothing left to close
                pass

    def __enter__(self) -> SensorBridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["SensorBridge", "SensorTransmitter"]
