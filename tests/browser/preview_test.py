"""The browser preview (radiosity-server --http-port, server/web/) in a real browser: headless
Chromium (Debian's `chromium`, software WebGL) loads the page against a running job, and the test
asserts from the page's own state (window.radiosityPreview.state) and from screenshots that the
mesh is drawn and changes as snapshots arrive; that the values drawn are the job's result as the
gRPC API gives it; that false colour draws viridis with a legend, the exposure slider brightens
and a drag orbits; and that the page sees only its token's tenant (HTTPS, bearer tokens).

Run by ctest (BrowserPreviewTest) with RADIOSITY_SERVER_BIN, RADIOSITY_SOURCE_DIR and PYTHONPATH
(the Python client, tests/python) set. Exits 77 (skipped) when no Chromium is installed.
"""

import base64
import http.client
import json
import os
import re
import shutil
import socket
import ssl
import subprocess
import sys
import tempfile
import time
import unittest
import urllib.error
import urllib.request

import numpy as np

import cdp
import radiosity
from client_test import ALICE, BOB, SCENES, Server, TenantPki

STATE = "window.radiosityPreview.state"
# The WebGL canvas's place on the page (index.html: 800 x 560).
CANVAS = "JSON.stringify(document.getElementById('gl').getBoundingClientRect())"
BACKGROUND = (18, 18, 18)  # preview.js's clear colour, 0.07 in sRGB bytes.
VIRIDIS = [(0x44, 0x01, 0x54), (0x48, 0x28, 0x78), (0x3e, 0x4a, 0x89), (0x31, 0x68, 0x8e),
           (0x26, 0x82, 0x8e), (0x1f, 0x9e, 0x89), (0x35, 0xb7, 0x79), (0x6e, 0xce, 0x58),
           (0xfd, 0xe7, 0x25)]


def viridis(t):
    """preview.js's (and solver/results/false_color.cc's) scale, 8-bit sRGB."""
    t = min(1.0, max(0.0, t)) * (len(VIRIDIS) - 1)
    i = min(int(t), len(VIRIDIS) - 2)
    return [round((1 - (t - i)) * a + (t - i) * b) for a, b in zip(VIRIDIS[i], VIRIDIS[i + 1])]


