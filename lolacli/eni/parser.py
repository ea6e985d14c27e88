"""Parse an ENI (ETG.2100 EtherCAT Network Information) document into :mod:`lolacli.eni.model`.

Pure: bytes in, an :class:`~lolacli.eni.model.Eni` out; every failure is an
:class:`~lolacli.errors.EniError` naming ``source`` and, where known, the line.

Hostile XML is refused in two layers. First defusedxml's expat parser with DTDs forbidden
reads the document: a ``<!DOCTYPE`` (and with it every entity, internal or external, so
billion laughs, quadratic blow-up and XXE) stops it at once, and malformed or truncated
XML fails with expat's line. Then lxml, with entity resolution, DTD loading and network
access off, builds the tree we read (lxml gives ``sourceline`` for later messages).

The reader follows the exports found in the wild, not only the schema's order: TwinCAT,
acontis EC-Engineer/EniEngine (``<EncryptedEtherCATConfig>`` with a plain body, whole
file on one line) and Elmo Application Studio (vendor elements before ``<Config>``, no
``<CycleTime>``, ``<Frame CycleTimeFactor=…>``). Numbers are decimal, ``#x…`` or ``0x…``.
"""

from __future__ import annotations

import itertools
import re
import struct
from collections.abc import Iterable, Iterator
from decimal import Decimal, InvalidOperation
from typing import Any
from xml.etree.ElementTree import ParseError

from lolacli.eni import limits as lim
from lolacli.eni.limits import Width
from lolacli.eni.model import (
    CoeInitCmd,
    ConfiguredFmmu,
    ConfiguredSyncManager,
    Cyclic,
    CyclicCommand,
    CyclicFrame,
    Direction,
    DistributedClock,
    Eni,
    Identity,
    InitCmd,
    Mailbox,
    Master,
    Pdo,
    PdoEntry,
    ProcessDataArea,
    ProcessImage,
    Slave,
    Variable,
)
from lolacli.errors import EniError
from lolacli.wire import registers as reg
from lolacli.wire.frame import DATAGRAM_HEADER_BYTES, ECAT_HEADER_BYTES, WKC_BYTES
from lolacli.wire.registers import (
    FMMU_BYTES,
    FMMU_COUNT_MAX,
    SYNC_MANAGER_BYTES,
    SYNC_MANAGER_COUNT_MAX,
    Register,
)

#: Root elements we accept. acontis tools write the second with a plain (unencrypted) body.
ENI_ROOTS = ("EtherCATConfig", "EncryptedEtherCATConfig")

_U16 = struct.Struct("<H")

_El = Any  # an lxml element (lxml ships no type information)

_TRUE = frozenset({"1", "true", "yes"})
_FIRST_ELEMENT = re.compile(rb"<[A-Za-z_:]")


# --------------------------------------------------------------------------- entry point


def parse_eni(data: bytes | str, source: str = "<string>") -> Eni:
    """Parse an ENI document. Raises :class:`EniError` (path ``source``, line) on any defect."""
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    root = _safe_tree(raw, source)
    return _Reader(source).eni(root)


def _safe_tree(raw: bytes, source: str) -> _El:
    """The lxml root of ``raw`` after the defusedxml gate; refuses DTDs and entities."""
    if not raw.strip():
        raise EniError("empty file, not an ENI", path=source)
    _refuse_foreign(raw, source)
    _refuse_doctype_prolog(raw, source)
    _defused_gate(raw, source)
    return _lxml_root(raw, source)


#: Public name of the hardened loader, for the other readers of the ``eni`` layer (ESI).
safe_tree = _safe_tree


_PCAP_MAGICS = frozenset(
    bytes.fromhex(m) for m in ("d4c3b2a1", "a1b2c3d4", "4d3cb2a1", "a1b23c4d")
)
_PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"
_EDS_SECTION = re.compile(rb"^\s*\[(FileInfo|DeviceInfo|MandatoryObjects)\]", re.M)


def foreign_format(raw: bytes) -> str | None:
    """What a file that is no XML at all is, where its first bytes tell: a pcap or pcapng
    capture, a CANopen EDS/DCF. None for anything else."""
    if raw[:4] in _PCAP_MAGICS:
        return "pcap capture"
    if raw[:4] == _PCAPNG_MAGIC:
        return "pcapng capture"
    if raw.lstrip(b"\xef\xbb\xbf \t\r\n")[:1] == b"[" and _EDS_SECTION.search(raw[:65536]):
        return "CANopen EDS/DCF"
    return None


def _refuse_foreign(raw: bytes, source: str) -> None:
    """A capture or an EDS given where an ENI (or ESI) is expected is named as what it is."""
    import shlex

    kind = foreign_format(raw)
    if kind is None:
        return
    if kind.endswith("capture"):
        hint = f"read it with: lolacli capture analyze {shlex.quote(source)}"
    else:
        hint = "a CANopen node's object dictionary: give it to the sdo commands with --eds"
    raise EniError(f"this is a {kind}, not an ENI ({hint})", path=source)


