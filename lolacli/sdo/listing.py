"""``sdo list``: a slave's object dictionary, from the slave or from its description file.

Which objects are listed: an EDS given with ``--eds`` (CANopen has no SDO Information
service); on EtherCAT the slave's SDO Information service, else the ``--esi`` device
matching the slave's identity. With no transport, the file alone (``--esi`` with
``--eni`` to pick the device by SLAVE's identity).

Each entry's type and name come from the one lookup of every ``sdo`` command
(:meth:`lolacli.od.lookup.TypeLookup.entry_type`), the listed dictionary taking the
place of its source in it, so that ``sdo list`` and ``sdo read`` say the same of an entry.
"""

from __future__ import annotations

from typing import Any

from lolacli.errors import UsageError
from lolacli.od import Dictionary, OdEntry
from lolacli.od.lookup import EntryType, TypeLookup
from lolacli.sdo.client import json_value
from lolacli.sdo.session import TransportOptions, open_session
from lolacli.text import plural


def dictionary_report(
    slave: str, dictionary: Dictionary, lookup: TypeLookup | None = None
) -> dict[str, Any]:
    """The report of ``sdo list`` over ``dictionary``'s objects; types and names by
    ``lookup`` (default: the dictionary, then CiA 301)."""
    if lookup is None:
        lookup = TypeLookup((dictionary,))
    return {
        "schema": "lolacli.sdo-list/1",
        "slave": slave,
        "source": dictionary.source,
        "path": dictionary.path or None,
        "objects": [
            {
                "index": o.index,
                "object": f"0x{o.index:04X}",
                "name": o.name,
                "object_code": o.object_code.name,
                "entries": [_entry(e, lookup.entry_type(e.index, e.subindex)) for e in o],
            }
            for o in dictionary
        ],
    }


def _entry(e: OdEntry, typed: EntryType) -> dict[str, Any]:
    return {
        "subindex": e.subindex,
        "object": typed.address,
        "name": typed.name or None,
        "data_type": typed.type_label or None,
        "type_source": typed.source or None,
        "access": e.access or None,
        "bit_size": e.bit_size,
        "default": json_value(e.default),
        "pdo_mapping": e.pdo_mapping,
    }


def list_dictionary(slave: str, options: TransportOptions) -> dict[str, Any]:
    """The report of ``sdo list`` (schema ``lolacli.sdo-list/1``)."""
    if options.eds is not None:
        from lolacli.sdo.address import parse_node_id
        from lolacli.sdo.files import load_eds

        node = parse_node_id(slave)
        return dictionary_report(str(node), load_eds(options.eds, node))
    if options.can is None and options.iface is None and options.esi:
        label, offline, more = _offline_esi(slave, options)
        return dictionary_report(label, offline, TypeLookup((offline, *more)))
    with open_session(options) as session:
        target = session.target(slave)
        info = target.client.dictionary()  # the SDO Information service, read whole
        listed = info or target.dictionary
        if listed is None:
            if options.can is not None:
                raise UsageError("CANopen has no SDO Information service: give --eds FILE")
            raise UsageError(
                f"slave {slave} has no SDO Information service and no --esi describes it: "
                "give --esi FILE"
            )
        # SDO Information read whole (or found missing): not asked again entry by entry
        lookup = TypeLookup(target.dictionaries, info)
        return dictionary_report(target.label, listed, lookup)


def _offline_esi(
    slave: str, options: TransportOptions
) -> tuple[str, Dictionary, tuple[Dictionary, ...]]:
    """The dictionary ``sdo list --esi`` shows without a bus, and the label it goes by: the
    ENI slave's device when ``--eni`` names the slave (and the ENI's PDO entries of it,
    the next source of types), else the ESI's only device with a dictionary (SLAVE is
    not on any bus then: the label says which device it is)."""
    from lolacli.eni.dictionary import from_eni
    from lolacli.errors import InputError
    from lolacli.files import load_eni, load_esi
    from lolacli.sdo.address import resolve_slave
    from lolacli.sdo.files import esi_dictionary

    files = [load_esi(p) for p in options.esi]
    with_od = [(f, d) for f in files for d in f.devices if d.dictionary is not None]
    names = ", ".join(str(p) for p in options.esi)
    if not with_od:
        raise InputError(
            "no device in it has an object dictionary (no <Profile><Dictionary>): "
            "sdo list needs one, or a bus's SDO Information",
            path=names,
        )
    if options.eni is not None:
        eni = load_eni(options.eni)
        target = resolve_slave(slave, eni)
        found = esi_dictionary(files, target.identity)
        if found is None:
            i = target.identity
            ident = (
                f"vendor 0x{i.vendor_id:08X}, product 0x{i.product_code:08X}, "
                f"revision 0x{i.revision:08X}"
                if i is not None
                else "no identity in the ENI"
            )
            raise UsageError(
                f"slave {slave} ({target.name}: {ident}) is not a device of {names} "
                "that has a dictionary"
            )
        mapped = from_eni(eni.slaves[target.position - 1], eni.source or "")
        return f"{slave} {target.name}", found, (mapped,) if mapped is not None else ()
    if len(with_od) > 1:
        shown = "; ".join(
            f"{d.name[:40]} (product 0x{d.identity.product_code:08X}, "
            f"revision 0x{d.identity.revision:08X})"
            for _, d in with_od[:3]
        )
        more = f"; {len(with_od) - 3} more" if len(with_od) > 3 else ""
        raise UsageError(
            f"{names} describes {plural(len(with_od), 'device')} with a dictionary "
            f"({shown}{more}): "
            "give --eni FILE so SLAVE picks one"
        )
    found = esi_dictionary(files, None)
    assert found is not None
    return f"{with_od[0][1].name} (ESI, no bus)", found, ()


__all__ = ["dictionary_report", "list_dictionary"]
