"""Python client of the radiosity service (docs/service/python.md).

``connect(address)`` returns a ``Client``; ``local()`` a Client of a private server that lives as
long as the script; ``radiosity.errors`` holds the typed errors; the
generated messages are ``radiosity.v1.service_pb2`` (also exported here as ``pb``).
"""

from radiosity import errors
from radiosity.client import Client, Snapshot, ViewFactors, connect, scene_dependencies
from radiosity.errors import JobFailed, RadiosityError
from radiosity.local import LocalClient, local
from radiosity.v1 import service_pb2 as pb

__all__ = ["Client", "LocalClient", "Snapshot", "ViewFactors", "connect", "local", "errors", "pb", "JobFailed",
           "RadiosityError", "scene_dependencies"]