def _refuse_doctype_prolog(raw: bytes, source: str) -> None:
    """Fast path for ASCII-compatible encodings: a DOCTYPE before the root element."""
    first = _FIRST_ELEMENT.search(raw)
    prolog = raw if first is None else raw[: first.start()]
    at = prolog.find(b"<!DOCTYPE")
    if at >= 0:
        raise EniError(_DTD_MESSAGE, path=source, line=raw.count(b"\n", 0, at) + 1)


_DTD_MESSAGE = "DOCTYPE/DTD not allowed in an ENI (entities and external references are refused)"


def _defused_gate(raw: bytes, source: str) -> None:
    from defusedxml import DefusedXmlException
    from defusedxml.ElementTree import DefusedXMLParser

    parser = DefusedXMLParser(
        target=_NullTarget(), forbid_dtd=True, forbid_entities=True, forbid_external=True
    )
    # The gate builds nothing: without ElementTree's default handler, expat hands no
    # character data to Python (6 ms instead of 37 ms for the 450 kB LOLA ENI). DOCTYPE and
    # entity declarations still stop it (defusedxml's own handlers), and so does an
    # undefined entity reference (expat's error without a DTD).
    parser.parser.DefaultHandlerExpand = None
    try:
        parser.feed(raw)
        parser.close()
    except DefusedXmlException as exc:
        line = int(parser.parser.CurrentLineNumber)
        raise EniError(f"{_DTD_MESSAGE} ({type(exc).__name__})", path=source, line=line) from exc
    except ParseError as exc:
        line, _column = exc.position
        message = str(exc).split(": line ")[0]
        raise EniError(f"not well-formed XML: {message}", path=source, line=line) from exc
    except (LookupError, ValueError) as exc:  # expat: unknown or multi-byte encoding
        raise EniError(f"unsupported XML encoding: {exc}", path=source, line=1) from exc


class _NullTarget:
    """An expat target that builds nothing: the gate only checks, lxml builds the tree."""


def _lxml_root(raw: bytes, source: str) -> _El:
    from lxml import etree

    parser = etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        remove_comments=True,
        remove_pis=True,
    )
    try:
        root = etree.fromstring(raw, parser)
    except etree.XMLSyntaxError as exc:
        raise EniError(f"not well-formed XML: {exc.msg}", path=source, line=exc.lineno) from exc
    docinfo = root.getroottree().docinfo
    if docinfo.doctype or docinfo.internalDTD is not None:
        raise EniError(_DTD_MESSAGE, path=source, line=1)
    _strip_namespaces(root, raw)
    return root


_PREFIXED_TAG = re.compile(rb"<[A-Za-z_][\w.-]*:")


def _no_element_namespace(raw: bytes) -> bool:
    """True when no element of ``raw`` can be in a namespace: an ASCII-compatible document
    with no default namespace (``xmlns=``) and no prefixed tag (``<x:``). The exports
    declare ``xmlns:xsi`` for attributes only; walking their 75 000 elements to strip
    nothing took a tenth of the parse."""
    if b"\x00" in raw[:4] or raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return False  # UTF-16/32: the byte patterns below do not apply
    return b"xmlns=" not in raw and _PREFIXED_TAG.search(raw) is None


def _strip_namespaces(root: _El, raw: bytes) -> None:
    """Local names only, so that plain ``find`` paths work on namespaced exports too."""
    if _no_element_namespace(raw):
        return
    for el in root.iter():
        tag = el.tag
        if isinstance(tag, str) and tag.startswith("{"):
            el.tag = tag.rsplit("}", 1)[-1]


# --------------------------------------------------------------------------- scalars


def parse_number(text: str) -> int:
    """An ENI integer: decimal, ``#x1A00`` or ``0x1A00`` (optionally signed; ASCII digits,
    ``_`` ignored). ValueError if not."""
    value = _number(text)
    if value is None:
        raise ValueError(text)
    return value


def _number(text: str) -> int | None:
    """:func:`parse_number`, None for no number."""
    m = _NUMBER.fullmatch(text.replace("_", "") if "_" in text else text)
    if m is None:
        return None
    sign, hex_digits, digits = m.groups()
    try:
        value = int(hex_digits, 16) if hex_digits is not None else int(digits, 10)
    except ValueError:  # more decimal digits than Python converts (4300)
        return None
    return -value if sign == "-" else value


_NUMBER = re.compile(r"\s*([+-]?)(?:[#0][xX]([0-9A-Fa-f]+)|([0-9]+))\s*")


def _local(tag: object) -> str:
    if not isinstance(tag, str):
        return ""  # comments, processing instructions
    return tag.rsplit("}", 1)[-1]


