"""The radiosity service from Python: a thin layer over the generated gRPC stubs
(``radiosity.v1.service_pb2``, made from ``proto/`` at build time).

    import radiosity
    with radiosity.connect("127.0.0.1:50051") as client:
        scene = client.upload("scenes/cornell_box.obj")
        job = client.solve(scene, max_seconds=30)
        for snap in client.watch(job):
            print(snap.sequence, snap.progress.unshot_fraction, snap.radiosity.shape)
        client.download(job, "out")

Names: every call takes a resource's name ("scenes/ID", "jobs/ID") or the message that holds it.
Errors: ``radiosity.errors`` (one class per gRPC status code, with the field the server named).
Units: as in service.proto (radiosity in W per square scene unit per channel).
"""

import csv
import hashlib
import io
import json
import os
import posixpath
from dataclasses import dataclass
from typing import Iterator, List, Optional

import grpc
import numpy as np

from radiosity import errors
from radiosity.v1 import service_pb2 as pb
from radiosity.v1 import service_pb2_grpc as pb_grpc

CHUNK_BYTES = 1 << 20  # The API's largest chunk payload.
_MAX_MESSAGE = 4 << 20

_METHODS = {
    "auto": pb.SOLVE_METHOD_AUTO,
    "progressive": pb.SOLVE_METHOD_PROGRESSIVE,
    "gauss-seidel": pb.SOLVE_METHOD_GAUSS_SEIDEL,
    "jacobi": pb.SOLVE_METHOD_JACOBI,
    "reflection": pb.SOLVE_METHOD_REFLECTION,
    "hierarchical": pb.SOLVE_METHOD_HIERARCHICAL,
}
_ESTIMATORS = {
    "montecarlo": pb.ESTIMATOR_MONTECARLO,
    "analytic": pb.ESTIMATOR_ANALYTIC,
    "hemicube": pb.ESTIMATOR_HEMICUBE,
}
_SAMPLINGS = {
    "sobol": pb.SAMPLING_SOBOL,
    "random": pb.SAMPLING_RANDOM,
    "stratified": pb.SAMPLING_STRATIFIED,
    "halton": pb.SAMPLING_HALTON,
}
_SCENE_EXTENSIONS = {
    ".obj": pb.SCENE_FORMAT_OBJ,
    ".json": pb.SCENE_FORMAT_JSON,
    ".pb": pb.SCENE_FORMAT_BINARY,
    ".binpb": pb.SCENE_FORMAT_BINARY,
}
_MODEL_EXTENSIONS = {".gltf", ".glb", ".fbx", ".dae", ".3ds", ".ply", ".stl"}
_ENDED = {pb.JOB_STATE_SUCCEEDED, pb.JOB_STATE_FAILED, pb.JOB_STATE_CANCELLED}


@dataclass
class Snapshot:
    """One snapshot of a converging solve (WatchJobResponse, its chunks joined).

    ``radiosity``: float32 array of shape (elements, 2, 3): element (elements.csv order), side
    (0 front, 1 back; 0 where there is no back side), channel; None for progress-only watches or
    before the mesh exists. ``std_error``: the same shape, with ``errors=True`` where the method
    estimates them, else None. ``final``: the job has ended and this is its result.
    """

    sequence: int
    state: int
    progress: pb.JobProgress
    final: bool
    resync: bool
    elements: int
    mesh_version: int
    attempts: int
    radiosity: Optional[np.ndarray] = None
    std_error: Optional[np.ndarray] = None
    error: Optional[pb.JobError] = None

    @property
    def state_name(self):
        return pb.JobState.Name(self.state)


@dataclass
class ViewFactors:
    """Surface-to-surface view factors: ``matrix[i, j]`` is F from ``surfaces[i]`` to
    ``surfaces[j]`` (rows sum to the fraction of i's light that meets another surface)."""

    surfaces: List[str]
    matrix: np.ndarray
    job: pb.Job


def _name(resource, collection):
    """'scenes/ID' from a name, a bare id or a message with a name."""
    name = getattr(resource, "name", resource)
    if not isinstance(name, str) or not name:
        raise errors.InvalidArgument(f"expected a {collection} name or message, got {resource!r}")
    return name if name.startswith(collection + "/") else f"{collection}/{name}"