def http_port(server):
    """The preview's port, from the server's start-up log line."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        with open(os.path.join(server.dir, "server.log")) as f:
            match = re.search(r'"http_port":(\d+)', f.read())
        if match:
            return int(match.group(1))
        time.sleep(0.05)
    raise AssertionError("the server logged no http_port")


def canvas_pixels(page):
    rect = json.loads(page.eval(CANVAS))
    image = page.screenshot({"x": rect["x"], "y": rect["y"], "width": rect["width"],
                             "height": rect["height"]})
    return np.frombuffer(image.rgba, dtype=np.uint8).reshape(image.height, image.width, 4)[..., :3]


def drawn(pixels):
    """Pixels that are not the background."""
    return np.abs(pixels.astype(int) - BACKGROUND).sum(axis=2) > 6


def state(page):
    return page.eval(f"JSON.parse(JSON.stringify({STATE}))")


class PreviewTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.server = Server("--http-port", "0", log_level="info")
        cls.url = f"http://127.0.0.1:{http_port(cls.server)}/"
        cls.client = radiosity.connect(cls.server.address, timeout=60)
        cls.scene = cls.client.upload(os.path.join(SCENES, "cornell_box.obj"))
        cls.browser = cdp.Browser()

    @classmethod
    def tearDownClass(cls):
        cls.browser.close()
        cls.client.close()
        cls.server.stop()

    def solve_slowly(self):
        """A progressive solve of the Cornell box that takes many snapshots over many seconds
        (a fine mesh, a tolerance it does not reach before max_seconds); the test cancels it once
        it has seen enough."""
        return self.client.solve(self.scene, method="progressive", max_elements=60000,
                                 tolerance=1e-9, max_seconds=300, snapshot_interval=0.3)

    def test_the_mesh_updates_as_snapshots_arrive(self):
        job = self.solve_slowly()
        job_id = job.name.split("/")[1]
        page = cdp.Page(self.browser, self.url + "#job=" + job_id)
        page.wait_for(f"{STATE}.snapshotsApplied >= 1 && {STATE}.jobState === 'RUNNING'",
                      what="a first snapshot drawn while the job runs")
        first, before = state(page), canvas_pixels(page)
        self.assertEqual(first["meshElements"], self.client.job(job).mesh.elements)
        self.assertGreater(drawn(before).mean(), 0.2, "the mesh covers a fifth of the canvas")
        # Three more snapshots drawn, and the light left to shoot halved: enough indirect light
        # added to change the picture however slowly the machine shoots (a sanitizer build).
        page.wait_for(f"{STATE}.snapshotsApplied >= {first['snapshotsApplied'] + 3} && "
                      f"{STATE}.unshotFraction < {0.5 * first['unshotFraction']}", timeout=120,
                      what="three more snapshots drawn, half the unshot light shot")
        later, after = state(page), canvas_pixels(page)
        self.assertGreater(later["appliedSequence"], first["appliedSequence"])
        self.assertNotEqual(later["colorSum"], first["colorSum"])
        changed = (np.abs(after.astype(int) - before.astype(int)).sum(axis=2) > 6).mean()
        self.assertGreater(changed, 0.05, "the picture changed as snapshots arrived")

        # Whatever the page drew last is the job's result, as the gRPC API gives it.
        try:
            self.client.cancel(job)
        except radiosity.errors.FailedPrecondition:
            pass  # It converged first.
        page.wait_for(f"{STATE}.final", timeout=120, what="the final snapshot")
        final = next(s for s in self.client.watch(job) if s.final)
        ended = state(page)
        self.assertEqual(ended["appliedSequence"], final.sequence)
        elements = final.radiosity.shape[0]
        for e in range(0, elements, max(1, elements // 97)):
            for side in (0, 1):
                shown = page.eval(f"window.radiosityPreview.radiosity({e}, {side})")
                np.testing.assert_allclose(shown, final.radiosity[e, side], rtol=1e-6, atol=0)
        self.assertAlmostEqual(ended["colorSum"], float(final.radiosity.sum(dtype=np.float64)),
                               delta=1e-5 * ended["colorSum"])
        # The convergence plot's points: the unshot fraction falls.
        history = ended["history"]
        self.assertGreaterEqual(len(history), 4)
        self.assertLess(history[-1]["unshot"], history[0]["unshot"])
        self.assertIn(job_id, [j["id"] for j in ended["jobs"]])
        # The walls keep their colours: the red wall, lit directly, is in sight.
        pixels = canvas_pixels(page).astype(int)
        self.assertGreater((pixels[..., 0] - pixels[..., 1] > 40).mean(), 0.01, "red wall")

        # A drag turns the view around the mesh.
        rect = json.loads(page.eval(CANVAS))
        cx, cy = rect["x"] + rect["width"] / 2, rect["y"] + rect["height"] / 2
        page.drag(cx, cy, cx + 150, cy + 40)
        turned = state(page)["view"]
        self.assertNotAlmostEqual(turned["yaw"], ended["view"]["yaw"], places=2)
        self.assertNotAlmostEqual(turned["pitch"], ended["view"]["pitch"], places=2)
        changed = (np.abs(canvas_pixels(page).astype(int) - pixels).sum(axis=2) > 6).mean()
        self.assertGreater(changed, 0.05, "the picture turned")

    def test_a_furnace_is_drawn_in_its_closed_form_colours(self):
        # A closed unit cube of reflectance 0.5 emitting 1 W/m^2: every element's radiosity is
        # 1 / (1 - 0.5) = 2 W/m^2 (the solver's error is far below a byte of colour).
        scene = self.client.upload(os.path.join(SCENES, "furnace.json"))
        job = self.client.solve(scene, method="progressive", wait=True)
        page = cdp.Page(self.browser, self.url + "#job=" + job.name.split("/")[1])
        page.wait_for(f"{STATE}.final && {STATE}.snapshotsApplied >= 1", what="the result")

        def colours():
            pixels = canvas_pixels(page)
            mask = drawn(pixels)
            if not page.eval("document.getElementById('legend').hidden"):  # Over the canvas.
                legend = json.loads(page.eval(
                    "JSON.stringify(document.getElementById('legend').getBoundingClientRect())"))
                canvas = json.loads(page.eval(CANVAS))
                top, left = int(legend["y"] - canvas["y"]), int(legend["x"] - canvas["x"])
                mask[max(0, top - 1):top + int(legend["height"]) + 2, max(0, left - 1):] = False
            self.assertGreater(mask.mean(), 0.1)
            return pixels[mask].astype(float)

        def set_input(element, value):
            page.eval(f"(() => {{ const e = document.getElementById('{element}');"
                      f" if (e.type === 'checkbox') e.checked = {json.dumps(value)};"
                      f" else e.value = {json.dumps(value)};"
                      " e.dispatchEvent(new Event('input')); })()")

        def assert_colour(drawn_pixels, expected, what):
            error = np.abs(drawn_pixels - np.array(expected, dtype=float)).max(axis=1)
            # Edges blend with the background (antialiasing): most pixels, not all.
            self.assertGreater((error <= 4).mean(), 0.95, f"{what}: {expected} expected, "
                               f"median {np.median(drawn_pixels, axis=0)}")

        # Shaded: the automatic exposure maps the mean (every element's 2) to 0.5, then sRGB:
        # 0.5 -> 188; -1 EV: 0.25 -> 137.
        srgb = lambda x: round(255 * (12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055))
        assert_colour(colours(), [srgb(0.5)] * 3, "shaded at 0 EV")
        set_input("exposure", "-1")
        assert_colour(colours(), [srgb(0.25)] * 3, "shaded at -1 EV")

        # False colour: 2 on a scale from 0 to 4 is viridis(0.5); from 0 to 2.5, viridis(0.8).
        set_input("false-color", True)
        self.assertFalse(page.eval("document.getElementById('legend').hidden"))
        set_input("fc-max", "4")
        assert_colour(colours(), viridis(0.5), "false colour 0:4")
        set_input("fc-max", "2.5")
        assert_colour(colours(), viridis(0.8), "false colour 0:2.5")

    def test_agglomerated_elements_are_drawn_whole(self):
        # A floor of 2 x 40 x 40 triangles on about 60 elements: most elements hold many
        # triangles (agglomeration), and the page must draw every one of them.
        cells = 40
        directory = tempfile.mkdtemp(prefix="radiosity_floor_")
        try:
            lines = ["mtllib floor.mtl", "usemtl floor"]
            lines += [f"v {i / cells} 0 {j / cells}" for j in range(cells + 1)
                      for i in range(cells + 1)]
            vertex = lambda i, j: j * (cells + 1) + i + 1
            for j in range(cells):
                for i in range(cells):
                    lines.append(f"f {vertex(i, j)} {vertex(i, j + 1)} {vertex(i + 1, j + 1)}")
                    lines.append(f"f {vertex(i, j)} {vertex(i + 1, j + 1)} {vertex(i + 1, j)}")
            light = (cells + 1) ** 2 + 1
            lines += ["usemtl light", "v 0.3 1 0.3", "v 0.7 1 0.3", "v 0.7 1 0.7", "v 0.3 1 0.7",
                      f"f {light} {light + 1} {light + 2} {light + 3}"]
            with open(os.path.join(directory, "floor.obj"), "w") as f:
                f.write("\n".join(lines) + "\n")
            with open(os.path.join(directory, "floor.mtl"), "w") as f:
                f.write("newmtl floor\nKd 0.5 0.5 0.5\nnewmtl light\nKd 0 0 0\nKe 10 10 10\n")
            scene = self.client.upload(os.path.join(directory, "floor.obj"))
        finally:
            shutil.rmtree(directory, ignore_errors=True)
        job = self.client.solve(scene, method="progressive", max_elements=60, wait=True)
        self.assertLessEqual(job.mesh.elements, 60)
        page = cdp.Page(self.browser, self.url + "#job=" + job.name.split("/")[1])
        page.wait_for(f"{STATE}.final && {STATE}.snapshotsApplied >= 1", what="the result")
        # The floor (1) and the light (0.16), whole: the first triangle of each element alone
        # would cover a small fraction of it.
        self.assertAlmostEqual(state(page)["drawnArea"], 1.16, delta=1e-4)
        # On screen, the floor without holes: seen from above (the light faces down, its back
        # culled) it is one convex quadrilateral, so each row of drawn pixels is one run.
        mask = drawn(canvas_pixels(page))
        self.assertGreater(mask.mean(), 0.03, "the floor is in sight")
        runs = inside = 0
        for row in mask:
            columns = np.flatnonzero(row)
            if len(columns):
                runs += columns[-1] - columns[0] + 1
                inside += len(columns)
        self.assertGreater(inside / runs, 0.99, "holes in the floor")

    def events(self, job_id, headers=None, limit=None):
        """The parsed events of /api/jobs/ID/events, up to `limit` events or the stream's end."""
        request = urllib.request.Request(self.url + f"api/jobs/{job_id}/events",
                                         headers=headers or {})
        out = []
        with urllib.request.urlopen(request, timeout=60) as stream:
            self.assertEqual(stream.headers["Content-Type"], "text/event-stream")
            event = {}
            for raw in stream:
                line = raw.decode().rstrip("\n")
                if not line:
                    if "data" in event:
                        event["data"] = json.loads(event["data"])
                        out.append(event)
                        if limit and len(out) >= limit:
                            break
                    event = {}
                elif not line.startswith(":"):
                    field, _, value = line.partition(": ")
                    event[field] = value
        return out

    def test_the_event_stream_relays_watchjob_and_resumes(self):
        job = self.client.solve(self.scene, method="progressive", snapshot_interval=0.05,
                                wait=True)
        job_id = job.name.split("/")[1]
        final = next(s for s in self.client.watch(job) if s.final)
        events = self.events(job_id)
        # Geometry before values; the final snapshot; then the call's status.
        self.assertEqual(events[0]["event"], "mesh")
        self.assertEqual(events[-1], {"event": "end", "data": {"code": "OK", "message": ""}})
        snapshots = [e for e in events if e["event"] == "snapshot"]
        last = snapshots[-1]["data"]
        self.assertTrue(last["final"])
        self.assertEqual(last["state"], "SUCCEEDED")
        self.assertEqual(int(snapshots[-1]["id"]), final.sequence)
        # The values, decoded as the page decodes them, are the gRPC API's (existing sides).
        values = np.concatenate([np.frombuffer(base64.b64decode(e["data"]["radiosity"]),
                                               dtype="<f4") for e in snapshots
                                 if e["data"]["sequence"] == final.sequence])
        expected = [final.radiosity[e, 0] for e in range(final.elements)]
        self.assertEqual(len(values), 3 * final.elements)  # One-sided walls: fronts only.
        np.testing.assert_array_equal(values.reshape(-1, 3), np.array(expected))
        mesh = events[0]["data"]
        self.assertEqual(mesh["elements"], final.elements)
        corners = np.frombuffer(base64.b64decode(mesh["corners"]), dtype="<f4")
        self.assertEqual(len(corners), 12 * min(final.elements, 8192))

        # Resuming after the final snapshot gives its state once more, without values; resuming
        # before it gives the mesh again, then the final values.
        again = self.events(job_id, {"Last-Event-ID": str(final.sequence)})
        self.assertEqual([e["event"] for e in again], ["snapshot", "end"])
        self.assertEqual(again[0]["data"]["radiosity"], "")
        resumed = self.events(job_id, {"Last-Event-ID": str(final.sequence - 1)})
        self.assertEqual(resumed[0]["event"], "mesh")
        self.assertEqual(int([e for e in resumed if "id" in e][-1]["id"]), final.sequence)
        with self.assertRaises(urllib.error.HTTPError) as caught:
            self.events(job_id, {"Last-Event-ID": "soon"})
        self.assertEqual(caught.exception.code, 400)

    def test_errors_are_shown_not_hidden(self):
        page = cdp.Page(self.browser, self.url + "#job=doesnotexist")
        error = page.wait_for(f"{STATE}.lastError", what="the page's error")
        self.assertIn("NOT_FOUND", error)
        self.assertIn("jobs/doesnotexist", error)
        with self.assertRaises(urllib.error.HTTPError) as caught:
            urllib.request.urlopen(self.url + "api/jobs/doesnotexist/events", timeout=10)
        self.assertEqual(caught.exception.code, 404)
        body = json.loads(caught.exception.read())
        self.assertEqual(body["error"]["code"], "NOT_FOUND")


