"""Typed errors of the radiosity client: one class per gRPC status code.

Every error carries the gRPC status code (``code``, a ``grpc.StatusCode``), the server's message
(``message``) and, where the message names a field of the request (``solve.max_rays: -1 is
outside [0, inf)``), that field's path (``field``, else ``None``).
"""

import re

import grpc


class RadiosityError(Exception):
    """A call to the radiosity service failed (or the client refused to make it)."""

    code = grpc.StatusCode.UNKNOWN

    def __init__(self, message, code=None, field=None):
        super().__init__(message)
        self.message = message
        if code is not None:
            self.code = code
        self.field = field

    def __str__(self):
        return f"{self.code.name}: {self.message}"


class InvalidArgument(RadiosityError):
    """A bad scene or parameter; ``field`` names the parameter when the server did."""

    code = grpc.StatusCode.INVALID_ARGUMENT


class NotFound(RadiosityError):
    code = grpc.StatusCode.NOT_FOUND


class AlreadyExists(RadiosityError):
    code = grpc.StatusCode.ALREADY_EXISTS


class FailedPrecondition(RadiosityError):
    """The resource is in the wrong state (e.g. cancelling a job that has ended)."""

    code = grpc.StatusCode.FAILED_PRECONDITION


class ResourceExhausted(RadiosityError):
    """A server limit or quota (the message names the server flag)."""

    code = grpc.StatusCode.RESOURCE_EXHAUSTED


class Cancelled(RadiosityError):
    code = grpc.StatusCode.CANCELLED


class Unavailable(RadiosityError):
    """The server cannot be reached or is shutting down: retry."""

    code = grpc.StatusCode.UNAVAILABLE


class Unauthenticated(RadiosityError):
    """No token, or a token the server does not know."""

    code = grpc.StatusCode.UNAUTHENTICATED


class PermissionDenied(RadiosityError):
    code = grpc.StatusCode.PERMISSION_DENIED


class DeadlineExceeded(RadiosityError):
    code = grpc.StatusCode.DEADLINE_EXCEEDED


class Internal(RadiosityError):
    code = grpc.StatusCode.INTERNAL


class JobFailed(RadiosityError):
    """A job ended FAILED; ``job`` is its final state (``job.error`` says why). It is also an
    instance of its error code's class, so ``except ResourceExhausted`` catches a job that failed
    over the server's memory cap as well as a refused request."""

    def __new__(cls, job, *args, **kwargs):
        if cls is JobFailed:
            base = _CLASSES.get(_CODES_BY_VALUE.get(job.error.code, grpc.StatusCode.UNKNOWN))
            if base is not None:
                cls = _JOB_FAILED_CLASSES.setdefault(
                    base, type(f"JobFailed{base.__name__}", (JobFailed, base), {}))
        return super().__new__(cls)

    def __init__(self, job):
        code = _CODES_BY_VALUE.get(job.error.code, grpc.StatusCode.UNKNOWN)
        super().__init__(f"{job.name} failed: {job.error.message}", code=code)
        self.job = job


_CLASSES = {
    cls.code: cls
    for cls in (InvalidArgument, NotFound, AlreadyExists, FailedPrecondition, ResourceExhausted,
                Cancelled, Unavailable, Unauthenticated, PermissionDenied, DeadlineExceeded,
                Internal)
}
_CODES_BY_VALUE = {code.value[0]: code for code in grpc.StatusCode}
_JOB_FAILED_CLASSES = {}  # JobFailed with each code's class, made when first raised.

# A field path at the start of a message: "solve.max_rays: ...", "page_token '...' is not valid".
_LEADING_PATH = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*(?:\[\d+\])?(?:\.[A-Za-z_][A-Za-z0-9_]*(?:\[\d+\])?)*)[:' ]")


def field_of(message, request_descriptor):
    """The field path a server message begins with, if it is a field of the request's message
    type (so that file names such as ``box.obj:12:`` are not taken for fields); else None."""
    match = _LEADING_PATH.match(message or "")
    if not match or request_descriptor is None:
        return None
    path = match.group(1)
    descriptor = request_descriptor
    for part in path.split("."):
        name = part.split("[", 1)[0]
        field = descriptor.fields_by_name.get(name) if descriptor else None
        if field is None:
            return None
        descriptor = field.message_type
    return path


def from_rpc_error(error, request_descriptor=None):
    """The typed error of a ``grpc.RpcError``."""
    code = error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
    message = error.details() if hasattr(error, "details") else str(error)
    cls = _CLASSES.get(code, RadiosityError)
    return cls(message or "", code=code, field=field_of(message, request_descriptor))
