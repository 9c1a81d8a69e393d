"""miro-gen as a CORBA peer: GIOP 1.0-1.2 over TCP (IIOP), IORs and corbaloc/corbaname URLs,
a CosNaming client, and CosEventComm push suppliers and consumers (docs/CORBA.md).

Generated stubs and skeletons work over IIOP unchanged: `IIOPInvoker` is an `Invoker` for
CORBA objects, `IIOPServer` serves servants to CORBA clients. `Server` and `Client` use them
(miro_gen.service.iiop) when the naming service is a CORBA one (`--naming
corbaloc:iiop:HOST:PORT/NameService`, an IOR, ...) or `--iiop-endpoint` is given. This package
sits below the transport: it imports the run time and the foundations only.
"""

from miro_gen.corba.anys import Any_, read_any, typecode_for, write_any
from miro_gen.corba.bodies import CORBA_SYSTEM_EXCEPTIONS
from miro_gen.corba.client import IIOPInvoker
from miro_gen.corba.ior import IOR, CorbaName, CorbaRef, UrlError, corbaloc, parse_url
from miro_gen.corba.naming import CorbaNaming, NamingContext
from miro_gen.corba.server import IIOPServer
from miro_gen.corba.typecode import TCKind, TypeCode

__all__ = [
    "CORBA_SYSTEM_EXCEPTIONS",
    "IOR",
    "Any_",
    "CorbaName",
    "CorbaNaming",
    "CorbaRef",
    "IIOPInvoker",
    "IIOPServer",
    "NamingContext",
    "TCKind",
    "TypeCode",
    "UrlError",
    "corbaloc",
    "parse_url",
    "read_any",
    "typecode_for",
    "write_any",
]
