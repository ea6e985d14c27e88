"""The emulated chain of an ENI behind the master's in-process transport, in virtual time.

:class:`VirtualBus` is the one place where :mod:`lolacli.master` meets
:mod:`lolacli.emulator`: it builds the chain of an ENI with the faults asked for
(:func:`lolacli.emulator.run.make_chain`) and puts it behind a
:class:`~lolacli.master.transport.ChainTransport`, whose clock jumps to whatever the
master waits for. ``bus simulate`` (:func:`lolacli.simulate.simulate`), the ``sdo``
commands' in-process transport and the tests use it::

    bus = VirtualBus(load_eni("lolacli/eni_examples/lola.xml"))
    master = Master(bus.eni, bus.transport)
    master.bring_up()
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from lolacli.emulator.run import EmulateOptions, arm_link_loss, make_chain
from lolacli.eni.model import Eni
from lolacli.master.transport import ChainTransport

if TYPE_CHECKING:
    from lolacli.eni.esi import EsiFile
    from lolacli.timing.model import HostLatency


class VirtualBus:
    """The emulated chain of ``eni`` (faults: ``faults``; SII images from ``esi`` devices
    as in ``bus emulate``) behind a :class:`ChainTransport` (see the module docstring).
    ``host_latency``: every returning frame also waits the master host's latency, a
    draw a frame seeded with ``faults.seed``
    (:class:`~lolacli.simulate.variation.HostLatencyLine`). UsageError for faults at
    positions the ENI does not have, EniError for an ENI without slaves."""

    def __init__(
        self,
        eni: Eni,
        faults: EmulateOptions | None = None,
        *,
        esi: Sequence[EsiFile] = (),
        host_latency: HostLatency | None = None,
    ) -> None:
        self.eni = eni
        self.faults = faults or EmulateOptions()
        self.chain = make_chain(eni, self.faults, esi=esi)
        if host_latency is None:
            self.transport = ChainTransport(self.chain)
        else:
            from lolacli.simulate.variation import HostLatencyLine

            line = HostLatencyLine(self.chain, host_latency, self.faults.seed)
            self.transport = ChainTransport(line)

    def now_ns(self) -> int:
        return self.transport.now_ns()

    def arm_faults(self) -> None:
        """Start the clock of the faults timed from the run's start (a link cut T seconds
        in): from now on."""
        arm_link_loss(self.chain, self.faults, self.transport.now_ns())


__all__ = ["EmulateOptions", "VirtualBus"]
