"""A private radiosity server for one script: ``radiosity.local()``.

The CLI without ``--server`` runs the service inside its own process; a Python script gets the
same by starting ``radiosity-server`` on a Unix socket in a temporary directory, for as long as
the script (or the ``with`` block) runs:

    import radiosity
    with radiosity.local() as client:
        job = client.solve(client.upload("scenes/cornell_box.obj"), wait=True)

The server program is ``server`` if given, else $RADIOSITY_SERVER_BIN, else ``radiosity-server``
on PATH. Its data (scenes, jobs, results) lives in the temporary directory and is deleted when
the client closes, unless ``data_dir`` names a directory to keep it in.
"""

import atexit
import os
import shutil
import subprocess
import tempfile
import time

import grpc

from radiosity import errors
from radiosity.client import Client


def _server_program(server):
    for candidate in (server, os.environ.get("RADIOSITY_SERVER_BIN")):
        if candidate:
            if not (os.path.isfile(candidate) and os.access(candidate, os.X_OK)):
                raise errors.InvalidArgument(f"{candidate} is not an executable radiosity-server",
                                             field="server")
            return candidate
    found = shutil.which("radiosity-server")
    if found is None:
        raise errors.FailedPrecondition(
            "radiosity-server is not on PATH: build it (bash deploy/quickstart.sh demo builds "
            "build/bin/radiosity-server) and add its directory to PATH, set "
            "$RADIOSITY_SERVER_BIN, or pass server=PATH", field="server")
    return found


class LocalClient(Client):
    """A Client of a private server, which it stops (and whose data it deletes) on close()."""

    def __init__(self, *, server=None, data_dir=None, workers=1, threads_per_job=0,
                 startup_timeout=60.0, **options):
        program = _server_program(server)
        self._tmp = tempfile.mkdtemp(prefix="radiosity-local-")
        self._process = None
        socket = os.path.join(self._tmp, "server.sock")
        data = data_dir or os.path.join(self._tmp, "data")
        self._log_path = os.path.join(self._tmp, "server.log")
        with open(self._log_path, "wb") as log:
            self._process = subprocess.Popen(
                [program, "--listen", "unix:" + socket, "--data-dir", data,
                 "--workers", str(workers), "--threads-per-job", str(threads_per_job),
                 "--log-level", "warn"],
                stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT)
        atexit.register(self.close)
        super().__init__("unix:" + socket, **options)
        deadline = time.monotonic() + startup_timeout
        while True:
            if self._process.poll() is not None:
                message = self._log_tail()
                self.close()
                raise errors.Unavailable(f"{program} exited with {self._process.returncode}: "
                                         f"{message}")
            try:
                grpc.channel_ready_future(self._channel).result(timeout=0.2)
                break
            except grpc.FutureTimeoutError:
                if time.monotonic() > deadline:
                    self.close()
                    raise errors.Unavailable(f"{program} did not answer within "
                                             f"{startup_timeout:g} s") from None

    def _log_tail(self):
        try:
            with open(self._log_path, encoding="utf-8", errors="replace") as f:
                return f.read()[-2000:].strip() or "(no output)"
        except OSError:
            return "(no log)"

    def close(self):
        if getattr(self, "_channel", None) is not None:
            super().close()
        if self._process is not None and self._process.poll() is None:
            self._process.terminate()
            try:
                self._process.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
        if self._tmp and os.path.isdir(self._tmp):
            shutil.rmtree(self._tmp, ignore_errors=True)
        self._tmp = None


def local(**options) -> LocalClient:
    """A Client of a private server on a Unix socket in a temporary directory, stopped when the
    client closes (or the script ends). Options: server (the program), data_dir (keep the data
    there), workers, threads_per_job (0: all cores), startup_timeout (seconds), and Client's
    (timeout)."""
    return LocalClient(**options)
