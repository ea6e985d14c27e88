"""Write an ENI model (:mod:`lolacli.eni.model`) as ETG.2100 XML: the subset our parser reads.

Pure: an :class:`~lolacli.eni.model.Eni` in, UTF-8 XML bytes out. The contract is the
round trip ``parse_eni(write_eni(parse_eni(f))) == parse_eni(f)`` (the ``source`` aside)
for every ENI the parser reads; elements the parser does not read are not written.

Elements follow the schema's order (``<Config>``: ``<Master>``, ``<Slave>``…, ``<Cyclic>``…,
``<ProcessImage>``; a slave's ``<Info>``, ``<ProcessData>``, ``<Mailbox>``, ``<InitCmds>``,
``<PreviousPort>``, ``<DC>``). Numbers are decimal except identities, indexes and
register offsets, written ``#x…`` as the exports do; data is hex.

What the parser derives is written in the form it derives it from: sync managers and
FMMUs that InitCmds configure stay in the InitCmds (a sync manager no InitCmd writes is a
``<SmN>`` of ``<ProcessData>``, its kind a ``<Type>``); a PDO's sync manager is its
``Sm`` attribute. PDOs are written in model order, RxPDOs as ``<RxPdo>`` and TxPDOs as
``<TxPdo>`` (the parser reads all RxPDOs first: a model from the parser keeps its order).
"""

from __future__ import annotations

from decimal import Decimal
from typing import Any

from lolacli.eni.model import (
    CoeInitCmd,
    Cyclic,
    CyclicCommand,
    CyclicFrame,
    Direction,
    DistributedClock,
    Eni,
    InitCmd,
    Mailbox,
    Master,
    Pdo,
    ProcessImage,
    Slave,
    Variable,
)

_El = Any  # an lxml element


def write_eni(eni: Eni) -> bytes:
    """``eni`` as ENI XML (UTF-8, with declaration, indented)."""
    from lxml import etree

    from lolacli.eni.parser import sync_managers_from_init_cmds

    root = etree.Element(eni.root or "EtherCATConfig")
    config = _sub(root, "Config")
    _master(config, eni.master)
    for slave in eni.slaves:
        written = {sm.index for sm in sync_managers_from_init_cmds(slave.init_cmds)}
        _slave(config, slave, written)
    for task in eni.cyclic:
        _cyclic(config, task)
    _process_image(config, eni.process_image)
    etree.indent(root, space="  ")
    out: bytes = etree.tostring(root, xml_declaration=True, encoding="UTF-8")
    return out + b"\n"


# ----------------------------------------------------------------------------- helpers


def _sub(parent: _El, tag: str, text: str | None = None, **attrs: str) -> _El:
    from lxml import etree

    el = etree.SubElement(parent, tag, attrs)
    if text is not None:
        el.text = text
    return el


def _hex(value: int, digits: int = 4) -> str:
    return f"#x{value:0{digits}x}"


def _num(parent: _El, tag: str, value: int | None) -> None:
    if value is not None:
        _sub(parent, tag, str(value))


def _text(parent: _El, tag: str, text: str) -> None:
    if text:
        _sub(parent, tag, text)


def _us(ns: int) -> str:
    """Nanoseconds as the µs decimal of ``<CycleTime>`` (exact)."""
    return format((Decimal(ns) / 1000).normalize(), "f")


# ----------------------------------------------------------------------------- master


def _master(config: _El, master: Master) -> None:
    el = _sub(config, "Master")
    info = _sub(el, "Info")
    _sub(info, "Name", master.name)
    _sub(info, "Destination", master.destination_mac.hex())
    _sub(info, "Source", master.source_mac.hex())
    _sub(info, "EtherType", master.ethertype.to_bytes(2, "little").hex())
    if master.cycle_time_ns is not None:
        _sub(el, "CycleTime", _us(master.cycle_time_ns))
    _init_cmds(el, master.init_cmds)


def _init_cmds(parent: _El, cmds: tuple[InitCmd, ...]) -> None:
    if not cmds:
        return
    el = _sub(parent, "InitCmds")
    for c in cmds:
        _init_cmd(el, c)


