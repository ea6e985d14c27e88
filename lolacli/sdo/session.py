"""Pick the transport from the options and hand out one client per SLAVE.

========================  =================================================================
options                   transport
========================  =================================================================
``--can CH [--interface`` CANopen through canopen + python-can; SLAVE is the node ID
``NAME] [--node N]``
(none)                    lolacli's own master against the emulated chain of ``--eni`` (default:
                          the embedded LOLA chain) in this process, in virtual time; ``--esi``
                          devices give the emulated slaves their SII as in ``bus emulate``
``--iface IF``            lolacli's own master on a live bus (a ``bus emulate`` at the other
                          end of a veth pair, or hardware) through a raw socket; configured by
                          ``--eni``, else from the slaves' SII (as SOEM does)
``--iface IF --backend``  EtherCAT through pysoem (SOEM) on a live bus
``soem``
========================  =================================================================

Our master brings only the slaves asked for to PREOP, each when first asked for
(:class:`lolacli.master.preop.PreopBus`).

Each target carries the sources of its value types and names, in the one order of
:mod:`lolacli.od.lookup`: ``--eds`` (CANopen), ``--esi`` (EtherCAT: the device whose
identity the slave reports) and the slave's PDO entries in the ENI, then the slave's SDO
Information (our master), then the CiA 301 objects.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lolacli.errors import UsageError
from lolacli.od import Dictionary
from lolacli.od.lookup import TypeLookup
from lolacli.sdo.address import parse_node_id, resolve_ref, slave_refs
from lolacli.sdo.client import SdoClient

BACKENDS = ("lolacli", "soem")


@dataclass(frozen=True)
class TransportOptions:
    can: str | None = None
    interface: str | None = None
    node: int | None = None
    iface: str | None = None
    backend: str = "lolacli"
    eni: Path | None = None
    eds: Path | None = None
    esi: tuple[Path, ...] = ()
    timeout_s: float = 1.0
    can_options: dict[str, Any] = field(default_factory=dict)


@dataclass
class Target:
    """One slave: the label the output calls it by, its client, and the sources of its
    entries' types and names (``lookup``: the dictionaries given or known for it, then
    the client's SDO Information, then CiA 301)."""

    label: str
    client: SdoClient
    dictionaries: tuple[Dictionary, ...] = ()
    lookup: TypeLookup = field(init=False)

    def __post_init__(self) -> None:
        self.lookup = TypeLookup(self.dictionaries, self.client.sdo_info())

    @property
    def dictionary(self) -> Dictionary | None:
        """The dictionary file (EDS, ESI) given for the slave, for ``sdo list``."""
        return next((d for d in self.dictionaries if d.source in ("eds", "esi")), None)


class Session:
    """An open transport. :meth:`target` resolves SLAVE; :meth:`close` releases it all."""

    def target(self, spec: str | int) -> Target:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class CanSession(Session):
    def __init__(self, options: TransportOptions) -> None:
        from lolacli.sdo.canopen_client import CanopenNetwork
        from lolacli.sdo.files import load_eds

        assert options.can is not None
        self.options = options
        self._eds_path = options.eds
        self._dictionaries: dict[int, Dictionary] = {}
        if options.eds is not None:  # a bad EDS fails before any bus is opened
            first = options.node or 1
            self._dictionaries[first] = load_eds(options.eds, first)
        self._load_eds = load_eds
        self.network = CanopenNetwork(
            options.can,
            interface=options.interface,
            timeout_s=options.timeout_s,
            **options.can_options,
        )

    def target(self, spec: str | int) -> Target:
        node = parse_node_id(spec)
        if self.options.node is not None and self.options.node != node:
            raise UsageError(
                f"SLAVE {spec!r} and --node {self.options.node} name different nodes "
                "(on CANopen SLAVE is the node ID)"
            )
        return Target(str(node), self.network.client(node), self._dictionary(node))

    def _dictionary(self, node: int) -> tuple[Dictionary, ...]:
        if self._eds_path is None:
            return ()
        if node not in self._dictionaries:  # $NODEID defaults differ per node
            self._dictionaries[node] = self._load_eds(self._eds_path, node)
        return (self._dictionaries[node],)

    def close(self) -> None:
        self.network.close()


