"""Python client of the radiosity service (README "Python client").

``connect(address)`` returns a ``Client``; ``radiosity.errors`` holds the typed errors; the
generated messages are ``radiosity.v1.service_pb2`` (also exported here as ``pb``).
"""

from radiosity import errors
from radiosity.client import Client, Snapshot, ViewFactors, connect, scene_dependencies
from radiosity.errors import JobFailed, RadiosityError
from radiosity.v1 import service_pb2 as pb

__all__ = ["Client", "Snapshot", "ViewFactors", "connect", "errors", "pb", "JobFailed",
           "RadiosityError", "scene_dependencies"]
