"""The Python client (client/python/radiosity) against a real radiosity-server on 127.0.0.1:
upload with the files a scene names, solve and watch, results against closed forms (a furnace's
radiosity E / (1 - rho); a unit cube's view factors, rows summing to 1, reciprocity), the final
snapshot against the downloaded elements.csv, typed errors naming the field, cancel, TLS with a
bearer token, and the README's example script.

Run by ctest (PythonClientTest) with RADIOSITY_SERVER_BIN, RADIOSITY_SOURCE_DIR and PYTHONPATH set.
"""

import csv
import os
import shutil
import subprocess
import sys
import tempfile
import time
import unittest

import grpc
import numpy as np

import radiosity
from radiosity import errors, pb

SERVER = os.environ["RADIOSITY_SERVER_BIN"]
SOURCE = os.environ["RADIOSITY_SOURCE_DIR"]
SCENES = os.path.join(SOURCE, "scenes")
ALICE = "alice-0123456789abcdef"
BOB = "bob-0123456789abcdef"


def read(path):
    try:
        with open(path) as f:
            return f.read().strip()
    except OSError:
        return ""


class Server:
    """radiosity-server on a free loopback port, in a temporary data directory."""

    def __init__(self, *extra, log_level="warn"):
        self.dir = tempfile.mkdtemp(prefix="radiosity_py_")
        self.args = ["--data-dir", os.path.join(self.dir, "data"), "--workers", "1",
                     "--log-level", log_level, *extra]
        self._start("127.0.0.1:0")

    def restart(self):
        """SIGTERM, then the same server again (same data, gRPC port and flags)."""
        self.process.terminate()
        self.process.wait(timeout=30)
        self._start(self.address)

    def _start(self, listen):
        port_file = os.path.join(self.dir, "port")
        log = os.path.join(self.dir, "server.log")
        if os.path.exists(port_file):
            os.remove(port_file)
        with open(log, "a") as stderr:
            self.process = subprocess.Popen(
                [SERVER, "--listen", listen, "--port-file", port_file, *self.args],
                stdout=subprocess.DEVNULL, stderr=stderr)
        deadline = time.monotonic() + 30
        while not read(port_file):
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.process.kill()
                raise RuntimeError("the server did not start: " + read(log))
            time.sleep(0.05)
        self.address = "127.0.0.1:" + read(port_file)

    def stop(self):
        self.process.terminate()
        self.process.wait(timeout=30)
        shutil.rmtree(self.dir, ignore_errors=True)


class TenantPki:
    """A throwaway CA and server certificate (deploy/make-test-pki.sh) and a tokens file with
    ALICE (tenant alice) and BOB (tenant bob), removed on exit."""

    def __enter__(self):
        self.dir = tempfile.mkdtemp(prefix="radiosity_pki_")
        subprocess.run(["sh", os.path.join(SOURCE, "deploy", "make-test-pki.sh"), self.dir],
                       check=True, capture_output=True)
        self.tokens = os.path.join(self.dir, "tokens")
        with open(self.tokens, "w") as f:
            f.write(f"{ALICE} alice\n{BOB} bob\n")
        self.ca = os.path.join(self.dir, "ca.pem")
        self.server_cert = os.path.join(self.dir, "server.pem")
        self.server_flags = ["--tls-cert", self.server_cert, "--tls-key",
                             os.path.join(self.dir, "server.key"), "--tokens-file", self.tokens]
        return self

    def __exit__(self, *exc):
        shutil.rmtree(self.dir, ignore_errors=True)


class ClientTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.server = Server()
        cls.client = radiosity.connect(cls.server.address, timeout=30)

    @classmethod
    def tearDownClass(cls):
        cls.client.close()
        cls.server.stop()

    def test_upload_sends_the_material_library_and_deduplicates(self):
        path = os.path.join(SCENES, "cornell_box.obj")
        self.assertEqual(radiosity.scene_dependencies(path), ["cornell_box.mtl"])
        scene = self.client.upload(path)
        self.assertEqual([f.name for f in scene.files], ["cornell_box.obj", "cornell_box.mtl"])
        self.assertTrue(scene.has_emitter)
        self.assertEqual(self.client.upload(path).name, scene.name)  # The same files: one scene.
        self.assertIn(scene.name, [s.name for s in self.client.scenes()])
        self.assertEqual(self.client.scene(scene.name).faces, scene.faces)

    def test_furnace_converges_to_e_over_one_minus_rho_and_the_stream_matches_the_csv(self):
        scene = self.client.upload(os.path.join(SCENES, "furnace.json"))
        job = self.client.solve(scene, method="progressive", max_elements=600, seed=7,
                                snapshot_interval=0.01)
        snapshots = list(self.client.watch(job, errors_too=True))
        self.assertTrue(snapshots[-1].final)
        self.assertEqual(snapshots[-1].state, pb.JOB_STATE_SUCCEEDED)
        sequences = [s.sequence for s in snapshots]
        self.assertEqual(sequences, sorted(set(sequences)))
        final = snapshots[-1].radiosity
        self.assertEqual(final.shape, (snapshots[-1].elements, 2, 3))
        # Closed form: in a closed furnace of reflectance 0.5 emitting 1, B = 1 / (1 - 0.5).
        front = final[:, 0, :].astype(np.float64)
        self.assertAlmostEqual(front.mean(), 2.0, delta=0.02)
        self.assertLess(np.abs(front / 2.0 - 1).max(), 0.1)
        self.assertTrue(np.all(final[:, 1, :] == 0), "one-sided walls have no back values")

        ended = self.client.job(job)
        self.assertEqual(ended.state, pb.JOB_STATE_SUCCEEDED)
        with tempfile.TemporaryDirectory() as out:
            written = self.client.download(job, out)
            self.assertIn(os.path.join(out, "elements.csv"), written)
            with open(os.path.join(out, "elements.csv")) as f:
                rows = list(csv.DictReader(f))
        self.assertEqual(len(rows), final.shape[0])
        csv_front = np.array([[float(r[c]) for c in ("r", "g", "b")] for r in rows])
        np.testing.assert_allclose(csv_front, front, rtol=1e-5)

    def test_a_luminaire_uploaded_with_the_scene_lights_sensors_by_the_inverse_square_law(self):
        with tempfile.TemporaryDirectory() as folder:
            with open(os.path.join(folder, "floor.json"), "w") as f:
                f.write('{"materials": [{"name": "grey", "reflectance": {"r": 0.5, "g": 0.5, '
                        '"b": 0.5}}], "surfaces": [{"name": "floor", "material": "grey", '
                        '"vertices": [-5, 0, -5, -5, 0, 5, 5, 0, 5, 5, 0, -5], '
                        '"faces": [{"indices": [0, 1, 2, 3]}]}]}')
            with open(os.path.join(folder, "lamp.ies"), "w") as f:
                f.write("IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 2 1 1 2 0 0 0\n1 1 0\n0 180\n0\n"
                        "500 500\n")
            scene = self.client.upload(os.path.join(folder, "floor.json"),
                                       extra_files=["lamp.ies"])
        self.assertEqual([f.name for f in scene.files], ["floor.json", "lamp.ies"])
        points = [((x, 0, 1), (0, 1, 0)) for x in (0, 1.5, 3)]
        job = self.client.solve(scene, max_elements=400, sensors=points, wait=True,
                                luminaires=[{"file": "lamp.ies", "position": (0, 2, 0)}])
        self.assertEqual(self.client.job(job).state, pb.JOB_STATE_SUCCEEDED)
        rows = list(csv.DictReader(self.client.read_result(job, "sensors.csv")
                                   .decode("utf-8").splitlines()))
        for (position, _), row in zip(points, rows):
            d2 = 4 + position[0] ** 2 + position[2] ** 2
            expected = 500 * 2 / d2 ** 1.5  # I cos(theta) / d^2, cos(theta) = h / d.
            self.assertAlmostEqual(float(row["g"]) / expected, 1, delta=1e-6)
        with self.assertRaises(errors.InvalidArgument) as caught:
            self.client.solve(scene, luminaires=[{"file": "lamp.ies"}])
        self.assertEqual(caught.exception.field, "luminaires")
        with self.assertRaises(errors.FailedPrecondition) as caught:
            self.client.solve(scene, luminaires=[{"file": "other.ies", "position": (0, 1, 0)}])
        self.assertIn("other.ies", str(caught.exception))

    def test_view_factors_of_a_unit_cube(self):
        scene = self.client.upload(os.path.join(SCENES, "furnace.json"))
        vf = self.client.view_factors(scene, estimator="analytic")
        self.assertEqual(sorted(vf.surfaces), ["x0", "x1", "y0", "y1", "z0", "z1"])
        f = vf.matrix
        i = {name: k for k, name in enumerate(vf.surfaces)}
        # Closed forms for a unit cube: opposite faces 0.199825, adjacent faces 0.200044.
        self.assertAlmostEqual(f[i["x0"], i["x1"]], 0.199825, delta=2e-3)
        self.assertAlmostEqual(f[i["x0"], i["y0"]], 0.200044, delta=2e-3)
        np.testing.assert_allclose(f.sum(axis=1), 1.0, atol=5e-3)
        np.testing.assert_allclose(f, f.T, atol=5e-3)  # Reciprocity (equal areas).
        self.assertTrue(np.all(np.diag(f) == 0))
        # Only two rows (from_surfaces, a repeated field): the same as the whole matrix's.
        some = self.client.view_factors(scene, estimator="analytic", from_surfaces=["x1", "z0"])
        j = {name: k for k, name in enumerate(some.surfaces)}
        for name in vf.surfaces:
            row = some.matrix[j[name]]
            if name in ("x1", "z0"):
                np.testing.assert_array_equal(row, f[i[name]])
            else:
                self.assertTrue(np.all(row == 0), name)

    def test_real_models_and_the_calls_new_users_get_wrong(self):
        # glTF 1.0 keeps its buffers and images in objects (Debian's assimp-testmodels).
        gltf1 = "/usr/share/assimp/models/glTF/BoxTextured-glTF-Embedded/BoxTextured.gltf"
        if os.path.exists(gltf1):
            self.assertEqual(self.client.upload(gltf1).files[0].name, "BoxTextured.gltf")
        with tempfile.TemporaryDirectory() as d:
            # A .gltf that is not JSON is the server's to refuse, naming the file.
            bad = os.path.join(d, "bad.gltf")
            with open(bad, "w") as f:
                f.write("[1, 2")
            with self.assertRaises(errors.InvalidArgument) as caught:
                self.client.upload(bad)
            self.assertIn("bad.gltf", caught.exception.message)
            # A UTF-16 OBJ still sends the material library it names.
            obj = os.path.join(d, "m.obj")
            with open(obj, "wb") as f:
                f.write("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl lamp\nf 1 2 3\n"
                        .encode("utf-16"))
            with open(os.path.join(d, "m.mtl"), "w") as f:
                f.write("newmtl lamp\nKd 0.5 0.5 0.5\nKe 1 1 1\n")
            self.assertEqual(radiosity.scene_dependencies(obj), ["m.mtl"])
        # Upload errors name the header's fields.
        with self.assertRaises(errors.InvalidArgument) as caught:
            self.client.upload(os.path.join(SCENES, "furnace.json"), request_id="x" * 5000)
        self.assertEqual(caught.exception.field, "header.request_id")
        # No deadline at all, a single file name, states by name.
        with radiosity.connect(self.server.address, timeout=None) as unlimited:
            scene = unlimited.upload(os.path.join(SCENES, "furnace.json"))
            job = unlimited.solve(scene, max_elements=100, wait=True)
            with tempfile.TemporaryDirectory() as out:
                self.assertEqual(unlimited.download(job, out, files="summary.json"),
                                 [os.path.join(out, "summary.json")])
            self.assertIn(job.name, [j.name for j in unlimited.jobs(states=["succeeded"])])
            self.assertIn(b'"convergence"', unlimited.read_result(job, "summary.json"))
        with self.assertRaises(errors.InvalidArgument) as caught:
            self.client.jobs(states=["sleeping"])
        self.assertEqual(caught.exception.field, "states")
        with self.assertRaises(errors.InvalidArgument) as caught:
            self.client.solve(scene, max_elements="abc")
        self.assertEqual(caught.exception.field, "max_elements")

    def test_errors_are_typed_and_name_the_field(self):
        scene = self.client.upload(os.path.join(SCENES, "furnace.json"))
        with self.assertRaises(errors.InvalidArgument) as caught:
            self.client.solve(scene, max_rays=-5)
        self.assertEqual(caught.exception.field, "solve.max_rays")
        self.assertIn("max_rays", caught.exception.message)
        with self.assertRaises(errors.InvalidArgument) as caught:
            self.client.solve(scene, method="newton")
        self.assertEqual(caught.exception.field, "method")
        with self.assertRaises(errors.InvalidArgument) as caught:
            self.client.solve(scene, no_such_option=1)
        self.assertEqual(caught.exception.field, "no_such_option")
        with self.assertRaises(errors.NotFound) as caught:
            self.client.job("jobs/0123456789ab")
        self.assertEqual(caught.exception.code.name, "NOT_FOUND")
        with self.assertRaises(errors.NotFound):
            self.client.upload(os.path.join(SCENES, "no_such_scene.obj"))
        with tempfile.TemporaryDirectory() as d:
            bad = os.path.join(d, "bad.obj")
            with open(bad, "w") as f:
                f.write("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
            with self.assertRaises(errors.InvalidArgument) as caught:
                self.client.upload(bad)
            self.assertIn("bad.obj", caught.exception.message)
            self.assertIsNone(caught.exception.field, "a file name is not a field")

    def test_cancel_ends_a_long_job_and_wait_reports_it(self):
        scene = self.client.upload(os.path.join(SCENES, "cornell_box.obj"))
        job = self.client.solve(scene, max_elements=20000, tolerance=1e-9, max_seconds=120)
        for snap in self.client.watch(job, progress_only=True):
            if snap.state == pb.JOB_STATE_RUNNING and snap.progress.rays > 0:
                break
        self.client.cancel(job)
        ended = self.client.wait(job, timeout=30)
        self.assertEqual(ended.state, pb.JOB_STATE_CANCELLED)
        with self.assertRaises(errors.FailedPrecondition):
            self.client.cancel(job)

    def test_example_script_solves_watches_and_plots(self):
        example = os.path.join(SOURCE, "client", "python", "examples", "convergence.py")
        with tempfile.TemporaryDirectory() as out:
            plot = os.path.join(out, "convergence.png")
            env = dict(os.environ, MPLBACKEND="Agg")
            run = subprocess.run(
                [sys.executable, example, "--server", self.server.address, "--out", plot,
                 "--max-seconds", "20", os.path.join(SCENES, "cornell_box.obj")],
                env=env, capture_output=True, text=True, timeout=300)
            self.assertEqual(run.returncode, 0, run.stderr)
            self.assertTrue(os.path.getsize(plot) > 1000)
            self.assertIn("SUCCEEDED", run.stdout)


class JobFailedTest(unittest.TestCase):
    def test_a_failed_job_is_also_an_error_of_its_code(self):
        job = pb.Job(name="jobs/abc", state=pb.JOB_STATE_FAILED)
        job.error.code = 8  # RESOURCE_EXHAUSTED: the server's memory cap, say.
        job.error.message = "--max-memory-mb: the job grew past 80 MiB"
        with self.assertRaises(errors.ResourceExhausted) as caught:
            raise errors.JobFailed(job)
        self.assertIsInstance(caught.exception, errors.JobFailed)
        self.assertIs(caught.exception.job, job)
        self.assertEqual(caught.exception.code, grpc.StatusCode.RESOURCE_EXHAUSTED)
        self.assertIn("jobs/abc failed: --max-memory-mb", str(caught.exception))
        self.assertIs(type(errors.JobFailed(job)), type(caught.exception))  # One class per code.
        job.error.code = 2  # UNKNOWN has no class of its own.
        unknown = errors.JobFailed(job)
        self.assertIs(type(unknown), errors.JobFailed)
        self.assertNotIsInstance(unknown, errors.ResourceExhausted)


class SecureClientTest(unittest.TestCase):
    """TLS with a test CA made now by deploy/make-test-pki.sh, and bearer tokens."""

    def test_tls_and_tokens(self):
        with TenantPki() as pki:
            server = Server(*pki.server_flags)
            ca = pki.ca
            try:
                with radiosity.connect(server.address, tls_ca=ca, token=ALICE) as alice:
                    scene = alice.upload(os.path.join(SCENES, "furnace.json"))
                    self.assertEqual(scene.tenant, "alice")
                with radiosity.connect(server.address, tls_ca=ca, token=BOB) as bob:
                    self.assertNotIn(scene.name, [s.name for s in bob.scenes()])
                    with self.assertRaises(errors.NotFound):
                        bob.scene(scene.name)
                with radiosity.connect(server.address, tls_ca=ca, token="nobody-0123456789abcdef") as nobody:
                    with self.assertRaises(errors.Unauthenticated):
                        nobody.scenes()
                with self.assertRaises(errors.InvalidArgument) as caught:
                    radiosity.connect(server.address, token=ALICE)  # Plaintext.
                self.assertEqual(caught.exception.field, "token")
            finally:
                server.stop()


if __name__ == "__main__":
    unittest.main()
