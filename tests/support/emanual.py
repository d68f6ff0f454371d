"""The instruction and status packet examples of the ROBOTIS e-manual (Protocol 2.0 page:
Ping, Read, Write, Sync Read, Sync Write, Reboot, Factory Reset), as hex strings."""

EMANUAL = {
    "ping": "FF FF FD 00 01 03 00 01 19 4E",
    "ping status (XM430-W210 1030, fw 38)": "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D",
    "read present position": "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15",
    "read status (166)": "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0",
    "write goal position 512": "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89",
    "write status": "FF FF FD 00 01 04 00 55 00 A1 0C",
    "sync read ids 1, 2": "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA",
    "sync read status id 2 (2079)": "FF FF FD 00 02 08 00 55 00 1F 08 00 00 BA BE",
    "sync write 150, 170": "FF FF FD 00 FE 11 00 83 74 00 04 00"
    " 01 96 00 00 00 02 AA 00 00 00 82 87",
    "factory reset 0x01": "FF FF FD 00 01 04 00 06 01 A1 E6",
    "reboot": "FF FF FD 00 01 03 00 08 2F 4E",
    "action": "FF FF FD 00 01 03 00 05 02 CE",
}