def _init_cmd(parent: _El, c: InitCmd) -> None:
    el = _sub(parent, "InitCmd")
    _text(el, "Comment", c.comment)
    for t in c.transitions:
        _sub(el, "Transition", t)
    if c.requires:
        _sub(el, "Requires", c.requires)
    _num(el, "Cmd", c.cmd)
    if c.logical_address is not None:
        _num(el, "Addr", c.logical_address)
    else:
        _num(el, "Adp", c.adp)
        _sub(el, "Ado", _hex(c.ado))
    _sub(el, "Data", c.data.hex())
    _num(el, "Cnt", c.expected_wkc)
    if c.retries:
        _num(el, "Retries", c.retries)
    if c.validate_data is not None or c.validate_mask is not None or (
        c.validate_timeout_ms is not None
    ):
        v = _sub(el, "Validate")
        if c.validate_data is not None:
            _sub(v, "Data", c.validate_data.hex())
        if c.validate_mask is not None:
            _sub(v, "DataMask", c.validate_mask.hex())
        _num(v, "Timeout", c.validate_timeout_ms)
    _num(el, "Timeout", c.timeout_ms)


# ----------------------------------------------------------------------------- slave


def _slave(config: _El, s: Slave, written_sms: set[int]) -> None:
    el = _sub(config, "Slave")
    info = _sub(el, "Info")
    _sub(info, "Name", s.name)
    _num(info, "PhysAddr", s.station_address)
    _num(info, "AutoIncAddr", s.auto_inc_address)
    if s.physics:
        _sub(info, "Physics", s.physics)
    _sub(info, "VendorId", _hex(s.identity.vendor_id, 8))
    _sub(info, "ProductCode", _hex(s.identity.product_code, 8))
    _sub(info, "RevisionNo", _hex(s.identity.revision, 8))
    _sub(info, "SerialNo", _hex(s.identity.serial, 8))
    _process_data(el, s, written_sms)
    if s.mailbox is not None:
        _mailbox(el, s.mailbox)
    _init_cmds(el, s.init_cmds)
    if s.previous_port is not None or s.previous_station_address is not None:
        port = _sub(el, "PreviousPort", Selected="1")
        if s.previous_port is not None:
            _sub(port, "Port", s.previous_port)
        _num(port, "PhysAddr", s.previous_station_address)
    if s.dc is not None:
        _dc(el, s.dc)


def _process_data(el: _El, s: Slave, written_sms: set[int]) -> None:
    if not (s.inputs or s.outputs or s.sync_managers or s.pdos):
        return
    pd = _sub(el, "ProcessData")
    for tag, areas in (("Send", s.outputs), ("Recv", s.inputs)):
        for a in areas:
            area = _sub(pd, tag)
            _num(area, "BitStart", a.bit_start)
            _num(area, "BitLength", a.bit_length)
    for cs in s.sync_managers:
        declared = cs.index not in written_sms
        if not declared and not cs.kind:
            continue
        sm = _sub(pd, f"Sm{cs.index}")
        _text(sm, "Type", cs.kind)
        if declared:
            m = cs.sync_manager
            _sub(sm, "StartAddress", _hex(m.physical_start))
            _sub(sm, "ControlByte", _hex(m.control, 2))
            _num(sm, "DefaultSize", m.length_bytes)
            _sub(sm, "Enable", str(int(bool(m.activate & 1))))
    for p in s.pdos:
        _pdo(pd, p)


def _pdo(parent: _El, p: Pdo) -> None:
    attrs: dict[str, str] = {}
    if p.sync_manager is not None:
        attrs["Sm"] = str(p.sync_manager)
    if p.fixed:
        attrs["Fixed"] = "1"
    if p.mandatory:
        attrs["Mandatory"] = "1"
    el = _sub(parent, "RxPdo" if p.direction is Direction.OUTPUT else "TxPdo", **attrs)
    _sub(el, "Index", _hex(p.index))
    _sub(el, "Name", p.name)
    for e in p.entries:
        entry = _sub(el, "Entry")
        _sub(entry, "Index", _hex(e.index))
        _num(entry, "SubIndex", e.subindex)
        _num(entry, "BitLen", e.bit_size)
        _text(entry, "Name", e.name)
        _text(entry, "DataType", e.data_type)


