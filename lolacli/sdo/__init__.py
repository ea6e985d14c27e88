"""SDO access to slaves: one client API over interchangeable transports.

* :mod:`lolacli.sdo.client` — the :class:`SdoClient` seam, typed :func:`read`/:func:`write`;
* :mod:`lolacli.od` (not here: a lower layer) — the one dictionary model, from EDS, ESI,
  ENI or SDO Information;
* :mod:`lolacli.sdo.canopen_client` — CANopen (canopen + python-can);
* :mod:`lolacli.sdo.soem_client` — EtherCAT through pysoem;
* :mod:`lolacli.sdo.session` — transport selection and SLAVE resolution;
* :mod:`lolacli.sdo.check` — ``sdo check`` files;
* :mod:`lolacli.sdo.node` — CANopen nodes served from an EDS (tests, users without hardware).

Only light modules load here; canopen, python-can, pysoem and PyYAML load when a
transport or a check file needs them.
"""

from lolacli.sdo.client import SdoClient, SdoValue, read, write

__all__ = ["SdoClient", "SdoValue", "read", "write"]
