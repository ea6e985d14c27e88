"""An emulated slave: ESC + device + CoE server, and a chain built from an ENI.

:func:`build_chain` is the one call that turns an ENI model into a running line of
slaves: for each ENI slave an SII image (:mod:`lolacli.emulator.sii`), a device model
(:func:`lolacli.devices.device_for`) and, for mailbox slaves, an SDO server.
"""

from __future__ import annotations

from collections.abc import Callable

from lolacli.devices import device_for
from lolacli.devices.base import Device
from lolacli.emulator.chain import Chain, ChainTiming, Faults
from lolacli.emulator.coe_server import SdoServer
from lolacli.emulator.esc import DcClock, Esc
from lolacli.emulator.registers import AlState
from lolacli.emulator.sii import sii_from_slave
from lolacli.eni.model import Eni, Slave


class SlaveApplication:
    """The PDI side of one ESC: a device and its SDO server (implements EscApplication)."""

    def __init__(self, device: Device, mailbox_in_bytes: int) -> None:
        self.device = device
        self.sdo = SdoServer(device.od, mailbox_in_bytes) if mailbox_in_bytes else None
        self.has_coe = mailbox_in_bytes > 0
        # called before Python uses the device: the chain's C core, which may hold the
        # device's state between cycles, gives it back (lolacli.emulator.core)
        self.before_use: Callable[[], None] | None = None

    def mailbox_request(self, request: bytes) -> list[bytes]:
        if self.before_use is not None:
            self.before_use()
        return self.sdo.handle(request) if self.sdo is not None else []

    def process_data_bytes(self) -> tuple[int, int]:
        return self.device.process_data_bytes()

    def state_changed(self, state: AlState) -> None:
        if self.before_use is not None:
            self.before_use()
        self.device.state_changed(int(state))

    def cycle(self, outputs: bytes, t_ns: int) -> bytes:
        if self.before_use is not None:
            self.before_use()
        return self.device.cycle(outputs, t_ns)


def build_slave(slave: Slave, *, drift_ppb: int = 0, start_ns: int = 0) -> Esc:
    """The ESC of one ENI slave with its device behind it."""
    sii = sii_from_slave(slave, complete_access=True)  # real CiA 402 drives offer it
    device = device_for(slave)
    mailbox_in = slave.mailbox.in_length_bytes if slave.mailbox is not None else 0
    app = SlaveApplication(device, mailbox_in)
    return Esc(sii, app=app, clock=DcClock(start_ns=start_ns, drift_ppb=drift_ppb))


def build_chain(
    eni: Eni,
    *,
    timing: ChainTiming | None = None,
    faults: Faults | None = None,
    drift_ppb: int = 0,
    engine: str | None = None,
) -> Chain:
    """All slaves of ``eni`` in line order. ``drift_ppb`` spreads clock rates along the
    line (slave i runs ``i × drift_ppb`` fast) so DC has something to correct; ``engine``
    as :func:`~lolacli.emulator.chain.chain_engine` takes it."""
    slaves = [
        build_slave(s, drift_ppb=i * drift_ppb, start_ns=i * 1_234_567)
        for i, s in enumerate(eni.slaves)
    ]
    return Chain(slaves, timing=timing, faults=faults, engine=engine)


def device_of(esc: Esc) -> Device | None:
    app = esc.app
    return app.device if isinstance(app, SlaveApplication) else None
