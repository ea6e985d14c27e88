"""SDO over CANopen: canopen's SDO client on a python-can bus (any interface by name).

``python-can`` opens the bus (``socketcan``, ``pcan``, ``kvaser``, … and, on hosts without
CAN hardware, ``virtual`` within one process or ``udp_multicast`` between processes);
``canopen``'s :class:`~canopen.RemoteNode` runs expedited and segmented transfers.
The node is given an empty object dictionary so that canopen hands back the bytes as
the node sent them; value types are :mod:`lolacli.sdo.client`'s business.
"""

from __future__ import annotations

import logging
from typing import Any

from lolacli.errors import TransportError, UsageError
from lolacli.od import Dictionary
from lolacli.sdo.client import abort_error
from lolacli.text import number

#: The group python-can's udp_multicast uses for IPv4 (its default is an IPv6 group).
UDP_MULTICAST_IPV4 = "239.74.163.2"
NOTIFIER_CYCLE_S = 0.02


def quiet_canopen() -> None:
    """canopen logs timeouts and aborts as warnings/errors; without a handler Python
    prints them on stderr. lolacli reports them itself."""
    for name in ("canopen", "can"):
        logger = logging.getLogger(name)
        if not logger.handlers:
            logger.addHandler(logging.NullHandler())
        logger.propagate = False


def open_bus(channel: str, interface: str | None, **options: Any) -> Any:
    """A python-can bus; UsageError for an unknown interface, TransportError if it cannot
    be opened (no such device, no permission)."""
    import can

    kwargs: dict[str, Any] = dict(options)
    if interface:
        kwargs["interface"] = interface
    try:
        return can.Bus(channel=channel, **kwargs)
    except (can.CanInterfaceNotImplementedError, NotImplementedError) as exc:
        raise UsageError(f"python-can interface {interface!r}: {exc}") from None
    except ImportError as exc:
        raise TransportError(
            f"python-can interface {interface!r} needs {exc.name}: {exc}"
        ) from None
    except (can.CanError, OSError, ValueError) as exc:
        where = f"{interface or 'default'} {channel}"
        raise TransportError(f"cannot open CAN bus {where}: {exc}") from None


class CanopenNetwork:
    """A CAN bus with canopen's network on it; :meth:`client` gives one node's SDO client."""

    def __init__(
        self,
        channel: str,
        *,
        interface: str | None = None,
        timeout_s: float = 1.0,
        bus: Any = None,
        **bus_options: Any,
    ) -> None:
        import canopen

        quiet_canopen()
        self.where = f"{interface or 'CAN'} {channel}"
        self.timeout_s = timeout_s
        self.bus = bus if bus is not None else open_bus(channel, interface, **bus_options)
        self.network = canopen.Network(self.bus)
        # the notifier thread polls the bus this often; closing waits for it (canopen's
        # 1 s default would add up to a second to every command)
        self.network.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
        self.network.connect()
        self._clients: dict[int, CanopenClient] = {}

    def client(self, node_id: int) -> CanopenClient:
        if node_id not in self._clients:
            self._clients[node_id] = CanopenClient(self, node_id)
        return self._clients[node_id]

    def close(self) -> None:
        try:
            self.network.disconnect()  # stops the notifier, shuts the bus down
        except Exception:  # a bus that failed half-way: nothing left to close
            pass

    def __enter__(self) -> CanopenNetwork:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class CanopenClient:
    """One CANopen node's SDO server (CiA 301 §7.2.4) through canopen + python-can."""

    def __init__(self, network: CanopenNetwork, node_id: int) -> None:
        import canopen

        self.network = network
        self.node_id = node_id
        self.description = f"node {node_id} on {network.where}"
        self.node = canopen.RemoteNode(node_id, canopen.ObjectDictionary())  # type: ignore[no-untyped-call]
        network.network.add_node(self.node)
        self.node.sdo.RESPONSE_TIMEOUT = network.timeout_s
        self.node.sdo.MAX_RETRIES = 1

    def upload(self, index: int, subindex: int, *, complete_access: bool = False) -> bytes:
        _no_complete_access(complete_access)
        return bytes(self._call(index, subindex, self.node.sdo.upload, index, subindex))

    def download(
        self, index: int, subindex: int, data: bytes, *, complete_access: bool = False
    ) -> None:
        _no_complete_access(complete_access)
        self._call(index, subindex, self.node.sdo.download, index, subindex, bytes(data))

    def dictionary(self) -> Dictionary | None:
        return None  # CANopen has no SDO Information service: the EDS is the dictionary

    def sdo_info(self) -> None:
        return None

    def close(self) -> None:
        self.network.close()

    def _call(self, index: int, subindex: int, fn: Any, *args: Any) -> Any:
        from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

        try:
            return fn(*args)
        except SdoAbortedError as exc:
            raise abort_error(index, subindex, exc.code) from None
        except SdoCommunicationError as exc:
            raise TransportError(
                f"0x{index:04X}:{subindex:02X}: {self.description}: {_reason(exc)} "
                f"(timeout {number(self.network.timeout_s, 's')})"
            ) from None
        except Exception as exc:  # can.CanError and OSError while sending
            raise TransportError(f"{self.description}: {exc}") from None


def _reason(exc: Exception) -> str:
    text = str(exc)
    return "no answer" if text == "No SDO response received" else text


def _no_complete_access(complete_access: bool) -> None:
    if complete_access:
        raise UsageError("complete access is an EtherCAT (CoE) service; CANopen has none")


__all__ = ["UDP_MULTICAST_IPV4", "CanopenClient", "CanopenNetwork", "open_bus"]
