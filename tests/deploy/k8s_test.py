"""deploy/k8s/ rendered offline (`kubectl kustomize`, docs/service/deployment.md) and checked object by
object: images pinned, probes, the preStop drain within the grace period, volumes and secrets
(referenced, never included), resources against the server's flags; then the sqlite overlay's
server arguments and readiness probe run for real against a server on loopback.

Skipped (exit 77) where kubectl is absent. Environment: RADIOSITY_SERVER_BIN, RADIOSITY_CLI,
RADIOSITY_SOURCE_DIR.
"""
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import unittest

import yaml

SOURCE = os.environ.get("RADIOSITY_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))
SERVER = os.environ.get("RADIOSITY_SERVER_BIN", "radiosity-server")
CLI = os.environ.get("RADIOSITY_CLI", "radiosity")
K8S = os.path.join(SOURCE, "deploy", "k8s")
OVERLAYS = ("sqlite", "postgresql")


def render(overlay):
    out = subprocess.run(["kubectl", "kustomize", os.path.join(K8S, "overlays", overlay)],
                         check=True, capture_output=True, text=True).stdout
    return [o for o in yaml.safe_load_all(out) if o]


def by_kind(objects, kind):
    return [o for o in objects if o["kind"] == kind]


def flag_value(args, name):
    for a in args:
        if a.startswith(name + "="):
            return a.split("=", 1)[1]
    return None


def read(path):
    with open(path) as f:
        return f.read().strip()


def help_text(binary):
    return subprocess.run([binary, "--help"], capture_output=True, text=True).stdout


class RenderedTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.rendered = {overlay: render(overlay) for overlay in OVERLAYS}
        cls.server_help = help_text(SERVER)
        cls.cli_help = help_text(CLI)

    def for_each(self):
        for overlay, objects in self.rendered.items():
            deployments = by_kind(objects, "Deployment")
            self.assertEqual(len(deployments), 1, overlay)
            yield overlay, objects, deployments[0]

    def test_kinds_and_no_secrets_inside(self):
        for overlay, objects, _ in self.for_each():
            kinds = sorted(o["kind"] for o in objects)
            self.assertEqual(kinds, ["Deployment", "PersistentVolumeClaim", "PodDisruptionBudget",
                                     "Service"], overlay)
            text = yaml.safe_dump_all(objects)
            self.assertNotIn("kind: Secret", text)
            self.assertNotRegex(text, r"postgres(ql)?://", "a store URI belongs in a secret")
            self.assertNotRegex(text.lower(), r"password|bearer|begin (ec |rsa )?private key")

    def test_images_are_pinned_and_the_pod_runs_unprivileged(self):
        for overlay, _, d in self.for_each():
            pod = d["spec"]["template"]["spec"]
            self.assertTrue(pod["securityContext"]["runAsNonRoot"])
            self.assertNotEqual(pod["securityContext"]["runAsUser"], 0)
            self.assertFalse(pod["automountServiceAccountToken"])
            for c in pod["containers"]:
                name, _, tag = c["image"].partition(":")
                self.assertEqual(name, "radiosity", overlay)
                self.assertRegex(tag, r"^\d+\.\d+\.\d+$", f"{overlay}: a version, not latest")
                self.assertIn("imagePullPolicy", c)
                sc = c["securityContext"]
                self.assertFalse(sc["allowPrivilegeEscalation"])
                self.assertTrue(sc["readOnlyRootFilesystem"])
                self.assertEqual(sc["capabilities"]["drop"], ["ALL"])

    def test_arguments_are_flags_the_binaries_accept(self):
        for overlay, _, d in self.for_each():
            c = d["spec"]["template"]["spec"]["containers"][0]
            for a in c["args"]:
                self.assertRegex(a, r"^--[a-z][a-z0-9-]*=", overlay)
                self.assertRegex(self.server_help, rf"(?m)^\s*{re.escape(a.split('=')[0])}\b",
                                 f"{overlay}: {a}")
            probe = c["readinessProbe"]["exec"]["command"]
            self.assertEqual(probe[0], "radiosity")
            self.assertEqual(probe[-1], "health")
            self.assertIn("health", self.cli_help)
            for a in probe:
                if a.startswith("--"):
                    self.assertRegex(self.cli_help, rf"(?m)^\s*{re.escape(a)}\b",
                                     f"{overlay}: probe {a}")

    def test_probes_and_a_drain_within_the_grace_period(self):
        for overlay, _, d in self.for_each():
            pod = d["spec"]["template"]["spec"]
            c = pod["containers"][0]
            ports = {p["name"]: p["containerPort"] for p in c["ports"]}
            listen = flag_value(c["args"], "--listen")
            self.assertEqual(int(listen.rsplit(":", 1)[1]), ports["grpc"])
            self.assertEqual(int(flag_value(c["args"], "--http-port")), ports["https"])
            # Liveness and start-up on the gRPC port; readiness through the health service.
            self.assertEqual(c["livenessProbe"]["tcpSocket"]["port"], "grpc")
            self.assertEqual(c["startupProbe"]["tcpSocket"]["port"], "grpc")
            probe = c["readinessProbe"]["exec"]["command"]
            self.assertEqual(probe[probe.index("--server") + 1], f"127.0.0.1:{ports['grpc']}")
            self.assertLess(float(probe[probe.index("--timeout") + 1]),
                            c["readinessProbe"]["timeoutSeconds"])
            # preStop pause + the server's grace < what Kubernetes waits before SIGKILL.
            pause = float(c["lifecycle"]["preStop"]["exec"]["command"][1])
            grace = float(flag_value(c["args"], "--shutdown-grace"))
            self.assertLess(pause + grace, pod["terminationGracePeriodSeconds"])

    def test_volumes_secrets_and_files_the_arguments_name(self):
        for overlay, _, d in self.for_each():
            pod = d["spec"]["template"]["spec"]
            c = pod["containers"][0]
            volumes = {v["name"]: v for v in pod["volumes"]}
            mounts = {m["mountPath"]: m["name"] for m in c["volumeMounts"]}
            self.assertEqual(set(mounts.values()), set(volumes), f"{overlay}: mounted = declared")
            secrets = {v["secret"]["secretName"] for v in volumes.values() if "secret" in v}
            expected = {"radiosity-tls", "radiosity-tokens"}
            if overlay == "postgresql":
                expected.add("radiosity-store")
            self.assertEqual(secrets, expected, overlay)
            for v in volumes.values():
                if "secret" in v:
                    # Kubernetes adds group read for fsGroup: nothing for others.
                    self.assertEqual(v["secret"]["defaultMode"] & 0o007, 0, "secret files private")
            # Every file argument lies in a mounted volume, secrets read-only.
            files = [flag_value(c["args"], f) for f in
                     ("--tls-cert", "--tls-key", "--tokens-file", "--data-dir")]
            store = flag_value(c["args"], "--store")
            if overlay == "postgresql":
                self.assertTrue(store.startswith("file:"), "the URI comes from a secret file")
                files.append(store[len("file:"):])
                files.append(flag_value(c["args"], "--blob-dir"))
            else:
                self.assertIsNone(store)
                self.assertIsNone(flag_value(c["args"], "--blob-dir"))
            probe = c["readinessProbe"]["exec"]["command"]
            files.append(probe[probe.index("--tls-ca") + 1])
            for f in files:
                mount = max((m for m in mounts if f == m or f.startswith(m + "/")), key=len,
                            default=None)
                self.assertIsNotNone(mount, f"{overlay}: {f} is in no volume")
                volume = volumes[mounts[mount]]
                if "secret" in volume:
                    self.assertTrue(next(m for m in c["volumeMounts"]
                                         if m["mountPath"] == mount).get("readOnly"))
            claims = {p["metadata"]["name"]: p for p in
                      by_kind(self.rendered[overlay], "PersistentVolumeClaim")}
            data = volumes[mounts[flag_value(c["args"], "--data-dir")]]
            if overlay == "sqlite":
                # The data directory (store and files) is on the claim; one pod at a time holds
                # it.
                self.assertNotIn("emptyDir", data, "sqlite: the data directory is not scratch")
                claim = claims[data["persistentVolumeClaim"]["claimName"]]
                self.assertEqual(claim["spec"]["accessModes"], ["ReadWriteOnce"])
                self.assertEqual(d["spec"]["replicas"], 1)
                self.assertEqual(d["spec"]["strategy"]["type"], "Recreate")
            else:
                # Replicas: what lasts is in PostgreSQL and on a volume every pod mounts; each
                # pod's data directory is bounded scratch.
                self.assertIn("sizeLimit", data["emptyDir"])
                blobs = volumes[mounts[flag_value(c["args"], "--blob-dir")]]
                claim = claims[blobs["persistentVolumeClaim"]["claimName"]]
                self.assertEqual(claim["spec"]["accessModes"], ["ReadWriteMany"])
                self.assertGreaterEqual(d["spec"]["replicas"], 2)
                self.assertEqual(d["spec"]["strategy"]["type"], "RollingUpdate")
                pdb = by_kind(self.rendered[overlay], "PodDisruptionBudget")[0]
                self.assertLessEqual(d["spec"]["strategy"]["rollingUpdate"]["maxUnavailable"],
                                     pdb["spec"]["maxUnavailable"])

    def test_selectors_and_resources(self):
        for overlay, objects, d in self.for_each():
            labels = d["spec"]["template"]["metadata"]["labels"]
            for o in by_kind(objects, "Service") + by_kind(objects, "PodDisruptionBudget"):
                selector = o["spec"]["selector"]
                selector = selector.get("matchLabels", selector)
                self.assertTrue(selector.items() <= labels.items(), f"{overlay}: {o['kind']}")
            self.assertEqual(d["spec"]["selector"]["matchLabels"].items() <= labels.items(), True)
            c = d["spec"]["template"]["spec"]["containers"][0]
            cpu = float(c["resources"]["requests"]["cpu"])
            self.assertEqual(int(flag_value(c["args"], "--threads-per-job")), cpu)
            mib = {"Mi": 1, "Gi": 1024}
            m = re.fullmatch(r"(\d+)(Mi|Gi)", c["resources"]["limits"]["memory"])
            limit = int(m[1]) * mib[m[2]]
            # A job's cap, plus the process's own, fits the limit; the largest mesh allowed fits
            # the cap at the server's own estimate of 1 KiB per element.
            cap = int(flag_value(c["args"], "--max-memory-mb"))
            self.assertLessEqual(cap + 256, limit)
            elements = int(flag_value(c["args"], "--max-elements"))
            self.assertLessEqual(elements * 1024 / 2**20 + 64, cap)


class ServerArgumentsTest(unittest.TestCase):
    """The sqlite overlay's arguments start a server, its readiness probe says SERVING, and
    SIGTERM ends it within its grace (paths and ports mapped onto a temporary directory)."""

    def test_the_rendered_server_starts_answers_its_probe_and_drains(self):
        d = by_kind(render("sqlite"), "Deployment")[0]
        c = d["spec"]["template"]["spec"]["containers"][0]
        tmp = tempfile.mkdtemp(prefix="radiosity_k8s_")
        try:
            pki = os.path.join(tmp, "pki")
            subprocess.run(["sh", os.path.join(SOURCE, "deploy", "make-test-pki.sh"), pki],
                           check=True)
            with open(os.path.join(tmp, "tokens"), "w") as f:
                f.write("k8s-test-token-0123456789abcdef alice\n")
            paths = {"/etc/radiosity/tls/tls.crt": os.path.join(pki, "server.pem"),
                     "/etc/radiosity/tls/tls.key": os.path.join(pki, "server.key"),
                     "/etc/radiosity/tls/ca.crt": os.path.join(pki, "ca.pem"),
                     "/etc/radiosity/tokens/tokens": os.path.join(tmp, "tokens"),
                     "/data": os.path.join(tmp, "data")}
            args = []
            for a in c["args"]:
                flag, value = a.split("=", 1)
                if flag == "--listen":
                    value = "127.0.0.1:0"
                elif flag == "--http-port":
                    value = "0"
                args.append(f"{flag}={paths.get(value, value)}")
            port_file = os.path.join(tmp, "port")
            log = open(os.path.join(tmp, "server.log"), "w")
            server = subprocess.Popen([SERVER, *args, "--port-file", port_file],
                                      stdout=subprocess.DEVNULL, stderr=log)
            try:
                deadline = time.monotonic() + 30
                while not (os.path.exists(port_file) and read(port_file)):
                    self.assertIsNone(server.poll(), read(log.name))
                    self.assertLess(time.monotonic(), deadline, "the server did not start")
                    time.sleep(0.05)
                port = read(port_file)
                probe = []
                for a in c["readinessProbe"]["exec"]["command"]:
                    a = paths.get(a, a)
                    a = {"radiosity": CLI, "127.0.0.1:50051": f"127.0.0.1:{port}"}.get(a, a)
                    probe.append(a)
                # The test certificate names localhost, the cluster's would name the Service.
                probe[probe.index("--tls-server-name") + 1] = "localhost"
                result = subprocess.run(probe, capture_output=True, text=True, timeout=30)
                self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
                server.send_signal(signal.SIGTERM)
                grace = float(flag_value(c["args"], "--shutdown-grace"))
                self.assertEqual(server.wait(timeout=grace + 5), 0, read(log.name))
            finally:
                if server.poll() is None:
                    server.kill()
                log.close()
        finally:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    if shutil.which("kubectl") is None:
        print("kubectl not found: deploy/k8s not rendered (skipped)")
        sys.exit(77)
    unittest.main()
