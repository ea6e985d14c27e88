"""The CoE SDO server in a slave's mailbox (ETG.1000.6 §5.6.2, CiA 301 §7.2.4.3).

Mailbox in, mailbox out. Services: SDO download (expedited, normal, segmented), SDO upload
(expedited, normal, segmented with toggle bit), abort, and SDO information (OD list,
object description, entry description). Anything else gets a mailbox error reply.

Layouts::

    mailbox header  length(2) address(2) channel:6|priority:2 (1) type:4|counter:3 (1)
    CoE header      number:9 | reserved:3 | service:4                      (2)
    SDO             command(1) index(2) subindex(1) data(4) [more data]
    SDO info        opcode:7|incomplete:1 (1) reserved(1) fragments left(2) data
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from lolacli.errors import SdoAbortError
from lolacli.od import Dictionary, access_word
from lolacli.wire.sdo import SdoAbortCode

_MBX = struct.Struct("<HHBB")
_SDO = struct.Struct("<BHB")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")

MAILBOX_HEADER_BYTES = 6
COE_HEADER_BYTES = 2
MAILBOX_TYPE_ERROR = 0x00
MAILBOX_TYPE_COE = 0x03
MAILBOX_ERROR_UNSUPPORTED_PROTOCOL = 0x0002
MAILBOX_ERROR_INVALID_HEADER = 0x0005

SERVICE_EMERGENCY = 1
SERVICE_SDO_REQUEST = 2
SERVICE_SDO_RESPONSE = 3
SERVICE_SDO_INFORMATION = 8

INFO_OD_LIST_REQUEST = 1
INFO_OD_LIST_RESPONSE = 2
INFO_OBJECT_DESCRIPTION_REQUEST = 3
INFO_OBJECT_DESCRIPTION_RESPONSE = 4
INFO_ENTRY_DESCRIPTION_REQUEST = 5
INFO_ENTRY_DESCRIPTION_RESPONSE = 6
INFO_ERROR = 7


@dataclass(slots=True)
class _Transfer:
    index: int
    subindex: int
    data: bytearray
    toggle: int
    size: int = 0
    complete: bool = False


class SdoServer:
    """Serves one object dictionary over CoE; ``mailbox_bytes`` is the mailbox-in size."""

    def __init__(self, od: Dictionary, mailbox_bytes: int = 128) -> None:
        self.od = od
        self.mailbox_bytes = mailbox_bytes
        self._counter = 0
        self._upload: _Transfer | None = None
        self._download: _Transfer | None = None
        self.transfers = 0
        self.aborts = 0

    # ------------------------------------------------------------- framing
    def _mailbox(self, mtype: int, payload: bytes) -> bytes:
        self._counter = self._counter % 7 + 1
        return _MBX.pack(len(payload), 0, 0, (mtype & 0x0F) | (self._counter << 4)) + payload

    def _coe(self, service: int, body: bytes) -> bytes:
        return self._mailbox(MAILBOX_TYPE_COE, _U16.pack(service << 12) + body)

    def emergency(self, error_code: int, error_register: int = 0, data: bytes = b"") -> bytes:
        """A CoE emergency (service 1): error code, error register, 5 bytes of data."""
        body = struct.pack("<HB", error_code, error_register) + data[:5].ljust(5, b"\0")
        return self._coe(SERVICE_EMERGENCY, body)

    def _mailbox_error(self, detail: int) -> bytes:
        return self._mailbox(MAILBOX_TYPE_ERROR, _U16.pack(0x0001) + _U16.pack(detail))

    @property
    def _room(self) -> int:
        """Bytes of SDO data after the 4-byte index/size part of an initiate response."""
        return self.mailbox_bytes - MAILBOX_HEADER_BYTES - COE_HEADER_BYTES - 8

    # ------------------------------------------------------------- dispatch
    def handle(self, request: bytes) -> list[bytes]:
        """A complete mailbox from the master -> the replies to post."""
        if len(request) < MAILBOX_HEADER_BYTES + COE_HEADER_BYTES:
            return [self._mailbox_error(MAILBOX_ERROR_INVALID_HEADER)]
        length, _address, _channel, type_counter = _MBX.unpack_from(request)
        if type_counter & 0x0F != MAILBOX_TYPE_COE:
            return [self._mailbox_error(MAILBOX_ERROR_UNSUPPORTED_PROTOCOL)]
        end = MAILBOX_HEADER_BYTES + min(length, len(request) - MAILBOX_HEADER_BYTES)
        (coe,) = _U16.unpack_from(request, MAILBOX_HEADER_BYTES)
        body = request[MAILBOX_HEADER_BYTES + COE_HEADER_BYTES : end]
        service = coe >> 12
        if service == SERVICE_SDO_REQUEST and len(body) >= 8:
            return [self._sdo(body)]
        if service == SERVICE_SDO_INFORMATION and len(body) >= 4:
            return self._info(body)
        return [self._mailbox_error(MAILBOX_ERROR_INVALID_HEADER)]

    def _sdo(self, body: bytes) -> bytes:
        command, index, subindex = _SDO.unpack_from(body)
        ccs = command >> 5
        try:
            if ccs == 1:
                return self._download_initiate(command, index, subindex, body)
            if ccs == 0:
                return self._download_segment(command, body)
            if ccs == 2:
                return self._upload_initiate(command, index, subindex)
            if ccs == 3:
                return self._upload_segment(command)
            if ccs == 4:
                self._upload = self._download = None
                return b""
            raise SdoAbortError(index, subindex, SdoAbortCode.UNKNOWN_COMMAND)
        except SdoAbortError as exc:
            return self._abort(exc.index, exc.subindex, exc.code)

    def _abort(self, index: int, subindex: int, code: int) -> bytes:
        self.aborts += 1
        self._upload = self._download = None
        return self._coe(SERVICE_SDO_REQUEST, _SDO.pack(0x80, index, subindex) + _U32.pack(code))

    # ------------------------------------------------------------- download
    def _download_initiate(self, command: int, index: int, subindex: int, body: bytes) -> bytes:
        complete = bool(command & 0x10)
        expedited, sized = command & 0x02, command & 0x01
        if expedited:
            size = 4 - ((command >> 2) & 0x03) if sized else 4
            self._store(index, subindex, body[4 : 4 + size], complete)
        else:
            (size,) = _U32.unpack_from(body, 4)
            data = body[8 : 8 + size]
            if len(data) >= size:
                self._store(index, subindex, data, complete)
            else:
                self.od.require(index, subindex)  # exists? (abort early otherwise)
                self._download = _Transfer(index, subindex, bytearray(data), 0, size, complete)
        response = _SDO.pack(0x60 | (0x10 if complete else 0), index, subindex) + bytes(4)
        return self._coe(SERVICE_SDO_RESPONSE, response)

    def _store(self, index: int, subindex: int, data: bytes, complete: bool = False) -> None:
        if complete:
            self._store_complete(index, subindex, bytes(data))
        else:
            self.od.write(index, subindex, bytes(data))
        self.transfers += 1

    def _store_complete(self, index: int, subindex: int, data: bytes) -> None:
        """Complete access download: sub 0 (8 bits padded to 16 when starting at 0), then
        the entries in order, each by its own size (ETG.1000.6 §5.6.2.1)."""
        obj = self.od.objects.get(index)
        if obj is None:
            raise SdoAbortError(index, subindex, SdoAbortCode.NO_OBJECT)
        if subindex > 1:
            raise SdoAbortError(index, subindex, SdoAbortCode.UNSUPPORTED_ACCESS)
        pos, count = 0, obj.max_subindex
        if subindex == 0:
            if len(data) < 2:
                raise SdoAbortError(index, subindex, SdoAbortCode.LENGTH_MISMATCH)
            count, pos = data[0], 2
        writes = []
        for sub in range(1, count + 1):
            entry = self.od.require(index, sub)
            size = max(1, (entry.bits + 7) // 8)
            if pos + size > len(data):
                raise SdoAbortError(index, sub, SdoAbortCode.LENGTH_MISMATCH)
            writes.append((sub, data[pos : pos + size]))
            pos += size
        if subindex == 0:
            self.od.write(index, 0, b"\x00")  # as a master does: count 0, entries, count
        for sub, value in writes:
            self.od.write(index, sub, value)
        if subindex == 0:
            self.od.write(index, 0, bytes([count]))

    def _download_segment(self, command: int, body: bytes) -> bytes:
        transfer = self._download
        if transfer is None:
            raise SdoAbortError(0, 0, SdoAbortCode.UNKNOWN_COMMAND)
        toggle = command & 0x10
        if toggle != transfer.toggle:
            raise SdoAbortError(
                transfer.index, transfer.subindex, SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED
            )
        segment = body[1:]
        if len(segment) <= 7:
            segment = segment[: 7 - ((command >> 1) & 0x07)]
        transfer.data += segment
        transfer.toggle ^= 0x10
        if command & 0x01:
            self._download = None
            data = bytes(transfer.data[: transfer.size])
            self._store(transfer.index, transfer.subindex, data, transfer.complete)
        return self._coe(SERVICE_SDO_RESPONSE, bytes([0x20 | toggle]) + bytes(7))

    # --------------------------------------------------------------- upload
    def _upload_initiate(self, command: int, index: int, subindex: int) -> bytes:
        if command & 0x10:
            data = self._complete_object(index, subindex)
        else:
            data = self.od.read(index, subindex)
        head = _SDO.pack
        if 0 < len(data) <= 4:
            self.transfers += 1
            cmd = 0x43 | ((4 - len(data)) << 2)
            return self._coe(
                SERVICE_SDO_RESPONSE, head(cmd, index, subindex) + data.ljust(4, b"\0")
            )
        # Segmented when it does not fit: the initiate response then carries only the
        # complete size and every byte comes in segments (ETG.1000.6 §5.6.2.4). SOEM also
        # accepts data here, but KickCAT and ethercrab discard it, so send none.
        first = data if len(data) <= self._room else b""
        if not first:
            self._upload = _Transfer(index, subindex, bytearray(data), 0)
        else:
            self.transfers += 1
        body = head(0x41 | (command & 0x10), index, subindex) + _U32.pack(len(data)) + first
        return self._coe(SERVICE_SDO_RESPONSE, body)

    def _complete_object(self, index: int, subindex: int) -> bytes:
        """Complete access: sub 0 (padded to 16 bits when starting at 0) and every entry."""
        obj = self.od.objects.get(index)
        if obj is None:
            raise SdoAbortError(index, subindex, SdoAbortCode.NO_OBJECT)
        if subindex > 1:
            raise SdoAbortError(index, subindex, SdoAbortCode.UNSUPPORTED_ACCESS)
        count = obj.entries[0].value[0] if 0 in obj.entries and obj.entries[0].value else 0
        out = bytearray()
        if subindex == 0:
            out += bytes([count, 0])
        for sub in range(1, count + 1):
            out += self.od.read(index, sub)
        return bytes(out)

    def _upload_segment(self, command: int) -> bytes:
        transfer = self._upload
        if transfer is None:
            raise SdoAbortError(0, 0, SdoAbortCode.UNKNOWN_COMMAND)
        toggle = command & 0x10
        if toggle != transfer.toggle:
            raise SdoAbortError(
                transfer.index, transfer.subindex, SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED
            )
        room = self.mailbox_bytes - MAILBOX_HEADER_BYTES - COE_HEADER_BYTES - 1
        segment = bytes(transfer.data[:room])
        del transfer.data[:room]
        last = not transfer.data
        transfer.toggle ^= 0x10
        unused = max(0, 7 - len(segment))
        cmd = toggle | (unused << 1) | (0x01 if last else 0)
        if last:
            self._upload = None
            self.transfers += 1
        return self._coe(SERVICE_SDO_RESPONSE, bytes([cmd]) + segment.ljust(7, b"\0"))

    # ---------------------------------------------------------- information
    def _info_reply(self, opcode: int, data: bytes) -> list[bytes]:
        room = self.mailbox_bytes - MAILBOX_HEADER_BYTES - COE_HEADER_BYTES - 4
        chunks = [data[i : i + room] for i in range(0, len(data), room)] or [b""]
        out = []
        for n, chunk in enumerate(chunks):
            left = len(chunks) - 1 - n
            head = bytes([opcode | (0x80 if left else 0), 0]) + _U16.pack(left)
            out.append(self._coe(SERVICE_SDO_INFORMATION, head + chunk))
        return out

    def _info(self, body: bytes) -> list[bytes]:
        opcode = body[0] & 0x7F
        data = body[4:]
        try:
            if opcode == INFO_OD_LIST_REQUEST and len(data) >= 2:
                return self._od_list(_U16.unpack_from(data)[0])
            if opcode == INFO_OBJECT_DESCRIPTION_REQUEST and len(data) >= 2:
                return self._object_description(_U16.unpack_from(data)[0])
            if opcode == INFO_ENTRY_DESCRIPTION_REQUEST and len(data) >= 4:
                index, sub, info = struct.unpack_from("<HBB", data)
                return self._entry_description(index, sub, info)
        except SdoAbortError as exc:
            return self._info_reply(INFO_ERROR, _U32.pack(exc.code))
        return self._info_reply(INFO_ERROR, _U32.pack(SdoAbortCode.UNKNOWN_COMMAND))

    def _od_list(self, list_type: int) -> list[bytes]:
        objects = list(self.od)
        if list_type == 0:
            counts = [len(objects), len(objects), 0, 0, 0]
            payload = _U16.pack(0) + b"".join(_U16.pack(c) for c in counts)
            return self._info_reply(INFO_OD_LIST_RESPONSE, payload)
        indexes = [o.index for o in objects]
        payload = _U16.pack(list_type) + b"".join(_U16.pack(i) for i in indexes)
        return self._info_reply(INFO_OD_LIST_RESPONSE, payload)

    def _object_description(self, index: int) -> list[bytes]:
        obj = self.od.objects.get(index)
        if obj is None:
            raise SdoAbortError(index, 0, SdoAbortCode.NO_OBJECT)
        first = obj.entries.get(1 if obj.max_subindex else 0)
        dtype = (first.data_type or 0) if first else 0
        payload = struct.pack("<HHBB", index, dtype, obj.max_subindex, obj.object_code)
        return self._info_reply(INFO_OBJECT_DESCRIPTION_RESPONSE, payload + obj.name.encode())

    def _entry_description(self, index: int, subindex: int, info: int) -> list[bytes]:
        entry = self.od.require(index, subindex)
        payload = struct.pack(
            "<HBBHHH", index, subindex, info, entry.data_type or 0, entry.bits, access_word(entry)
        )
        return self._info_reply(INFO_ENTRY_DESCRIPTION_RESPONSE, payload + entry.name.encode())
