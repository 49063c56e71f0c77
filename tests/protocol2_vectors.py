"""Protocol 2.0 packets printed in the ROBOTIS e-manual ("DYNAMIXEL Protocol 2.0", Instruction Details),
shared by the CRC, packet and framer tests.  Hex as printed: header first, CRC_L CRC_H last."""

from __future__ import annotations

#: Packets printed in the e-manual's "DYNAMIXEL Protocol 2.0" page, CRC_L CRC_H last.
EMANUAL_PACKETS = {
    "Ping (0x01) instruction": "FF FF FD 00 01 03 00 01 19 4E",
    "Ping status": "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D",
    "Ping broadcast": "FF FF FD 00 FE 03 00 01 31 42",
    "Ping status ID 2": "FF FF FD 00 02 07 00 55 00 06 04 26 6F 6D",
    "Read (0x02)": "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15",
    "Read status": "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0",
    "Write (0x03)": "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89",
    "empty status": "FF FF FD 00 01 04 00 55 00 A1 0C",
    "Reg Write (0x04)": "FF FF FD 00 01 09 00 04 68 00 C8 00 00 00 AE 8E",
    "Action (0x05)": "FF FF FD 00 01 03 00 05 02 CE",
    "Factory Reset (0x06)": "FF FF FD 00 01 04 00 06 01 A1 E6",
    "Reboot (0x08)": "FF FF FD 00 01 03 00 08 2F 4E",
    "Clear (0x10)": "FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC",
    "Control Table Backup (0x20) store": "FF FF FD 00 01 08 00 20 01 43 54 52 4C 16 F5",
    "Sync Read (0x82)": "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA",
    "Sync Read status ID 2": "FF FF FD 00 02 08 00 55 00 1F 08 00 00 BA BE",
    "Sync Write (0x83)": "FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87",
    "Fast Sync Read (0x8A)": "FF FF FD 00 FE 0A 00 8A 84 00 04 00 03 07 04 20 F2",
    "Fast Sync Read status": "FF FF FD 00 FE 19 00 55 00 03 A6 00 00 00 84 08 00 07 1F 08 00 00 16 CA 00 04 FF 03 00 00 D1 9E",
    "Bulk Read (0x92)": "FF FF FD 00 FE 0D 00 92 01 90 00 02 00 02 92 00 01 00 1A 05",
    "Bulk Read status ID 1": "FF FF FD 00 01 06 00 55 00 77 00 C3 69",
    "Bulk Read status ID 2": "FF FF FD 00 02 05 00 55 00 24 8B A9",
    "Bulk Write (0x93)": "FF FF FD 00 FE 10 00 93 01 20 00 02 00 A0 00 02 1F 00 01 00 50 B7 68",
    "Fast Bulk Read status": "FF FF FD 00 FE 14 00 55 00 03 A6 00 00 00 67 A4 00 07 A5 01 24 74 00 04 1F D9 C1",
}


#: Two printed examples whose CRC does not match their bytes, by dynamixel-sdk's updateCRC as well as ours:
#: (bytes before the CRC, CRC printed, CRC of those bytes).
EMANUAL_ERRATA = {
    # Prints 20 F2, the Fast Sync Read example's CRC: a copying slip.
    "Fast Bulk Read (0x9A)": ("FF FF FD 00 FE 12 00 9A 03 84 00 04 00 07 7C 00 02 00 04 92 00 01 00", 0xF220, 0x2DDA),
    # Prints 92 F5 where the bytes give 9E F5 (the store example beside it, 16 F5, is right).
    "Control Table Backup (0x20) restore": ("FF FF FD 00 01 08 00 20 02 43 54 52 4C", 0xF592, 0xF59E),
}
