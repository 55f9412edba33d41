"""The ESC's register map (ETG.1000.4 6.1, Beckhoff's ESC datasheet section II): addresses, the
AL states and AL status codes, the sync manager and FMMU layouts. Names and numbers only."""

from __future__ import annotations

import struct
from enum import IntEnum

TYPE = 0x0000  # ESC type
REVISION = 0x0001
BUILD = 0x0002  # 2 bytes
FMMUS = 0x0004  # FMMUs supported
SYNC_MANAGERS = 0x0005  # sync managers supported
RAM_SIZE = 0x0006  # process data RAM in KiB
PORT_DESCRIPTOR = 0x0007
FEATURES = 0x0008  # 2 bytes: bit 2 distributed clocks, bit 3 64-bit system time
STATION_ADDRESS = 0x0010  # configured station address, 2 bytes
STATION_ALIAS = 0x0012  # from the SII (word 4) at power-on
DL_CONTROL = 0x0100  # 4 bytes
DL_STATUS = 0x0110  # 2 bytes
AL_CONTROL = 0x0120  # 2 bytes
AL_STATUS = 0x0130  # 2 bytes
AL_STATUS_CODE = 0x0134  # 2 bytes
PDI_CONTROL = 0x0140
PDI_CONFIG = 0x0150
ECAT_EVENT_MASK = 0x0200
AL_EVENT_MASK = 0x0204
AL_EVENT_REQUEST = 0x0220
RX_ERROR_COUNTERS = 0x0300  # to 0x0313: any write clears them
WATCHDOG_DIVIDER = 0x0400  # 2 bytes: the watchdog's unit, (divider + 2) × 40 ns
WATCHDOG_PDI = 0x0410
WATCHDOG_SM = 0x0420  # 2 bytes: the process data (SM) watchdog's time, in units
WATCHDOG_SM_STATUS = 0x0440  # bit 0: 1 = not expired
WATCHDOG_COUNTER_SM = 0x0442
EEPROM_CONFIG = 0x0500  # bit 0: offered to the PDI, bit 1: forced to ECAT
EEPROM_PDI_ACCESS = 0x0501
EEPROM_CONTROL = 0x0502  # 2 bytes: command (write) / status (read)
EEPROM_ADDRESS = 0x0504  # 4 bytes, in 16-bit words
EEPROM_DATA = 0x0508  # 8 bytes
FMMU0 = 0x0600  # 16 bytes each
SM0 = 0x0800  # 8 bytes each
DC_RECEIVE_TIME_PORT0 = 0x0900  # 4 bytes per port, latched by a write to 0x0900
DC_SYSTEM_TIME = 0x0910  # 8 bytes
DC_RECEIVE_TIME_PU = 0x0918  # 8 bytes: local time at the write to 0x0900
DC_SYSTEM_TIME_OFFSET = 0x0920  # 8 bytes
DC_SYSTEM_TIME_DELAY = 0x0928  # 4 bytes
DC_SYSTEM_TIME_DIFFERENCE = 0x092C  # 4 bytes: bit 31 sign, bits 0-30 magnitude (ns)
DC_SPEED_COUNTER_START = 0x0930
DC_TIME_FILTER = 0x0934
DC_CYCLIC_UNIT_CONTROL = 0x0980
DC_ACTIVATION = 0x0981  # bit 0 cyclic operation, bit 1 SYNC0, bit 2 SYNC1
DC_PULSE_LENGTH = 0x0982  # 2 bytes, 10 ns units, from the SII (word 2)
DC_SYNC0_STATUS = 0x098E
DC_START_TIME = 0x0990  # 8 bytes: system time of the first SYNC0
DC_SYNC0_CYCLE = 0x09A0  # 4 bytes, ns
DC_SYNC1_CYCLE = 0x09A4
REGISTERS_END = 0x1000  # process data RAM starts here

FMMU = struct.Struct("<IHBBHBBB3x")  # logical start, length, start bit, end bit, physical, bit, type, on
SYNC_MANAGER = struct.Struct("<HHBBBB")  # start, length, control, status, activate, PDI control

SM_MODE_MASK = 0x03  # control bits 0-1
SM_MODE_BUFFERED = 0x00
SM_MODE_MAILBOX = 0x02
SM_DIRECTION_MASK = 0x0C  # control bits 2-3
SM_DIRECTION_READ = 0x00  # the master reads (the slave writes)
SM_DIRECTION_WRITE = 0x04  # the master writes
SM_WATCHDOG = 0x40  # control bit 6
SM_STATUS_MAILBOX_FULL = 0x08
SM_ENABLE = 0x01  # activate bit 0
SM_REPEAT_REQUEST = 0x02  # activate bit 1
SM_PDI_REPEAT_ACK = 0x02  # PDI control bit 1

EEPROM_READ = 0x0100  # command bits 8-10
EEPROM_WRITE = 0x0200
EEPROM_RELOAD = 0x0300
EEPROM_COMMAND_MASK = 0x0700
EEPROM_WRITE_ENABLE = 0x0001
EEPROM_READ_8_BYTES = 0x0040  # status bit 6
EEPROM_ERROR_COMMAND = 0x0800  # status bit 11: a command not understood
EEPROM_ERROR_ACK = 0x2000  # bit 13: the EEPROM did not acknowledge (an address beyond it)


class AlState(IntEnum):
    """The application layer's states (ETG.1000.6 6.4.1); AL control and status bits 0-3."""

    INIT = 0x01
    PRE_OP = 0x02
    BOOT = 0x03
    SAFE_OP = 0x04
    OP = 0x08


AL_STATE_MASK = 0x0F
AL_ERROR = 0x10  # AL status: error indicator; AL control: error acknowledge


class AlStatusCode(IntEnum):
    """AL status codes (ETG.1000.6 Table 11) this simulator sets."""

    NO_ERROR = 0x0000
    UNSPECIFIED = 0x0001
    INVALID_STATE_CHANGE = 0x0011
    UNKNOWN_STATE = 0x0012
    BOOTSTRAP_NOT_SUPPORTED = 0x0013
    INVALID_MAILBOX_CONFIGURATION = 0x0016
    INVALID_SYNC_MANAGER_CONFIGURATION = 0x0017
    NO_VALID_OUTPUTS = 0x0019
    SYNCHRONIZATION_ERROR = 0x001A
    SYNC_MANAGER_WATCHDOG = 0x001B
    INVALID_OUTPUT_CONFIGURATION = 0x001D
    INVALID_INPUT_CONFIGURATION = 0x001E
    NO_SYNC = 0x002D  # SYNC0 not received (yet)
    INVALID_DC_SYNC_CONFIGURATION = 0x0030
    DC_INVALID_SYNC_CYCLE_TIME = 0x0035


# the state changes a slave takes (ETG.1000.6 Figure 9): to INIT from anywhere, one step up, or down
ALLOWED = frozenset(
    {
        (AlState.INIT, AlState.PRE_OP),
        (AlState.INIT, AlState.BOOT),
        (AlState.BOOT, AlState.INIT),
        (AlState.PRE_OP, AlState.INIT),
        (AlState.PRE_OP, AlState.SAFE_OP),
        (AlState.SAFE_OP, AlState.INIT),
        (AlState.SAFE_OP, AlState.PRE_OP),
        (AlState.SAFE_OP, AlState.OP),
        (AlState.OP, AlState.INIT),
        (AlState.OP, AlState.PRE_OP),
        (AlState.OP, AlState.SAFE_OP),
    }
)
