"""The ENI-driven EtherCAT master and the seed's Bus Variables middleware.

* :class:`Master` (:mod:`lolacli.master.core`): InitCmds per transition, cyclic frames,
  WKC, distributed clocks; mailbox and CoE SDO (:mod:`lolacli.master.mailbox`).
* :class:`Transport` (:mod:`lolacli.master.transport`): the one seam to a bus —
  :class:`ChainTransport` (an in-process chain, virtual time) or
  :class:`RawSocketTransport` (a network interface, real time).
* Bus Variables (:mod:`lolacli.master.variables`) and device abstraction classes
  (:mod:`lolacli.master.slaves`).

The master imports nothing of :mod:`lolacli.emulator`; :mod:`lolacli.simulate` (the layer
above both) composes the two for ``lolacli bus simulate``, the ``sdo`` commands and tests.
"""

from lolacli.master.core import Master, MasterOptions, MasterStats, Refusal
from lolacli.master.mailbox import MailboxClient, SdoClient
from lolacli.master.slaves import BusSlave, Cia402Drive, ForceTorqueSensor, Imu, bus_field
from lolacli.master.transport import ChainTransport, RawSocketTransport, Received, Transport
from lolacli.master.variables import (
    BusBool,
    BusBytes,
    BusInt8,
    BusInt16,
    BusInt32,
    BusInt64,
    BusReal32,
    BusReal64,
    BusUInt8,
    BusUInt16,
    BusUInt32,
    BusUInt64,
    BusVariable,
    ProcessImage,
    Snapshot,
)

__all__ = [
    "BusBool",
    "BusBytes",
    "BusInt8",
    "BusInt16",
    "BusInt32",
    "BusInt64",
    "BusReal32",
    "BusReal64",
    "BusSlave",
    "BusUInt8",
    "BusUInt16",
    "BusUInt32",
    "BusUInt64",
    "BusVariable",
    "ChainTransport",
    "Cia402Drive",
    "ForceTorqueSensor",
    "Imu",
    "MailboxClient",
    "Master",
    "MasterOptions",
    "MasterStats",
    "ProcessImage",
    "RawSocketTransport",
    "Received",
    "Refusal",
    "SdoClient",
    "Snapshot",
    "Transport",
    "bus_field",
]