def _read_first_line(path):
    with open(path, encoding="utf-8") as f:
        return f.readline().strip()


def _safe_relative(name):
    """A '/'-separated relative name without '.' or '..' components, or None."""
    name = posixpath.normpath(name.replace("\\", "/"))
    if name.startswith("/") or name == "." or ".." in name.split("/"):
        return None
    return name


def scene_dependencies(main_path):
    """Names (relative to the main file's directory) of the files a scene reads besides itself:
    an OBJ's material libraries (``mtllib``) that exist, a .gltf's buffers and images."""
    directory = os.path.dirname(os.path.abspath(main_path))
    extension = os.path.splitext(main_path)[1].lower()
    names = []
    if extension == ".obj":
        with open(main_path, "rb") as f:
            data = f.read()
        # As the loader reads it: UTF-16 with a byte-order mark, else UTF-8, else Latin-1.
        if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
            text = data.decode("utf-16", "replace")
        else:
            try:
                text = data.decode("utf-8")
            except UnicodeDecodeError:
                text = data.decode("latin-1")
        for line in text.splitlines():
            line = line.strip()
            if not line.startswith("mtllib"):
                continue
            rest = line[len("mtllib"):].strip()
            # A name with spaces is one library when that file exists, else each word is.
            candidates = [rest] if os.path.isfile(os.path.join(directory, rest)) else rest.split()
            for candidate in candidates:
                name = _safe_relative(candidate)
                if name and os.path.isfile(os.path.join(directory, name)) and name not in names:
                    names.append(name)
    elif extension == ".gltf":
        # The buffers and images it names that exist (as the CLI sends them; a missing texture is
        # the server's to warn about, a missing buffer its to refuse). glTF 1.0 keeps them in
        # objects, 2.0 in arrays; a file that is not JSON is the server's to refuse, by name.
        try:
            with open(main_path, "rb") as f:
                gltf = json.loads(f.read().decode("utf-8-sig"))
        except (ValueError, UnicodeDecodeError):
            return names
        if not isinstance(gltf, dict):
            return names
        entries = []
        for key in ("buffers", "images"):
            group = gltf.get(key, [])
            entries.extend(group.values() if isinstance(group, dict) else
                           group if isinstance(group, list) else [])
        for entry in entries:
            uri = entry.get("uri", "") if isinstance(entry, dict) else ""
            if not isinstance(uri, str) or not uri or uri.startswith("data:"):
                continue
            name = _safe_relative(uri)
            if name and name not in names and os.path.isfile(os.path.join(directory, name)):
                names.append(name)
    return names


def _main_file_of(directory):
    candidates = sorted(
        f for f in os.listdir(directory)
        if os.path.isfile(os.path.join(directory, f)) and
        os.path.splitext(f)[1].lower() in set(_SCENE_EXTENSIONS) | _MODEL_EXTENSIONS)
    if len(candidates) != 1:
        raise errors.InvalidArgument(
            f"{directory}: a folder is uploaded by its one scene file (.obj, .json, .pb, .gltf, "
            f".glb, ...); found {len(candidates)}: {', '.join(candidates) or 'none'}; pass the "
            f"main file instead")
    return os.path.join(directory, candidates[0])


