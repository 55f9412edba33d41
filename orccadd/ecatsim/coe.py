"""The CoE mailbox server of a simulated EtherCAT slave (ETG.1000.6 5.6.2): SDOs over the mailbox.

A CoE message is a mailbox message (`mailbox`) of type 3 whose data start with a 2-byte CoE header
(number in bits 0-8, service in bits 12-15). A SDO request or response then carries CANopen's
8 bytes — command, index (uint16), sub-index (uint8), 4 bytes of data or the complete size
(uint32) — and, in a normal transfer, the data after them in the same message. A segment carries
its command byte and then the data (7 bytes at least, padded). All little-endian.

The server answers what SOEM's `ecx_SDOread` / `ecx_SDOwrite` ask (ethercatcoe.c):

- upload: expedited (1-4 bytes, command 0x43 | unused << 2), normal (0x41, the complete size then
  as many bytes as the mailbox holds, `mailbox_size` - 16), then segments (requests 0x60 / 0x70,
  the toggle alternating from 0; responses of up to `mailbox_size` - 9 bytes, the last one's bit 0
  set, fewer than 7 bytes padded to 7 with their count of unused bytes in bits 1-3);
- download: expedited (0x23 | unused << 2, or 0x22 without a size: the object's size taken, as in
  `ObjectStore.unsized`), normal (0x21: the complete size, then the data; without a size
  indication, 0x20, the data in the message are all of it), then download segments (0x00 / 0x10,
  bit 0 on the last) while the data did not fit; each answered 0x60 or 0x20 | toggle;
- complete access (command bit 4, `complete_access`) for upload and download;
- SDO aborts (service 2 "SDO request", command 0x80, index, sub-index, the code): every refusal of
  the object store, 0x05030000 for a toggle out of turn, 0x05040001 for a command it does not know
  or a segment without a transfer under way, 0x06070010 / 0x06070012 when a normal download's data
  do not match their announced size, 0x08000000 for a value the description cannot encode. An
  abort from the master ends the transfer under way, unanswered. A new initiate request ends the
  transfer under way too.

Anything else is answered with a mailbox error reply (`mailbox.ErrorDetail`): no room for the 6-byte
header 0x0001 (syntax), a length beyond the buffer 0x0008 (invalid size), a channel other than 0
0x0003, a type other than CoE 0x0002 (unsupported protocol), a CoE service other than "SDO
request" (SDO information, PDOs by mailbox, ...) 0x0004 (service not supported), fewer bytes than
the CoE header or a SDO request need 0x0006 (size too short).

Counters (ETG.1000.4): a message whose counter is not 0 and equals the previous message's is the
master repeating it and is ignored; the server's own messages count 1..7, then 1 again. `reset`
(mailbox set up again, INIT to PRE-OP) starts both over.

No I/O: messages come in through `on_mailbox`, go out through `post`. Every method may be called
from a tick.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum

from orccadd.drivesim.objects import (
    ABORT_COMMAND,
    ABORT_GENERAL,
    ABORT_LENGTH,
    ABORT_READ_ONLY,
    ABORT_TOGGLE,
    ABORT_TOO_LONG,
    VARIABLE_SIZE,
    ObjectStore,
    SdoAbortError,
)
from orccadd.ecatsim.complete_access import check_complete, read_complete, write_complete
from orccadd.ecatsim.mailbox import (
    HEADER,
    ErrorDetail,
    MailboxHeader,
    MailboxType,
    error_reply,
    message,
    next_counter,
)

COE_HEADER = struct.Struct("<H")  # number in bits 0-8, service in bits 12-15
SDO = struct.Struct("<BHBI")  # command, index, sub-index, data or complete size or abort code
SEGMENT_MIN_DATA = 7  # bytes a segment carries at least (padded)
NORMAL_OVERHEAD = HEADER.size + COE_HEADER.size + SDO.size  # 16 bytes before a normal transfer's data
SEGMENT_OVERHEAD = HEADER.size + COE_HEADER.size + 1  # 9 bytes before a segment's data
EXPEDITED_MAX = 4  # bytes
ERROR_REGISTER = (0x1001, 0)
EMERGENCY = struct.Struct("<HB")  # error code, error register; then 5 manufacturer bytes
EMERGENCY_MANUFACTURER = 5  # bytes

# the command byte: the specifier in bits 5-7, then flags
CCS_DOWNLOAD_SEGMENT, CCS_DOWNLOAD, CCS_UPLOAD, CCS_UPLOAD_SEGMENT, CCS_ABORT = 0, 1, 2, 3, 4
COMPLETE_ACCESS = 0x10
TOGGLE = 0x10
EXPEDITED = 0x02
SIZE_INDICATED = 0x01
LAST_SEGMENT = 0x01
UPLOAD_EXPEDITED = 0x43  # | unused bytes << 2
UPLOAD_NORMAL = 0x41  # | COMPLETE_ACCESS
DOWNLOAD_RESPONSE = 0x60
DOWNLOAD_SEGMENT_RESPONSE = 0x20  # | toggle
ABORT = 0x80


class CoeService(IntEnum):
    """The CoE header's service (bits 12-15)."""

    EMERGENCY = 1
    SDO_REQUEST = 2
    SDO_RESPONSE = 3
    TXPDO = 4
    RXPDO = 5
    TXPDO_REMOTE = 6
    RXPDO_REMOTE = 7
    SDO_INFORMATION = 8