def _mailbox(parent: _El, m: Mailbox) -> None:
    el = _sub(parent, "Mailbox")
    send = _sub(el, "Send")
    _num(send, "Start", m.out_start)
    _num(send, "Length", m.out_length_bytes)
    recv = _sub(el, "Recv")
    _num(recv, "Start", m.in_start)
    _num(recv, "Length", m.in_length_bytes)
    _num(recv, "PollTime", m.poll_time_ms)
    _num(recv, "StatusBitAddr", m.status_bit_address)
    for p in m.protocols:
        _sub(el, "Protocol", p)
    if m.coe_init_cmds:
        cmds = _sub(_sub(el, "CoE"), "InitCmds")
        for c in m.coe_init_cmds:
            _coe_init_cmd(cmds, c)


def _coe_init_cmd(parent: _El, c: CoeInitCmd) -> None:
    attrs: dict[str, str] = {}
    if c.complete_access:
        attrs["CompleteAccess"] = "1"
    if c.fixed:
        attrs["Fixed"] = "1"
    el = _sub(parent, "InitCmd", **attrs)
    for t in c.transitions:
        _sub(el, "Transition", t)
    _text(el, "Comment", c.comment)
    _num(el, "Timeout", c.timeout_ms)
    _num(el, "Ccs", c.ccs)
    _sub(el, "Index", _hex(c.index))
    _num(el, "SubIndex", c.subindex)
    _sub(el, "Data", c.data.hex())


def _dc(parent: _El, dc: DistributedClock) -> None:
    el = _sub(parent, "DC")
    if dc.reference_clock:
        _sub(el, "ReferenceClock", "1")
    _num(el, "CycleTime0", dc.cycle_time0_ns)
    _num(el, "CycleTime1", dc.cycle_time1_ns)
    _num(el, "ShiftTime", dc.shift_time_ns)
    if dc.assign_activate is not None:
        _sub(el, "AssignActivate", _hex(dc.assign_activate))


# ----------------------------------------------------------------------------- cyclic


def _cyclic(config: _El, task: Cyclic) -> None:
    el = _sub(config, "Cyclic")
    _text(el, "Comment", task.comment)
    if task.cycle_time_ns is not None:
        _sub(el, "CycleTime", _us(task.cycle_time_ns))
    for frame in task.frames:
        _frame(el, frame)


def _frame(parent: _El, frame: CyclicFrame) -> None:
    attrs = {}
    if frame.cycle_time_factor is not None:
        attrs["CycleTimeFactor"] = str(frame.cycle_time_factor)
    el = _sub(parent, "Frame", **attrs)
    _text(el, "Comment", frame.comment)
    for c in frame.commands:
        _cyclic_cmd(el, c)


def _cyclic_cmd(parent: _El, c: CyclicCommand) -> None:
    el = _sub(parent, "Cmd")
    for s in c.states:
        _sub(el, "State", s)
    _text(el, "Comment", c.comment)
    _num(el, "Cmd", c.cmd)
    if c.logical_address is not None:
        _num(el, "Addr", c.logical_address)
    else:
        _num(el, "Adp", c.adp)
        if c.ado is not None:
            _sub(el, "Ado", _hex(c.ado))
    _num(el, "DataLength", c.data_length_bytes)
    _num(el, "Cnt", c.expected_wkc)
    _num(el, "InputOffs", c.input_offset_bytes)
    _num(el, "OutputOffs", c.output_offset_bytes)


# ----------------------------------------------------------------------------- image


def _process_image(config: _El, image: ProcessImage) -> None:
    el = _sub(config, "ProcessImage")
    for tag, size, direction in (
        ("Inputs", image.inputs_bytes, Direction.INPUT),
        ("Outputs", image.outputs_bytes, Direction.OUTPUT),
    ):
        section = _sub(el, tag)
        if size:
            _num(section, "ByteSize", size)
        for v in image.variables:
            if v.direction is direction:
                _variable(section, v)


def _variable(section: _El, v: Variable) -> None:
    el = _sub(section, "Variable")
    _sub(el, "Name", v.name)
    _text(el, "Comment", v.comment)
    _text(el, "DataType", v.data_type)
    _num(el, "BitSize", v.bit_size)
    _num(el, "BitOffs", v.bit_offset)


__all__ = ["write_eni"]