class _Reader:
    """Element helpers bound to one source name (for error messages)."""

    def __init__(self, source: str) -> None:
        self.source = source
        # the children of each element asked, by tag: lxml's find() parses its path each
        # call, and most elements are asked for several children
        self._by_tag: dict[_El, dict[Any, list[_El]]] = {}

    # -- element access (namespace-agnostic) --

    def _kids(self, el: _El) -> dict[Any, list[_El]]:
        kids = self._by_tag.get(el)
        if kids is None:
            kids = {}
            for c in el:
                group = kids.get(c.tag)
                if group is None:
                    kids[c.tag] = [c]
                else:
                    group.append(c)
            self._by_tag[el] = kids
        return kids

    def children(self, el: _El, name: str) -> list[_El]:
        return self._kids(el).get(name, [])

    def child(self, el: _El | None, path: str) -> _El | None:
        if el is None:
            return None
        if "/" in path:
            return el.find(path)
        group = self._kids(el).get(path)
        return None if group is None else group[0]

    def text(self, el: _El | None, path: str, default: str = "") -> str:
        node = self.child(el, path)
        if node is None or node.text is None:
            return default
        return str(node.text)

    def error(self, el: _El | None, message: str) -> EniError:
        line = None if el is None else el.sourceline
        return EniError(message, path=self.source, line=line)

    def number(
        self, el: _El | None, path: str, default: int | None = None, width: Width | None = None
    ) -> int | None:
        """The number of ``<path>`` below ``el`` (``default`` when absent or empty), within
        ``width``: a value outside it is an :class:`EniError` naming its line."""
        if el is None:
            return default
        if "/" in path:
            node = el.find(path)
        else:  # child(), inlined: the parser asks for 45 000 numbers in the LOLA ENI
            group = (self._by_tag.get(el) or self._kids(el)).get(path)
            node = None if group is None else group[0]
        if node is None:
            return default
        text = node.text
        if not text or text.isspace():
            return default
        return self.value(node, text, width)

    def value(self, node: _El, text: str, width: Width | None, label: str = "") -> int:
        """``text`` of ``node`` (``label`` in messages, else ``<Tag>``) as a number within
        ``width``."""
        value = _number(text)
        if value is None:
            what = label or f"<{_local(node.tag)}>"
            raise self.error(node, f"{what}: not a number: {_shown(text)!r}")
        if width is None or (width.lo <= value and (width.hi is None or value <= width.hi)):
            return value
        got = width.read(value)
        if got is None:
            what = label or f"<{_local(node.tag)}>"
            raise self.error(node, f"{what} {_shown(text)} is outside {width}")
        return got

    def need(self, el: _El, path: str, width: Width | None = None) -> int:
        value = self.number(el, path, width=width)
        if value is None:
            node = self.child(el, path)
            if node is not None:
                raise self.error(node, f"<{path}> is empty: expected a number")
            raise self.error(el, f"<{_local(el.tag)}> has no <{path}>")
        return value

    def attr_number(self, el: _El, name: str, width: Width) -> int | None:
        text = el.get(name)
        if text is None:
            return None
        return self.value(el, text, width, f"<{_local(el.tag)}> {name}")

    def flag(self, el: _El | None, path: str) -> bool:
        return self.text(el, path).strip().lower() in _TRUE

    def attr_flag(self, el: _El, name: str) -> bool:
        return str(el.get(name, "")).strip().lower() in _TRUE

    def hexdata(self, el: _El | None, path: str) -> bytes | None:
        node = self.child(el, path)
        if node is None:
            return None
        text = "".join((node.text or "").split())
        try:
            return bytes.fromhex(text)
        except ValueError:
            raise self.error(node, f"<{path}>: not hex data: {text[:40]!r}") from None

    def texts(self, el: _El, name: str) -> tuple[str, ...]:
        return tuple(str(c.text).strip() for c in self.children(el, name) if c.text)

    # -- document --

    def eni(self, root: _El) -> Eni:
        name = _local(root.tag)
        if name == "EtherCATInfo":
            raise self.error(
                root, "this is an ESI device description (<EtherCATInfo>), not an ENI "
                "(give it to bus emulate or the sdo commands with --esi)",
            )
        if name not in ENI_ROOTS:
            raise self.error(root, f"not an ENI: root element is <{name}>, not <EtherCATConfig>")
        config = self.child(root, "Config")
        if config is None:
            raise self.error(root, f"<{name}> has no <Config>")
        slaves = tuple(self.slave(el, i + 1) for i, el in enumerate(self.children(config, "Slave")))
        cyclic = tuple(self.cyclic(el) for el in self.children(config, "Cyclic"))
        frames = tuple(f for task in cyclic for f in task.frames)
        slaves = tuple(_with_process_data_fmmus(s, frames) for s in slaves)
        return Eni(
            master=self.master(self.child(config, "Master")),
            slaves=slaves,
            cyclic=cyclic,
            process_image=self.process_image(self.child(config, "ProcessImage")),
            root=name,
            source=self.source,
        )

    # -- master --

    def master(self, el: _El | None) -> Master:
        if el is None:
            return Master()
        info = self.child(el, "Info")
        return Master(
            name=self.text(info, "Name").strip(),
            destination_mac=self.mac(info, "Destination", b"\xff" * 6),
            source_mac=self.mac(info, "Source", b"\x00" * 6),
            ethertype=self.ethertype(info),
            init_cmds=self.init_cmds(self.child(el, "InitCmds")),
            cycle_time_ns=self.cycle_time_ns(el),  # Elmo Application Studio only
        )

    def mac(self, info: _El | None, name: str, default: bytes) -> bytes:
        data = self.hexdata(info, name)
        if data is None:
            return default
        if len(data) != 6:
            raise self.error(self.child(info, name), f"<{name}>: a MAC address has 6 bytes")
        return data

    def ethertype(self, info: _El | None) -> int:
        data = self.hexdata(info, "EtherType")
        if not data:
            return 0x88A4
        if len(data) != 2:
            raise self.error(self.child(info, "EtherType"), "<EtherType>: an EtherType has 2 bytes")
        return int.from_bytes(data, "little")  # the ENI writes the wire bytes: "a488"

    # -- InitCmds --

    def init_cmds(self, el: _El | None) -> tuple[InitCmd, ...]:
        if el is None:
            return ()
        return tuple(self.init_cmd(c) for c in self.children(el, "InitCmd"))

    def init_cmd(self, el: _El) -> InitCmd:
        cmd = self.need(el, "Cmd", lim.COMMAND)
        data = self.datagram_data(el, "Data")
        if data is None:
            data = bytes(self.number(el, "DataLength", 0, lim.DATA_LENGTH) or 0)
        logical = self.number(el, "Addr", width=lim.WORD32)
        adp = self.number(el, "Adp", 0, lim.ADDRESS16) or 0
        ado = self.number(el, "Ado", 0, lim.ADDRESS16) or 0
        if logical is not None:
            adp, ado = logical & 0xFFFF, (logical >> 16) & 0xFFFF
        validate = self.child(el, "Validate")
        return InitCmd(
            transitions=self.texts(el, "Transition"),
            cmd=cmd,
            adp=adp,
            ado=ado,
            data=data,
            expected_wkc=self.number(el, "Cnt", width=lim.WKC),
            comment=self.text(el, "Comment").strip(),
            requires=self.text(el, "Requires").strip(),
            retries=self.number(el, "Retries", 0, lim.RETRIES) or 0,
            validate_data=self.datagram_data(validate, "Data"),
            validate_mask=self.datagram_data(validate, "DataMask"),
            validate_timeout_ms=self.number(validate, "Timeout", width=lim.MILLISECONDS),
            logical_address=logical,
            timeout_ms=self.number(el, "Timeout", width=lim.MILLISECONDS),
        )

    def datagram_data(self, el: _El | None, path: str) -> bytes | None:
        """Hex data of one datagram: at most what a frame carries."""
        data = self.hexdata(el, path)
        if data is not None and not lim.DATA_LENGTH.holds(len(data)):
            raise self.error(
                self.child(el, path), f"<{path}> of {len(data)} bytes: {lim.DATA_LENGTH}"
            )
        return data

    # -- slave --

    def slave(self, el: _El, position: int) -> Slave:
        info = self.child(el, "Info")
        if info is None:
            raise self.error(el, f"slave {position}: <Slave> has no <Info>")
        init_cmds = self.init_cmds(self.child(el, "InitCmds"))
        process_data = self.child(el, "ProcessData")
        mailbox = self.mailbox(self.child(el, "Mailbox"))
        port, port_address = self.previous_port(el)
        return Slave(
            position=position,
            name=self.text(info, "Name"),
            identity=self.identity(info, position),
            station_address=self.need(info, "PhysAddr", lim.ADDRESS16),
            auto_inc_address=self.auto_inc(info, position),
            previous_port=port,
            previous_station_address=port_address,
            mailbox=mailbox,
            sync_managers=self.sync_managers(process_data, init_cmds, mailbox),
            fmmus=fmmus_from_init_cmds(init_cmds),
            pdos=self.pdos(process_data),
            init_cmds=init_cmds,
            dc=self.dc(self.child(el, "DC"), init_cmds),
            inputs=self.areas(process_data, "Recv"),
            outputs=self.areas(process_data, "Send"),
            physics=self.text(info, "Physics").rstrip().upper(),
        )

    def auto_inc(self, info: _El, position: int) -> int:
        """AutoIncAddr as a 16-bit word (the ENI may write 65535 or -1); absent: from position."""
        value = self.number(info, "AutoIncAddr", width=lim.ADDRESS16)
        return -(position - 1) & 0xFFFF if value is None else value

    def identity(self, info: _El, position: int) -> Identity:
        for name in ("PhysAddr", "VendorId", "ProductCode"):
            if self.child(info, name) is None:
                raise self.error(info, f"slave {position}: <Info> has no <{name}>")
        return Identity(
            vendor_id=self.need(info, "VendorId", lim.WORD32),
            product_code=self.need(info, "ProductCode", lim.WORD32),
            revision=self.number(info, "RevisionNo", 0, lim.WORD32) or 0,
            serial=self.number(info, "SerialNo", 0, lim.WORD32) or 0,
        )

    def previous_port(self, el: _El) -> tuple[str | None, int | None]:
        ports = list(self.children(el, "PreviousPort"))
        if not ports:
            return None, None
        chosen = next((p for p in ports if self.attr_flag(p, "Selected")), ports[0])
        port = self.text(chosen, "Port").strip() or None
        return port, self.number(chosen, "PhysAddr", width=lim.ADDRESS16)

    def mailbox(self, el: _El | None) -> Mailbox | None:
        if el is None:
            return None
        send, recv = self.child(el, "Send"), self.child(el, "Recv")
        return Mailbox(
            out_start=self.number(send, "Start", 0, lim.U16) or 0,
            out_length_bytes=self.number(send, "Length", 0, lim.U16) or 0,
            in_start=self.number(recv, "Start", 0, lim.U16) or 0,
            in_length_bytes=self.number(recv, "Length", 0, lim.U16) or 0,
            protocols=self.texts(el, "Protocol"),
            coe_init_cmds=self.coe_init_cmds(self.child(el, "CoE/InitCmds")),
            poll_time_ms=self.number(recv, "PollTime", width=lim.MILLISECONDS),
            status_bit_address=self.number(recv, "StatusBitAddr", width=lim.LOGICAL_BIT),
        )

    def coe_init_cmds(self, el: _El | None) -> tuple[CoeInitCmd, ...]:
        if el is None:
            return ()
        return tuple(self.coe_init_cmd(c) for c in self.children(el, "InitCmd"))

    def coe_init_cmd(self, el: _El) -> CoeInitCmd:
        return CoeInitCmd(
            transitions=self.texts(el, "Transition"),
            index=self.need(el, "Index", lim.U16),
            subindex=self.number(el, "SubIndex", 0, lim.U8) or 0,
            data=self.hexdata(el, "Data") or b"",
            complete_access=self.attr_flag(el, "CompleteAccess"),
            fixed=self.attr_flag(el, "Fixed"),
            comment=self.text(el, "Comment").strip(),
            ccs=self.number(el, "Ccs", 1, lim.CCS) or 1,
            timeout_ms=self.number(el, "Timeout", width=lim.MILLISECONDS),
        )

    def dc(self, el: _El | None, init_cmds: tuple[InitCmd, ...]) -> DistributedClock | None:
        if el is None:
            return None
        assign = self.number(el, "AssignActivate", width=lim.U16)
        if assign is None:
            assign = dc_activation_from_init_cmds(init_cmds)
        return DistributedClock(
            cycle_time0_ns=self.number(el, "CycleTime0", width=lim.U32),
            cycle_time1_ns=self.number(el, "CycleTime1", width=lim.U32),
            shift_time_ns=self.number(el, "ShiftTime", width=lim.I32),
            assign_activate=assign,
            reference_clock=self.flag(el, "ReferenceClock"),
        )

    def areas(self, process_data: _El | None, name: str) -> tuple[ProcessDataArea, ...]:
        if process_data is None:
            return ()
        return tuple(
            ProcessDataArea(
                self.need(a, "BitStart", lim.LOGICAL_BIT), self.need(a, "BitLength", lim.AREA_BITS)
            )
            for a in self.children(process_data, name)
        )

    # -- sync managers and PDOs --

    def sm_elements(self, process_data: _El | None) -> dict[int, _El]:
        if process_data is None:
            return {}
        out: dict[int, _El] = {}
        for c in process_data:
            name = _local(c.tag)
            if re.fullmatch(r"Sm\d+", name):
                index = int(name[2:])
                if not lim.SM_INDEX.holds(index):
                    raise self.error(c, f"<{name}>: sync manager {index} is outside {lim.SM_INDEX}")
                out[index] = c
        return out

    def sync_managers(
        self, process_data: _El | None, init_cmds: tuple[InitCmd, ...], mailbox: Mailbox | None
    ) -> tuple[ConfiguredSyncManager, ...]:
        """Sync managers as written by the InitCmds (0x0800 + 8·n), else as ``<SmN>`` says."""
        declared = self.sm_elements(process_data)
        written = sync_managers_from_init_cmds(init_cmds)
        kinds = {n: self.text(el, "Type").strip() for n, el in declared.items()}
        if mailbox is not None:
            kinds.setdefault(0, "MBoxOut")
            kinds.setdefault(1, "MBoxIn")
        result = {sm.index: sm for sm in written}
        if mailbox is not None:  # mailbox SMs the ENI describes but no InitCmd writes
            mbx = (
                (0, mailbox.out_start, mailbox.out_length_bytes, reg.SM_CONTROL_MAILBOX_OUT),
                (1, mailbox.in_start, mailbox.in_length_bytes, reg.SM_CONTROL_MAILBOX_IN),
            )
            for n, start, length, control in mbx:
                if n not in result and n not in declared and length:
                    result[n] = ConfiguredSyncManager(
                        n,
                        reg.SyncManager(start, length, control, activate=reg.SM_ACTIVATE_ENABLE),
                    )
        for n, el in declared.items():
            if n not in result:
                result[n] = self.declared_sm(n, el)
        return tuple(_with_kind(result[n], kinds.get(n, "")) for n in sorted(result))

    def declared_sm(self, index: int, el: _El) -> ConfiguredSyncManager:
        size = self.number(el, "DefaultSize", width=lim.U16)
        if size is None:
            size = self.number(el, "MaxSize", 0, lim.U16) or 0
        sm = reg.SyncManager(
            physical_start=self.number(el, "StartAddress", 0, lim.U16) or 0,
            length_bytes=size,
            control=self.number(el, "ControlByte", 0, lim.U8) or 0,
            activate=int(self.flag(el, "Enable")),
        )
        return ConfiguredSyncManager(index, sm)

    def pdos(self, process_data: _El | None) -> tuple[Pdo, ...]:
        if process_data is None:
            return ()
        assigned: dict[int, int] = {}
        for n, el in self.sm_elements(process_data).items():
            for p in self.children(el, "Pdo"):
                if p.text and p.text.strip():
                    assigned[self.value(p, p.text, lim.U16)] = n
        pdos: list[Pdo] = []
        for tag, direction in (("RxPdo", Direction.OUTPUT), ("TxPdo", Direction.INPUT)):
            for el in self.children(process_data, tag):
                pdos.append(self.pdo(el, direction, assigned))
        return tuple(pdos)

    def pdo(self, el: _El, direction: Direction, assigned: dict[int, int]) -> Pdo:
        index = self.need(el, "Index", lim.U16)
        sm = self.attr_number(el, "Sm", lim.SM_INDEX)
        return Pdo(
            index=index,
            name=self.text(el, "Name").strip(),
            direction=direction,
            sync_manager=assigned.get(index) if sm is None else sm,
            entries=tuple(self.entry(e) for e in self.children(el, "Entry")),
            fixed=self.attr_flag(el, "Fixed"),
            mandatory=self.attr_flag(el, "Mandatory"),
        )

    def entry(self, el: _El) -> PdoEntry:
        return PdoEntry(
            index=self.need(el, "Index", lim.U16),
            subindex=self.number(el, "SubIndex", 0, lim.U8) or 0,
            bit_size=self.need(el, "BitLen", lim.BIT_LEN),
            name=self.text(el, "Name").strip(),
            data_type=self.text(el, "DataType").strip(),
        )

    # -- cyclic --

    def cycle_time_ns(self, el: _El) -> int | None:
        """``<CycleTime>`` below ``el``, in µs (a decimal), as ns; None when absent or empty."""
        node = self.child(el, "CycleTime")
        if node is None or node.text is None or not node.text.strip():
            return None
        text = node.text.strip()
        try:
            us = Decimal(text)
        except InvalidOperation:
            raise self.error(node, f"<CycleTime>: not a number of µs: {_shown(text)!r}") from None
        # bound before converting: 1e999999999 µs must not become a billion-digit integer
        ns = int(us * 1000) if us.is_finite() and abs(us) <= _MAX_CYCLE_US else None
        if ns is None or not lim.CYCLE_NS.holds(ns):
            raise self.error(
                node, f"<CycleTime> {_shown(text)} µs is outside 0.001..{_MAX_CYCLE_US} µs "
                f"({lim.CYCLE_NS.name})"
            )
        return ns

    def cyclic(self, el: _El) -> Cyclic:
        frames = [self.frame(f) for f in self.children(el, "Frame")]
        factors = [f.cycle_time_factor for f in frames if f.cycle_time_factor is not None]
        return Cyclic(
            cycle_time_ns=self.cycle_time_ns(el),
            frames=tuple(frames),
            comment=self.text(el, "Comment").strip(),
            cycle_time_factor=factors[0] if factors else None,
        )

    def frame(self, el: _El) -> CyclicFrame:
        commands = tuple(self.cyclic_cmd(c) for c in self.children(el, "Cmd"))
        payload = ECAT_HEADER_BYTES + sum(
            DATAGRAM_HEADER_BYTES + c.data_length_bytes + WKC_BYTES for c in commands
        )
        if payload > lim.ETHERNET_PAYLOAD_BYTES:
            raise self.error(
                el, f"<Frame> of {len(commands)} datagrams needs {payload} bytes: an Ethernet "
                f"frame carries {lim.ETHERNET_PAYLOAD_BYTES}",
            )
        return CyclicFrame(
            commands=commands,
            comment=self.text(el, "Comment").strip(),
            cycle_time_factor=self.attr_number(el, "CycleTimeFactor", lim.U16),
        )

    def cyclic_cmd(self, el: _El) -> CyclicCommand:
        from lolacli.wire.commands import LOGICAL

        cmd = self.need(el, "Cmd", lim.COMMAND)
        length = self.number(el, "DataLength", width=lim.DATA_LENGTH)
        if length is None:
            length = len(self.datagram_data(el, "Data") or b"")
        addr = self.number(el, "Addr", width=lim.WORD32)
        adp = self.number(el, "Adp", width=lim.ADDRESS16)
        ado = self.number(el, "Ado", width=lim.ADDRESS16)
        if cmd in LOGICAL and addr is None and (adp is not None or ado is not None):
            addr = (adp or 0) | ((ado or 0) << 16)
        if cmd in LOGICAL:
            adp = ado = None
        elif addr is not None and adp is None and ado is None:
            adp, ado, addr = addr & 0xFFFF, (addr >> 16) & 0xFFFF, None
        return CyclicCommand(
            cmd=cmd,
            data_length_bytes=length,
            expected_wkc=self.number(el, "Cnt", width=lim.WKC),
            adp=adp,
            ado=ado,
            logical_address=addr,
            input_offset_bytes=self.number(el, "InputOffs", width=lim.IMAGE_BYTES),
            output_offset_bytes=self.number(el, "OutputOffs", width=lim.IMAGE_BYTES),
            states=self.texts(el, "State"),
            comment=self.text(el, "Comment").strip(),
        )

    # -- process image --

    def process_image(self, el: _El | None) -> ProcessImage:
        if el is None:
            return ProcessImage(0, 0)
        variables: list[Variable] = []
        sizes: dict[str, int] = {}
        for tag, direction in (("Inputs", Direction.INPUT), ("Outputs", Direction.OUTPUT)):
            section = self.child(el, tag)
            declared = self.number(section, "ByteSize", width=lim.IMAGE_BYTES)
            sizes[tag] = declared or 0
            if section is not None:
                variables += [
                    self.variable(v, direction, declared)
                    for v in self.children(section, "Variable")
                ]
        return ProcessImage(sizes["Inputs"], sizes["Outputs"], tuple(variables))

    def variable(self, el: _El, direction: Direction, image_bytes: int | None) -> Variable:
        name = self.text(el, "Name")
        offset = self.need(el, "BitOffs", lim.IMAGE_BIT)
        size = self.need(el, "BitSize", lim.IMAGE_BIT)
        if image_bytes is not None and offset + size > image_bytes * 8:
            raise self.error(
                el, f"variable \"{' '.join(name.split())}\": bits {offset}..{offset + size - 1} "
                f"lie past the {image_bytes}-byte {direction.value} image (<ByteSize>)",
            )
        return Variable(
            name=name,
            direction=direction,
            bit_offset=offset,
            bit_size=size,
            data_type=self.text(el, "DataType").strip(),
            comment=self.text(el, "Comment").strip(),
        )