class RestartPreviewTest(unittest.TestCase):
    def test_the_page_follows_a_job_across_a_server_restart(self):
        # A fixed preview port (a restarted server must be found at the same address).
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        server = Server("--http-port", str(port))
        browser = cdp.Browser()
        try:
            # The page is up before the job starts, so that it sees the job run however slowly
            # the browser starts; it opens the job when the address names it.
            page = cdp.Page(browser, f"http://127.0.0.1:{port}/")
            with radiosity.connect(server.address, timeout=60) as client:
                scene = client.upload(os.path.join(SCENES, "cornell_box.obj"))
                job = client.solve(scene, method="progressive", max_elements=60000,
                                   tolerance=1e-9, max_seconds=8, snapshot_interval=0.3)
            page.eval(f"location.hash = 'job={job.name.split('/')[1]}'")
            page.wait_for(f"{STATE}.snapshotsApplied >= 2 && {STATE}.jobState === 'RUNNING'",
                          what="snapshots before the restart")
            before = state(page)["appliedSequence"]
            server.restart()  # SIGTERM: the job is queued again and runs from the start.
            page.wait_for(f"{STATE}.final", timeout=120, what="the final snapshot after it")
            ended = state(page)
            self.assertGreater(ended["appliedSequence"], before)
            self.assertEqual(ended["jobState"], "SUCCEEDED")
            with radiosity.connect(server.address, timeout=60) as client:
                final = next(s for s in client.watch(job) if s.final)
            self.assertEqual(ended["appliedSequence"], final.sequence)
            self.assertAlmostEqual(ended["colorSum"], float(final.radiosity.sum(dtype=np.float64)),
                                   delta=1e-5 * ended["colorSum"])
        finally:
            browser.close()
            server.stop()


