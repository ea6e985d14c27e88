"""SDO in a few lines: read, write and list through lolacli's own master, against the LOLA
chain emulated in this process (``TransportOptions(iface="eth0")`` for a live bus)."""

from lolacli.sdo import read, write
from lolacli.sdo.session import TransportOptions, open_session
from lolacli.wire.datatypes import DataType

with open_session(TransportOptions()) as bus:  # the embedded LOLA chain, brought up on demand
    drive = bus.target("Joint05 L Ankle A")  # or a position ("5") or a station ("@1005")
    print(read(drive.client, 0x1018, 2).value)  # product code: 198948
    write(drive.client, 0x607F, 0, 250000, data_type=DataType.UNSIGNED32)
    velocity = read(drive.client, 0x607F, 0, data_type=DataType.UNSIGNED32)
    print(velocity.value, velocity.raw.hex())  # 250000 90d00300
    objects = drive.client.dictionary()  # the slave's SDO Information service
    print(len(objects), objects.entry(0x6041, 0).name)  # 40 Statusword
