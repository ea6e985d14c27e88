"""What an ENI says of a slave's objects, as the one dictionary model (source ``eni``).

* ``<RxPdo>``/``<TxPdo>`` entries: index, subindex, name, data type (its IEC or CiA
  name, :func:`lolacli.wire.datatypes.data_type_from_name`; None when it is none of
  them) and bit size; PDO-mappable. An object of entries after sub 0 is a RECORD whose
  own name the ENI does not give.
* with ``init_cmds``, the CoE ``<InitCmd>`` downloads of the slave's mailbox (not the
  complete-access ones: their entries' sizes are not in the ENI): index, subindex, the
  bytes written as the value (so their size), the command's ``<Comment>`` as the name,
  no data type (the ENI gives none). The emulated devices create such objects; the
  ``sdo`` commands' type lookup leaves them out (a comment names the command, "download
  sm (1C12) pdo entries", not the object).

Access is not known from an ENI (``""``).
"""

from __future__ import annotations

from lolacli.eni.model import Slave
from lolacli.od.model import RECORD, VAR, Dictionary, OdEntry, OdObject
from lolacli.wire.datatypes import data_type_from_name


def from_eni(slave: Slave, path: str = "", *, init_cmds: bool = False) -> Dictionary | None:
    """The objects the ENI describes for ``slave`` (see the module); None when none."""
    found: dict[int, dict[int, OdEntry]] = {}
    for pdo in slave.pdos:
        for e in pdo.entries:
            if e.index == 0:  # a gap in the PDO
                continue
            kind = data_type_from_name(e.data_type) if e.data_type else None
            entry = OdEntry(e.index, e.subindex, e.name, kind, "", e.bit_size or None, b"", True)
            found.setdefault(e.index, {}).setdefault(e.subindex, entry)
    if init_cmds and slave.mailbox is not None:
        for cmd in slave.mailbox.coe_init_cmds:
            if cmd.ccs != 1 or cmd.complete_access or not cmd.data:
                continue
            entry = OdEntry(
                cmd.index, cmd.subindex, cmd.comment, None, "", 8 * len(cmd.data), cmd.data
            )
            found.setdefault(cmd.index, {}).setdefault(cmd.subindex, entry)
    if not found:
        return None
    objects = []
    for index in sorted(found):
        entries = [found[index][s] for s in sorted(found[index])]
        if len(entries) == 1 and entries[0].subindex == 0:
            objects.append(OdObject.of(index, entries[0].name, VAR, entries))
        else:
            objects.append(OdObject.of(index, "", RECORD, entries))
    return Dictionary(objects, "eni", path)


__all__ = ["from_eni"]