class Client:
    """A connection to a radiosity server.

    ``address``: HOST:PORT (default: $RADIOSITY_SERVER, else 127.0.0.1:50051). TLS when any of
    ``tls``, ``tls_ca``, ``tls_cert``/``tls_key`` is given (``tls=True``: the system's CAs).
    ``token``: the bearer token of a server with tenants (default: $RADIOSITY_TOKEN); sent only
    over TLS. ``timeout``: seconds each unary call may take (streams run until they end).
    """

    def __init__(self, address=None, *, tls=False, tls_ca=None, tls_cert=None, tls_key=None,
                 server_name=None, token=None, timeout=60.0):
        self.address = address or os.environ.get("RADIOSITY_SERVER", "127.0.0.1:50051")
        self.timeout = timeout
        # Uploads and downloads move files: at least 10 minutes unless there is no limit at all.
        self._transfer_timeout = None if timeout is None else max(timeout, 600)
        if token is None:
            token = os.environ.get("RADIOSITY_TOKEN", "")
        token = token.strip() or None
        options = [("grpc.max_receive_message_length", _MAX_MESSAGE),
                   ("grpc.keepalive_time_ms", 60000)]
        secure = tls or tls_ca or tls_cert or tls_key
        if not secure:
            if token:
                raise errors.InvalidArgument(
                    "a bearer token is sent only over TLS: pass tls_ca=FILE (or tls=True for the "
                    "system's CAs)", field="token")
            self._channel = grpc.insecure_channel(self.address, options=options)
        else:
            if bool(tls_cert) != bool(tls_key):
                raise errors.InvalidArgument("tls_cert and tls_key go together", field="tls_cert")

            def pem(path, what):
                if path is None:
                    return None
                try:
                    with open(path, "rb") as f:
                        return f.read()
                except OSError as e:
                    raise errors.InvalidArgument(f"{what}: {path}: {e.strerror}", field=what) from e

            credentials = grpc.ssl_channel_credentials(
                root_certificates=pem(tls_ca, "tls_ca"),
                private_key=pem(tls_key, "tls_key"),
                certificate_chain=pem(tls_cert, "tls_cert"))
            if token:
                credentials = grpc.composite_channel_credentials(
                    credentials, grpc.access_token_call_credentials(token))
            if server_name:
                options.append(("grpc.ssl_target_name_override", server_name))
            self._channel = grpc.secure_channel(self.address, credentials, options=options)
        self._stub = pb_grpc.RadiosityServiceStub(self._channel)

    # --- plumbing -------------------------------------------------------------------------------

    def close(self):
        self._channel.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _call(self, method, request, timeout=None):
        try:
            return method(request, timeout=timeout or self.timeout)
        except grpc.RpcError as e:
            raise errors.from_rpc_error(e, request.DESCRIPTOR) from None

    # --- scenes ---------------------------------------------------------------------------------

    def upload(self, path, *, extra_files=(), request_id=None, display_name=None, strict=False,
               vertex_colors=False) -> pb.SceneInfo:
        """Uploads a scene: a file (.obj with the MTL files it names, .json/.pb, or a model such
        as .gltf with its buffers and images, .glb, .ply, .stl ...), or a folder holding exactly
        one such file. ``extra_files``: more files to send, relative to the main file's folder.
        The default ``request_id`` is derived from the contents: uploading the same files again
        returns the stored scene without sending them."""
        if os.path.isdir(path):
            path = _main_file_of(path)
        if not os.path.isfile(path):
            raise errors.NotFound(f"{path}: no such file")
        extension = os.path.splitext(path)[1].lower()
        if extension in _SCENE_EXTENSIONS:
            scene_format = _SCENE_EXTENSIONS[extension]
        elif extension in _MODEL_EXTENSIONS:
            scene_format = pb.SCENE_FORMAT_MODEL
        else:
            raise errors.InvalidArgument(f"{path}: unknown scene extension '{extension}'")
        directory = os.path.dirname(os.path.abspath(path))
        names = [os.path.basename(path)]
        for name in list(scene_dependencies(path)) + list(extra_files):
            safe = _safe_relative(name)
            if safe is None:
                raise errors.InvalidArgument(f"{name}: not a relative name inside {directory}")
            if safe not in names:
                names.append(safe)
        header = pb.UploadSceneHeader(format=scene_format,
                                      display_name=display_name or path,
                                      strict=strict, vertex_colors=vertex_colors)
        key = hashlib.sha256(header.display_name.encode())
        key.update(b"\0strict" if strict else b"")
        key.update(b"\0vertex_colors" if vertex_colors else b"")
        local = []
        for name in names:
            full = os.path.join(directory, *name.split("/"))
            digest = hashlib.sha256()
            size = 0
            try:
                with open(full, "rb") as f:
                    for block in iter(lambda: f.read(CHUNK_BYTES), b""):
                        digest.update(block)
                        size += len(block)
            except OSError as e:
                raise errors.NotFound(f"{full}: {e.strerror}") from e
            header.files.add(name=name, size=size, sha256=digest.hexdigest())
            key.update(b"\0" + name.encode() + b"\0" + digest.hexdigest().encode())
            local.append(full)
        header.request_id = request_id or "upload-" + key.hexdigest()

        def messages():
            yield pb.UploadSceneRequest(header=header)
            for info, full in zip(header.files, local):
                with open(full, "rb") as f:
                    offset = 0
                    while True:
                        data = f.read(CHUNK_BYTES)
                        if not data and offset > 0:
                            break
                        yield pb.UploadSceneRequest(
                            chunk=pb.FileChunk(file=info.name, offset=offset, data=data))
                        offset += len(data)
                        if not data:
                            break

        try:
            return self._stub.UploadScene(messages(), timeout=self._transfer_timeout)
        except grpc.RpcError as e:
            raise errors.from_rpc_error(e, pb.UploadSceneRequest.DESCRIPTOR) from None

    def scene(self, name) -> pb.SceneInfo:
        return self._call(self._stub.GetScene, pb.GetSceneRequest(name=_name(name, "scenes")))

    def scenes(self) -> List[pb.SceneInfo]:
        """Every scene, newest first (all pages)."""
        out, token = [], ""
        while True:
            page = self._call(self._stub.ListScenes,
                              pb.ListScenesRequest(page_size=1000, page_token=token))
            out.extend(page.scenes)
            token = page.next_page_token
            if not token:
                return out

    def delete_scene(self, scene):
        self._call(self._stub.DeleteScene, pb.DeleteSceneRequest(name=_name(scene, "scenes")))

    # --- jobs -----------------------------------------------------------------------------------

    @staticmethod
    def solve_spec(*, method=None, estimator=None, sampling=None, max_elements=None,
                   element_size=None, sensors=None, luminaires=None, **fields) -> pb.SolveSpec:
        """A SolveSpec from keyword arguments: ``method`` ("auto", "progressive", "jacobi",
        "gauss-seidel", "reflection", "hierarchical"), ``estimator`` ("montecarlo", "analytic",
        "hemicube"), ``sampling`` ("sobol", "random", "stratified", "halton"), ``max_elements``
        and ``element_size`` (the mesh), ``sensors`` (a sequence of (position, normal) or
        (position, normal, grid name) of 3-vectors), ``luminaires`` (a sequence of dicts with
        ``file``, a photometric file uploaded with the scene, ``position`` and optionally ``aim``,
        ``c0``, ``multiplier`` and ``color``), and any scalar field of SolveSpec by its name (max_seconds, max_rays,
        tolerance, seed, threads, rays_per_element, width, height, snapshot_interval, ...)."""
        spec = pb.SolveSpec()

        def choose(table, value, field):
            if value is None:
                return None
            if value not in table:
                raise errors.InvalidArgument(
                    f"{field}: '{value}' is not one of {', '.join(table)}", field=field)
            return table[value]

        if method is not None:
            spec.solve_method = choose(_METHODS, method, "method")
        if estimator is not None:
            spec.formfactor.estimator = choose(_ESTIMATORS, estimator, "estimator")
        if sampling is not None:
            spec.formfactor.sampling_pattern = choose(_SAMPLINGS, sampling, "sampling")
        def number(kind, value, field):
            try:
                return kind(value)
            except (TypeError, ValueError, OverflowError) as e:
                raise errors.InvalidArgument(f"{field}: {value!r} is not a number", field=field) from e

        try:
            if max_elements is not None:
                spec.mesh.max_elements = number(int, max_elements, "max_elements")
            if element_size is not None:
                spec.mesh.element_size = number(float, element_size, "element_size")
        except ValueError as e:  # Out of the field's range (protobuf's check).
            raise errors.InvalidArgument(f"{e}", field="max_elements") from e
        for point in sensors or ():
            if len(point) not in (2, 3):
                raise errors.InvalidArgument(
                    f"sensors: {point!r} is not (position, normal) or (position, normal, grid)",
                    field="sensors")
            sensor = spec.sensors.add()
            try:
                sensor.position.x, sensor.position.y, sensor.position.z = map(float, point[0])
                sensor.normal.x, sensor.normal.y, sensor.normal.z = map(float, point[1])
                if len(point) == 3:
                    sensor.grid = point[2]
            except (TypeError, ValueError) as e:
                raise errors.InvalidArgument(
                    f"sensors: {point!r} is not (position, normal[, grid]) of 3-vectors and a "
                    f"name", field="sensors") from e
        for i, luminaire in enumerate(luminaires or ()):
            where = f"luminaires[{i}]"
            if not isinstance(luminaire, dict) or "file" not in luminaire or (
                    "position" not in luminaire):
                raise errors.InvalidArgument(
                    f"{where}: {luminaire!r} is not a dict with 'file' and 'position'",
                    field="luminaires")
            unknown = set(luminaire) - {"file", "position", "aim", "c0", "multiplier", "color"}
            if unknown:
                raise errors.InvalidArgument(
                    f"{where}: unknown keys {', '.join(sorted(unknown))} (file, position, aim, c0, "
                    f"multiplier, color)", field="luminaires")
            out = spec.luminaires.add()
            try:
                out.file = str(luminaire["file"])
                for key, target in (("position", out.position), ("aim", out.aim), ("c0", out.c0)):
                    if luminaire.get(key) is not None:
                        target.x, target.y, target.z = map(float, luminaire[key])
                if luminaire.get("multiplier") is not None:
                    out.multiplier = float(luminaire["multiplier"])
                if luminaire.get("color") is not None:
                    out.r, out.g, out.b = map(float, luminaire["color"])
            except (TypeError, ValueError) as e:
                raise errors.InvalidArgument(f"{where}: {e} (3-vectors and numbers expected)",
                                             field="luminaires") from e
        for key, value in fields.items():
            field = pb.SolveSpec.DESCRIPTOR.fields_by_name.get(key)
            if field is None or field.message_type is not None or (
                    field.label == field.LABEL_REPEATED):
                raise errors.InvalidArgument(
                    f"{key}: not a scalar field of SolveSpec (service.proto); pass spec= for "
                    f"nested settings", field=key)
            try:
                setattr(spec, key, value)
            except (TypeError, ValueError) as e:
                raise errors.InvalidArgument(f"{key}: {e}", field=key) from e
        return spec

    def solve(self, scene, *, spec=None, request_id="", wait=False, **options) -> pb.Job:
        """Creates a solve job on ``scene`` from ``spec`` (a SolveSpec) or keyword options
        (``solve_spec``); returns the job as queued, or with ``wait=True`` as it ended."""
        if spec is None:
            spec = self.solve_spec(**options)
        elif options:
            raise errors.InvalidArgument("pass either spec= or keyword options, not both")
        job = self._call(self._stub.CreateJob, pb.CreateJobRequest(
            scene=_name(scene, "scenes"), solve=spec, request_id=request_id))
        return self.wait(job) if wait else job

    def job(self, job) -> pb.Job:
        return self._call(self._stub.GetJob, pb.GetJobRequest(name=_name(job, "jobs")))

    def jobs(self, *, states=(), scene=None) -> List[pb.Job]:
        """Jobs, newest first (all pages), optionally in the given states or on one scene."""
        out, token = [], ""
        while True:
            try:
                wanted = [pb.JobState.Value("JOB_STATE_" + s.upper()) if isinstance(s, str) else s
                          for s in states]
                request = pb.ListJobsRequest(page_size=1000, page_token=token, states=wanted)
            except (ValueError, TypeError) as e:
                raise errors.InvalidArgument(f"states: {list(states)!r}: {e}",
                                             field="states") from e
            if scene is not None:
                request.scene = _name(scene, "scenes")
            page = self._call(self._stub.ListJobs, request)
            out.extend(page.jobs)
            token = page.next_page_token
            if not token:
                return out

    def cancel(self, job) -> pb.Job:
        return self._call(self._stub.CancelJob, pb.CancelJobRequest(name=_name(job, "jobs")))

    def delete_job(self, job):
        self._call(self._stub.DeleteJob, pb.DeleteJobRequest(name=_name(job, "jobs")))

    def wait(self, job, timeout=None) -> pb.Job:
        """Waits for the job to end and returns it; raises ``errors.JobFailed`` if it failed,
        ``errors.DeadlineExceeded`` after ``timeout`` seconds (None: no limit)."""
        try:
            for snap in self.watch(job, progress_only=True, timeout=timeout):
                if snap.final:
                    break
        except errors.DeadlineExceeded:
            pass  # Said below, with the job's state.
        ended = self.job(job)
        if ended.state == pb.JOB_STATE_FAILED:
            raise errors.JobFailed(ended)
        if ended.state not in _ENDED:
            raise errors.DeadlineExceeded(
                f"{ended.name} is still {pb.JobState.Name(ended.state)} after {timeout} s")
        return ended

    def watch(self, job, *, progress_only=False, errors_too=False, after_sequence=0,
              timeout=None) -> Iterator[Snapshot]:
        """Snapshots of a job as it converges, then its final state (``Snapshot.final``).
        A slow reader gets the newest snapshot (``resync`` marks skipped ones); leaving the loop
        ends the stream without cancelling the job."""
        request = pb.WatchJobRequest(name=_name(job, "jobs"), after_sequence=after_sequence,
                                     progress_only=progress_only, include_errors=errors_too,
                                     existing_sides_only=True)
        stream = self._stub.WatchJob(request, timeout=timeout)
        parts, std_parts, first = [], [], None
        try:
            for message in stream:
                if message.HasField("mesh"):
                    continue  # Geometry announcements are not snapshots.
                if message.chunk_index == 0:
                    parts, std_parts, first = [], [], message
                if first is None or message.sequence != first.sequence:
                    raise errors.Internal(f"watch {request.name}: a snapshot's chunks are mixed")
                parts.append(np.asarray(message.radiosity, dtype=np.float32))
                std_parts.append(np.asarray(message.std_error, dtype=np.float32))
                if message.chunk_index + 1 < message.chunk_count:
                    continue
                yield self._snapshot(first, message, parts, std_parts)
                if message.final:
                    return
        except grpc.RpcError as e:
            raise errors.from_rpc_error(e, request.DESCRIPTOR) from None
        finally:
            stream.cancel()

    @staticmethod
    def _expand(values, elements, first):
        """(elements, 2, 3) from a snapshot's floats, in the full or existing-sides layout."""
        if values.size == 0 or elements == 0:
            return None
        if not first.existing_sides_only:
            return values.reshape(elements, 2, 3)
        out = np.zeros((elements, 2, 3), dtype=np.float32)
        has_back = np.zeros(elements, dtype=bool)
        ranges = list(first.back_ranges)
        for begin, end in zip(ranges[0::2], ranges[1::2]):
            has_back[begin:end] = True
        sides = 1 + has_back.astype(np.int64)
        if int(sides.sum()) * 3 != values.size:
            raise errors.Internal(
                f"snapshot {first.sequence}: {values.size} floats for {elements} elements of "
                f"which {int(has_back.sum())} have a back side")
        starts = np.concatenate(([0], np.cumsum(sides)[:-1])) * 3
        front = starts[:, None] + np.arange(3)
        out[:, 0, :] = values[front]
        back = np.nonzero(has_back)[0]
        out[back, 1, :] = values[starts[back][:, None] + 3 + np.arange(3)]
        return out

    def _snapshot(self, first, last, parts, std_parts):
        values = np.concatenate(parts) if parts else np.zeros(0, np.float32)
        std = np.concatenate(std_parts) if std_parts else np.zeros(0, np.float32)
        return Snapshot(
            sequence=first.sequence, state=last.state, progress=last.progress, final=last.final,
            resync=first.resync, elements=first.elements, mesh_version=first.mesh_version,
            attempts=first.attempts, radiosity=self._expand(values, first.elements, first),
            std_error=self._expand(std, first.elements, first) if std.size else None,
            error=last.error if last.HasField("error") else None)

    # --- results --------------------------------------------------------------------------------

    def download(self, job, out_dir, files=None) -> List[str]:
        """Writes the job's result files (all, or those named in ``files``) into ``out_dir``,
        each checked against its size and SHA-256; returns their paths."""
        if isinstance(files, str):
            files = [files]
        os.makedirs(out_dir, exist_ok=True)
        wanted = list(files) if files else [""]
        written = []
        for name in wanted:
            request = pb.DownloadResultRequest(name=_name(job, "jobs"), file=name)
            handle, current, digest, path, info = None, None, None, None, None
            try:
                for chunk in self._stub.DownloadResult(request, timeout=self._transfer_timeout):
                    if chunk.file != current:
                        if handle:
                            handle.close()
                        current, info = chunk.file, chunk.info
                        safe = _safe_relative(chunk.file)
                        if safe is None:
                            raise errors.Internal(f"the server sent a file named {chunk.file!r}")
                        path = os.path.join(out_dir, safe)
                        handle, digest, size = open(path, "wb"), hashlib.sha256(), 0
                    handle.write(chunk.data)
                    digest.update(chunk.data)
                    size += len(chunk.data)
                    if chunk.last:
                        handle.close()
                        handle = None
                        if size != info.size or digest.hexdigest() != info.sha256:
                            os.remove(path)
                            raise errors.Internal(f"{path}: the download does not match its size "
                                                  f"and SHA-256 (removed; retry)")
                        written.append(path)
            except grpc.RpcError as e:
                raise errors.from_rpc_error(e, request.DESCRIPTOR) from None
            finally:
                if handle:
                    handle.close()
        return written

    def read_result(self, job, file) -> bytes:
        """One result file's bytes (e.g. "summary.json"), checked against its size and SHA-256."""
        request = pb.DownloadResultRequest(name=_name(job, "jobs"), file=file)
        try:
            chunks = list(self._stub.DownloadResult(request, timeout=self._transfer_timeout))
        except grpc.RpcError as e:
            raise errors.from_rpc_error(e, request.DESCRIPTOR) from None
        data = b"".join(c.data for c in chunks)
        info = chunks[-1].info if chunks else None
        if info is None or len(data) != info.size or hashlib.sha256(data).hexdigest() != info.sha256:
            raise errors.Internal(f"{request.name} {file}: the download does not match its size "
                                  f"and SHA-256 (retry)")
        return data

    def view_factors(self, scene, *, estimator=None, sampling=None, request_id="",
                     **fields) -> ViewFactors:
        """Surface-to-surface view factors of a scene as a matrix (runs a view-factor job and
        waits for it). Keyword fields are ViewFactorSpec's (tolerance, rays_per_surface,
        shadow_rays, hemicube_resolution, seed, threads, ...)."""
        spec = pb.ViewFactorSpec()
        if estimator is not None:
            if estimator not in _ESTIMATORS:
                raise errors.InvalidArgument(f"estimator: '{estimator}' is not one of "
                                             f"{', '.join(_ESTIMATORS)}", field="estimator")
            spec.estimator = _ESTIMATORS[estimator]
        if sampling is not None:
            if sampling not in _SAMPLINGS:
                raise errors.InvalidArgument(f"sampling: '{sampling}' is not one of "
                                             f"{', '.join(_SAMPLINGS)}", field="sampling")
            spec.sampling_pattern = _SAMPLINGS[sampling]
        for key, value in fields.items():
            if key not in pb.ViewFactorSpec.DESCRIPTOR.fields_by_name:
                raise errors.InvalidArgument(f"{key}: not a field of ViewFactorSpec", field=key)
            try:
                field = pb.ViewFactorSpec.DESCRIPTOR.fields_by_name[key]
                if field.label == field.LABEL_REPEATED:
                    if isinstance(value, str):
                        raise TypeError("a list is expected, not a string")
                    getattr(spec, key).extend(value)  # from_surfaces=["a", "b"]
                else:
                    setattr(spec, key, value)
            except (TypeError, ValueError) as e:
                raise errors.InvalidArgument(f"{key}: {e}", field=key) from e
        job = self._call(self._stub.CreateJob, pb.CreateJobRequest(
            scene=_name(scene, "scenes"), view_factor=spec, request_id=request_id))
        job = self.wait(job)
        surfaces = list(job.view_factor_result.surfaces)
        index = {name: i for i, name in enumerate(surfaces)}
        matrix = np.zeros((len(surfaces), len(surfaces)))
        text = self.read_result(job, "viewfactors.csv").decode("utf-8")
        for row in csv.DictReader(io.StringIO(text)):
            matrix[index[row["from"]], index[row["to"]]] = float(row["F"])
        return ViewFactors(surfaces=surfaces, matrix=matrix, job=job)


def connect(address=None, **options) -> Client:
    """A Client (see Client for the options)."""
    return Client(address, **options)