@dataclass
class _Transfer:
    """A segmented SDO transfer under way."""

    index: int
    sub: int
    complete_access: bool
    upload: bool
    data: bytes = b""  # upload: all the object's bytes
    offset: int = 0  # upload: bytes sent so far
    received: bytearray = field(default_factory=bytearray)  # download: the bytes so far
    size: int = 0  # download: the complete size announced
    toggle: int = 0  # the toggle bit (0 or TOGGLE) the next segment must carry


class CoeServer:
    """SDOs over the mailbox for one slave's `store`. `post` receives each message for the master
    unpadded (the 6-byte header and `length` bytes, never more than `mailbox_size`): the ESC pads it
    to the send mailbox (SM1) and queues what the master has not read yet. `mailbox_size` is the
    mailboxes' length in bytes (both directions alike, 16 at least)."""

    def __init__(self, store: ObjectStore, post: Callable[[bytes], None], mailbox_size: int) -> None:
        if mailbox_size < NORMAL_OVERHEAD:
            raise ValueError(f"mailbox_size (={mailbox_size}) must be at least {NORMAL_OVERHEAD} bytes")
        self.store = store
        self.post = post
        self.mailbox_size = mailbox_size
        self._counter_in = 0  # the last message's counter
        self._counter_out = 0
        self._transfer: _Transfer | None = None

    def reset(self) -> None:
        """The mailbox set up again: counters from 0, any transfer dropped."""
        self._counter_in = self._counter_out = 0
        self._transfer = None

    # ---- messages in -----------------------------------------------------------------------------
    def on_mailbox(self, data: bytes) -> None:
        """The receive mailbox (SM0) as the master wrote it: header first, `mailbox_size` bytes."""
        if len(data) < HEADER.size:
            self._error(ErrorDetail.SYNTAX)
            return
        header = MailboxHeader.parse(data)
        if header.counter and header.counter == self._counter_in:
            return  # the master's repeat
        self._counter_in = header.counter
        detail = _header_fault(header, len(data))
        if detail is not None:
            self._error(detail)
            return
        body = bytes(data[HEADER.size : HEADER.size + header.length])
        if len(body) < COE_HEADER.size:
            self._error(ErrorDetail.SIZE_TOO_SHORT)
            return
        (coe,) = COE_HEADER.unpack_from(body)
        if coe >> 12 != CoeService.SDO_REQUEST:
            self._error(ErrorDetail.SERVICE_NOT_SUPPORTED)
        elif len(body) < COE_HEADER.size + SDO.size:
            self._error(ErrorDetail.SIZE_TOO_SHORT)
        else:
            self._sdo(body[COE_HEADER.size :])

    def _sdo(self, req: bytes) -> None:
        ccs = req[0] >> 5
        try:
            if ccs == CCS_ABORT:
                self._transfer = None
            elif ccs == CCS_UPLOAD_SEGMENT:
                self._upload_segment(req)
            elif ccs == CCS_DOWNLOAD_SEGMENT:
                self._download_segment(req)
            else:
                self._transfer = None
                self._initiate(req)
        except SdoAbortError as e:
            self._abort(req, e.code)
        except (ValueError, TypeError, struct.error):  # a value the description cannot encode
            self._abort(req, ABORT_GENERAL)

    def _initiate(self, req: bytes) -> None:
        cmd, index, sub, word = SDO.unpack_from(req)
        ccs = cmd >> 5
        if ccs == CCS_UPLOAD:
            self._upload(index, sub, bool(cmd & COMPLETE_ACCESS))
        elif ccs == CCS_DOWNLOAD:
            self._download(cmd, index, sub, word, req[SDO.size :])
        else:
            raise SdoAbortError(ABORT_COMMAND)  # block transfers and unknown commands

    # ---- upload ----------------------------------------------------------------------------------
    def _upload(self, index: int, sub: int, complete: bool) -> None:
        data = read_complete(self.store, index, sub) if complete else self.store.read(index, sub)
        if not complete and 0 < len(data) <= EXPEDITED_MAX:
            unused = EXPEDITED_MAX - len(data)
            word = int.from_bytes(data, "little")
            self._respond(SDO.pack(UPLOAD_EXPEDITED | unused << 2, index, sub, word))
            return
        room = self.mailbox_size - NORMAL_OVERHEAD
        cmd = UPLOAD_NORMAL | (COMPLETE_ACCESS if complete else 0)
        self._respond(SDO.pack(cmd, index, sub, len(data)) + data[:room])
        if len(data) > room:
            self._transfer = _Transfer(index, sub, complete, True, data=data, offset=room)

    def _upload_segment(self, req: bytes) -> None:
        t = self._segment_transfer(req[0], upload=True)
        room = self.mailbox_size - SEGMENT_OVERHEAD
        chunk = t.data[t.offset : t.offset + room]
        t.offset += len(chunk)
        last = t.offset >= len(t.data)
        unused = max(0, SEGMENT_MIN_DATA - len(chunk))
        cmd = (req[0] & TOGGLE) | unused << 1 | (LAST_SEGMENT if last else 0)
        self._respond(bytes([cmd]) + chunk + bytes(unused))
        if last:
            self._transfer = None

    # ---- download --------------------------------------------------------------------------------
    def _download(self, cmd: int, index: int, sub: int, word: int, rest: bytes) -> None:
        complete = bool(cmd & COMPLETE_ACCESS)
        self._check_writable(index, sub, complete)
        if cmd & EXPEDITED:
            data = word.to_bytes(EXPEDITED_MAX, "little")
            if cmd & SIZE_INDICATED:
                data = data[: EXPEDITED_MAX - (cmd >> 2 & 0x3)]
            elif not complete:
                data = self.store.unsized(self.store.var(index, sub), data)
            self._write(index, sub, complete, data)
        else:
            size = word if cmd & SIZE_INDICATED else len(rest)
            if len(rest) > size:
                raise SdoAbortError(ABORT_TOO_LONG)
            if len(rest) == size:
                self._write(index, sub, complete, rest)
            else:
                self._check_size(index, sub, complete, size)
                self._transfer = _Transfer(index, sub, complete, False, received=bytearray(rest), size=size)
        self._respond(SDO.pack(DOWNLOAD_RESPONSE, index, sub, 0))

    def _download_segment(self, req: bytes) -> None:
        t = self._segment_transfer(req[0], upload=False)
        cmd = req[0]
        n = len(req) - 1
        if cmd & LAST_SEGMENT and n == SEGMENT_MIN_DATA:
            n -= cmd >> 1 & 0x7  # unused bytes of a short last segment
        t.received += req[1 : 1 + n]
        if len(t.received) > t.size:
            raise SdoAbortError(ABORT_TOO_LONG)
        if cmd & LAST_SEGMENT:
            self._transfer = None
            if len(t.received) != t.size:
                raise SdoAbortError(ABORT_LENGTH)
            self._write(t.index, t.sub, t.complete_access, bytes(t.received))
        self._respond(bytes([DOWNLOAD_SEGMENT_RESPONSE | (cmd & TOGGLE)]) + bytes(SEGMENT_MIN_DATA))

    def _check_writable(self, index: int, sub: int, complete: bool) -> None:
        if complete:
            check_complete(self.store, index, sub)
        elif not self.store.var(index, sub).writable:
            raise SdoAbortError(ABORT_READ_ONLY)

    def _check_size(self, index: int, sub: int, complete: bool, size: int) -> None:
        """A segmented download of a fixed-size entry announces its size: refused at once."""
        if complete:
            return
        var = self.store.var(index, sub)
        if var.data_type not in VARIABLE_SIZE and size != len(var) // 8:
            raise SdoAbortError(ABORT_LENGTH)

    def _write(self, index: int, sub: int, complete: bool, data: bytes) -> None:
        if complete:
            write_complete(self.store, index, sub, data)
        else:
            self.store.write(index, sub, data)

    # ---- segments, aborts, messages out ----------------------------------------------------------
    def _segment_transfer(self, cmd: int, upload: bool) -> _Transfer:
        """The transfer a segment request continues, its toggle checked and turned."""
        t = self._transfer
        if t is None or t.upload != upload:
            raise SdoAbortError(ABORT_COMMAND)
        if cmd & TOGGLE != t.toggle:
            raise SdoAbortError(ABORT_TOGGLE)
        t.toggle ^= TOGGLE
        return t

    def _abort(self, req: bytes, code: int) -> None:
        """Abort SDO transfer request: the request's index and sub-index (a segment's: its transfer's)."""
        t = self._transfer
        if req[0] >> 5 in (CCS_UPLOAD_SEGMENT, CCS_DOWNLOAD_SEGMENT):
            index, sub = (t.index, t.sub) if t is not None else (0, 0)
        else:
            _, index, sub, _ = SDO.unpack_from(req)
        self._transfer = None
        self._post_coe(CoeService.SDO_REQUEST, SDO.pack(ABORT, index, sub, code))

    def emergency(self, code: int, register: int, manufacturer: bytes = b"") -> None:
        """Post a CoE emergency: `code` (uint16, 0 = error reset), the error `register` (uint8, also
        stored in 0x1001 if the description has it) and up to 5 manufacturer-specific bytes."""
        if self.store.has(*ERROR_REGISTER):
            self.store.set(*ERROR_REGISTER, register)
        extra = manufacturer[:EMERGENCY_MANUFACTURER].ljust(EMERGENCY_MANUFACTURER, b"\x00")
        self._post_coe(CoeService.EMERGENCY, EMERGENCY.pack(code, register) + extra)

    def _respond(self, sdo: bytes) -> None:
        self._post_coe(CoeService.SDO_RESPONSE, sdo)

    def _post_coe(self, service: CoeService, payload: bytes) -> None:
        self.post(message(MailboxType.COE, self._next_counter(), COE_HEADER.pack(service << 12) + payload))

    def _error(self, detail: ErrorDetail) -> None:
        self.post(error_reply(detail, self._next_counter()))

    def _next_counter(self) -> int:
        self._counter_out = next_counter(self._counter_out)
        return self._counter_out


def _header_fault(header: MailboxHeader, buffer_size: int) -> ErrorDetail | None:
    """What is wrong with a mailbox header for this server, if anything."""
    if HEADER.size + header.length > buffer_size:
        return ErrorDetail.INVALID_SIZE
    if header.channel != 0:
        return ErrorDetail.INVALID_CHANNEL
    if header.type != MailboxType.COE:
        return ErrorDetail.UNSUPPORTED_PROTOCOL
    return None