class SoemSession(Session):
    def __init__(self, options: TransportOptions) -> None:
        from lolacli.files import load_eni, load_esi
        from lolacli.sdo.soem_client import SoemBus

        assert options.iface is not None
        self.eni = load_eni(options.eni) if options.eni is not None else None
        self.esi = [load_esi(p) for p in options.esi]
        self.bus = SoemBus(options.iface, timeout_s=options.timeout_s)

    def target(self, spec: str | int) -> Target:
        from lolacli.eni.dictionary import from_eni
        from lolacli.sdo.files import esi_dictionary

        on_bus = self.bus.slaves()
        if self.eni is not None:
            ref = resolve_ref(spec, slave_refs(self.eni), source=self.eni.source or "the ENI")
        else:
            ref = resolve_ref(spec, on_bus, source=self.bus.iface)
        client = self.bus.client(ref.position, ref.name)
        identity = on_bus[ref.position - 1].identity if ref.position <= len(on_bus) else None
        dictionaries = [esi_dictionary(self.esi, identity) if self.esi else None]
        if self.eni is not None:
            dictionaries.append(from_eni(self.eni.slaves[ref.position - 1], self.eni.source))
        return Target(str(spec).strip(), client, tuple(d for d in dictionaries if d is not None))

    def close(self) -> None:
        self.bus.close()


class LolaSession(Session):
    """lolacli's own master: the emulated chain in process (no ``--iface``) or a live bus."""

    def __init__(self, options: TransportOptions) -> None:
        from lolacli.files import load_eni, load_esi
        from lolacli.sdo.lola_client import LolaBus

        self.esi = [load_esi(p) for p in options.esi]
        if options.iface is None:
            from lolacli.simulate import VirtualBus

            eni = load_eni(options.eni if options.eni is not None else default_eni())
            virtual = VirtualBus(eni, esi=self.esi)
            name = Path(eni.source).name if eni.source else "ENI"
            self.source = f"the emulated chain ({name})"  # its errors name the slave only
            self.bus = LolaBus(virtual.transport, eni, where="", timeout_s=options.timeout_s)
        else:
            from lolacli.master.transport import RawSocketTransport

            config = load_eni(options.eni) if options.eni is not None else None
            transport = RawSocketTransport(options.iface)  # TransportError: exit 4
            self.source = config.source if config is not None else options.iface
            self.bus = LolaBus(
                transport,
                config,
                where=f"on {options.iface}",
                name=options.iface,
                timeout_s=options.timeout_s,
            )

    def target(self, spec: str | int) -> Target:
        from lolacli.eni.dictionary import from_eni

        ref = resolve_ref(spec, self.bus.slaves(), source=self.source)
        client = self.bus.client(ref)
        dictionaries = []
        if self.esi:
            from lolacli.sdo.files import esi_dictionary

            dictionaries.append(esi_dictionary(self.esi, ref.identity))
        eni = self.bus.eni
        dictionaries.append(from_eni(eni.slaves[ref.position - 1], eni.source or ""))
        return Target(str(spec).strip(), client, tuple(d for d in dictionaries if d is not None))

    def close(self) -> None:
        self.bus.close()


def default_eni() -> Path:
    """The embedded LOLA chain (``lolacli/eni_examples/lola.xml``)."""
    import lolacli.eni_examples

    return Path(lolacli.eni_examples.__file__).resolve().parent / "lola.xml"


def open_session(options: TransportOptions) -> Session:
    """The transport the options ask for; UsageError when they ask for none that exists."""
    if options.backend not in BACKENDS:
        raise UsageError(f"unknown --backend {options.backend!r} (one of {', '.join(BACKENDS)})")
    if options.can is not None:
        if options.iface is not None:
            raise UsageError("--can and --iface exclude each other (CANopen or EtherCAT)")
        if options.esi or options.eni is not None:
            raise UsageError("--esi/--eni describe EtherCAT slaves; a CANopen node takes --eds")
        return CanSession(options)
    if options.eds is not None:
        raise UsageError("--eds describes a CANopen node: give --can CHANNEL too")
    if options.interface is not None or options.node is not None:
        raise UsageError("--interface and --node are CANopen options: give --can CHANNEL too")
    if options.backend == "soem":
        if options.iface is None:
            raise UsageError("--backend soem drives a live bus: give --iface IF too")
        return SoemSession(options)
    return LolaSession(options)


__all__ = [
    "BACKENDS",
    "CanSession",
    "LolaSession",
    "Session",
    "SoemSession",
    "Target",
    "TransportOptions",
    "default_eni",
    "open_session",
]