class SecurePreviewTest(unittest.TestCase):
    """HTTPS with the gRPC port's certificate, and the tenants of its bearer tokens."""

    def test_each_token_sees_its_tenants_jobs_only(self):
        with TenantPki() as pki:
            server = Server(*pki.server_flags, "--http-port", "0", log_level="info")
            browser = None
            try:
                url = f"https://localhost:{http_port(server)}/"
                ca = pki.ca
                with radiosity.connect(server.address, tls_ca=ca, token=ALICE) as alice:
                    scene = alice.upload(os.path.join(SCENES, "furnace.json"))
                    alices = alice.solve(scene, wait=True).name.split("/")[1]
                context = ssl.create_default_context(cafile=ca)

                def get(path, token=None):
                    request = urllib.request.Request(url + path)
                    if token:
                        request.add_header("Authorization", "Bearer " + token)
                    return urllib.request.urlopen(request, timeout=10, context=context)

                with self.assertRaises(urllib.error.HTTPError) as caught:
                    get("api/jobs")
                self.assertEqual(caught.exception.code, 401)
                self.assertEqual([j["id"] for j in json.load(get("api/jobs", ALICE))["jobs"]],
                                 [alices])
                self.assertEqual(json.load(get("api/jobs", BOB))["jobs"], [])
                with self.assertRaises(urllib.error.HTTPError) as caught:
                    get(f"api/jobs/{alices}/events", BOB)
                self.assertEqual(caught.exception.code, 404)
                # Plain HTTP to the HTTPS port.
                with self.assertRaises((urllib.error.URLError, OSError, http.client.HTTPException)):
                    urllib.request.urlopen(url.replace("https", "http") + "api/jobs", timeout=10)

                # Chromium trusts the test server's key alone (its SPKI hash).
                spki = subprocess.run(
                    f"openssl x509 -in {pki.server_cert} -pubkey -noout | "
                    "openssl pkey -pubin -outform der | openssl dgst -sha256 -binary | base64",
                    shell=True, check=True, capture_output=True, text=True).stdout.strip()
                browser = cdp.Browser(extra_flags=[f"--ignore-certificate-errors-spki-list={spki}"])
                page = cdp.Page(browser, url + f"#token={ALICE}&job={alices}")
                page.wait_for(f"{STATE}.final && {STATE}.snapshotsApplied >= 1",
                              what="alice's result")
                self.assertEqual([j["id"] for j in state(page)["jobs"]], [alices])
                self.assertNotIn(ALICE, page.eval("location.href"), "the token left the URL")
                bobs = cdp.Page(browser, url + f"#token={BOB}&job={alices}")
                self.assertIn("NOT_FOUND", bobs.wait_for(f"{STATE}.lastError", what="an error"))
                self.assertEqual(state(bobs)["snapshots"], 0)
            finally:
                if browser:
                    browser.close()
                server.stop()


if __name__ == "__main__":
    if not cdp.find_chromium():
        print("no chromium: skipped (deploy/packages-test.txt lists it)", file=sys.stderr)
        sys.exit(77)
    unittest.main()
