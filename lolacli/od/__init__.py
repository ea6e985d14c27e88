"""The one object-dictionary model (:mod:`lolacli.od.model`) and the sources that are not
files of ours: the CiA 301 communication objects (:mod:`lolacli.od.cia301`) and EDS/DCF
through canopen (:mod:`lolacli.od.eds`). ESI and ENI dictionaries are read by
:mod:`lolacli.eni`; values are typed by :mod:`lolacli.wire.datatypes`.

Pure (no IO): above :mod:`lolacli.wire` (the codec), below :mod:`lolacli.eni` (whose ESI
and ENI readers build it), so every layer that has a dictionary — devices, emulator,
capture, master, sdo — reads the same one.
"""

from lolacli.od.model import (
    ARRAY,
    RECORD,
    VAR,
    Dictionary,
    ObjectCode,
    OdEntry,
    OdObject,
    access_text,
    access_word,
    from_sdo_info,
    info_entry,
    object_code,
    pdo_configuration,
    typed_value,
)

__all__ = [
    "ARRAY",
    "RECORD",
    "VAR",
    "Dictionary",
    "ObjectCode",
    "OdEntry",
    "OdObject",
    "access_text",
    "access_word",
    "from_sdo_info",
    "info_entry",
    "object_code",
    "pdo_configuration",
    "typed_value",
]