#: the longest cycle time (µs) :data:`lim.CYCLE_NS` admits
_MAX_CYCLE_US = Decimal(lim.CYCLE_NS.hi or 0) / 1000


def _shown(text: str) -> str:
    """A number as written, for a message (long junk cut short)."""
    t = " ".join(text.split())
    return t if len(t) <= 40 else t[:37] + "..."


# --------------------------------------------------------------------------- register decoding


def _register_writes(
    init_cmds: Iterable[InitCmd], base: int, size: int, count: int
) -> Iterator[tuple[int, bytes, InitCmd]]:
    """(index, bytes) of each register block ``base + size·index`` an InitCmd writes."""
    from lolacli.wire.commands import Command

    writes = {Command.APWR, Command.FPWR, Command.BWR, Command.APRW, Command.FPRW, Command.BRW}
    end = base + size * count
    for ic in init_cmds:
        if ic.cmd not in writes or ic.logical_address is not None:
            continue
        if not base <= ic.ado < end or (ic.ado - base) % size:
            continue
        first = (ic.ado - base) // size
        for k in range(len(ic.data) // size):
            if first + k < count:
                yield first + k, ic.data[k * size : (k + 1) * size], ic


def fmmus_from_init_cmds(init_cmds: Iterable[InitCmd]) -> tuple[ConfiguredFmmu, ...]:
    """The FMMUs the InitCmds configure (the last non-zero write of each wins)."""
    found: dict[int, ConfiguredFmmu] = {}
    for index, block, _ic in _register_writes(
        init_cmds, Register.FMMU, FMMU_BYTES, FMMU_COUNT_MAX
    ):
        if any(block):
            found[index] = ConfiguredFmmu(index, reg.decode_fmmu(block))
    return tuple(found[i] for i in sorted(found))


def sync_managers_from_init_cmds(
    init_cmds: Iterable[InitCmd],
) -> tuple[ConfiguredSyncManager, ...]:
    """The sync managers the InitCmds configure; bootstrap-only (``IB``) writes are skipped."""
    found: dict[int, ConfiguredSyncManager] = {}
    for index, block, ic in _register_writes(
        init_cmds, Register.SM, SYNC_MANAGER_BYTES, SYNC_MANAGER_COUNT_MAX
    ):
        if any(block) and set(ic.transitions) != {"IB"}:
            found[index] = ConfiguredSyncManager(index, reg.decode_sync_manager(block))
    return tuple(found[i] for i in sorted(found))


def dc_activation_from_init_cmds(init_cmds: Iterable[InitCmd]) -> int | None:
    """AssignActivate as written to register 0x0980 (the last non-zero write)."""
    value = None
    for ic in init_cmds:
        dc_activation = ic.ado == Register.DC_CYCLIC_UNIT_CONTROL  # 0x0980 and 0x0981
        if dc_activation and len(ic.data) >= 2 and ic.logical_address is None:
            (word,) = _U16.unpack_from(ic.data)
            if word:
                value = word
    return value


def _frame_layout(frames: tuple[CyclicFrame, ...]) -> bool:
    """True when image offsets follow the frame (TwinCAT): each command's offset points at
    its datagram header, so the next one is 10 + data + 2 further on. acontis and Elmo
    exports point at the data itself."""
    for frame in frames:
        offs = [c.input_offset_bytes for c in frame.commands]
        for (a, b), c in zip(itertools.pairwise(offs), frame.commands, strict=False):
            if a is not None and b is not None and b - a == c.data_length_bytes + 12:
                return True
    return False


def fmmus_from_process_data(
    slave: Slave, frames: tuple[CyclicFrame, ...]
) -> tuple[ConfiguredFmmu, ...]:
    """FMMUs implied by ``<ProcessData><Send|Recv>`` and the logical cyclic commands.

    For ENIs without FMMU InitCmds: an area's image bits are placed at the logical address
    of the command whose image window holds them; the physical side is the Outputs / Inputs
    sync manager (SM2 / SM3 when the ENI names none).
    """
    header = DATAGRAM_HEADER_BYTES if _frame_layout(frames) else 0
    found: list[ConfiguredFmmu] = []
    for areas, kind, default_sm, fmmu_type in (
        (slave.outputs, "Outputs", 2, 2),
        (slave.inputs, "Inputs", 3, 1),
    ):
        sm = next((m for m in slave.sync_managers if m.kind == kind), None)
        sm = sm or next((m for m in slave.sync_managers if m.index == default_sm), None)
        for area in areas:
            logical_bit = _logical_bit(area, frames, fmmu_type, header)
            if logical_bit is None or not area.bit_length or sm is None:
                continue
            start_bit = logical_bit % 8
            length = (start_bit + area.bit_length + 7) // 8
            end_bit = (start_bit + area.bit_length - 1) % 8
            fmmu = reg.Fmmu(
                logical_bit // 8,
                length,
                logical_start_bit=start_bit,
                logical_stop_bit=end_bit,
                physical_start=sm.sync_manager.physical_start,
                type=fmmu_type,
                activate=1,
            )
            found.append(ConfiguredFmmu(len(found), fmmu))
    return tuple(found)


def _logical_bit(
    area: ProcessDataArea, frames: tuple[CyclicFrame, ...], fmmu_type: int, header: int
) -> int | None:
    from lolacli.wire.commands import Command

    wanted = {Command.LRW, Command.LWR if fmmu_type == 2 else Command.LRD}
    for frame in frames:
        for c in frame.commands:
            offs = c.output_offset_bytes if fmmu_type == 2 else c.input_offset_bytes
            if c.cmd not in wanted or c.logical_address is None or offs is None:
                continue
            start = (offs + header) * 8
            if (
                start <= area.bit_start
                and area.bit_start + area.bit_length <= start + 8 * c.data_length_bytes
            ):
                return c.logical_address * 8 + area.bit_start - start
    return None


def _with_process_data_fmmus(slave: Slave, frames: tuple[CyclicFrame, ...]) -> Slave:
    from dataclasses import replace

    if slave.fmmus or not (slave.inputs or slave.outputs):
        return slave
    return replace(slave, fmmus=fmmus_from_process_data(slave, frames))


def _with_kind(sm: ConfiguredSyncManager, kind: str) -> ConfiguredSyncManager:
    from dataclasses import replace

    return replace(sm, kind=kind) if kind and not sm.kind else sm


__all__ = [
    "ENI_ROOTS",
    "foreign_format",
    "fmmus_from_init_cmds",
    "fmmus_from_process_data",
    "parse_eni",
    "parse_number",
    "sync_managers_from_init_cmds",
]
