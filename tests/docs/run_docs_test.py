#!/usr/bin/env python3
"""run_docs.py fails a page whose block fails, naming it, and passes the same page corrected.

The page (broken_page.md) is the service example with the jq path that `solve --detach --json`
does not have (`.name`, where the line is {"event":"job","job":{...}}): the watch that follows
is refused. The same page with `.job.name` passes, and its checks hold.
Usage: run_docs_test.py BIN_DIR SOURCE_DIR
"""
import os
import subprocess
import sys
import tempfile
import unittest

BIN, SOURCE = sys.argv[1], sys.argv[2]
HERE = os.path.dirname(os.path.abspath(__file__))
RUNNER = os.path.join(HERE, "run_docs.py")


def run(page):
    return subprocess.run([sys.executable, RUNNER, "--bin", BIN, "--source", SOURCE, page],
                          capture_output=True, text=True, timeout=300)


class RunDocsTest(unittest.TestCase):
    def test_the_broken_jq_line_fails_its_page(self):
        proc = run(os.path.join(HERE, "broken_page.md"))
        self.assertEqual(proc.returncode, 1, proc.stdout + proc.stderr)
        self.assertIn("FAIL", proc.stderr)
        self.assertIn("broken_page.md:6:", proc.stderr)
        self.assertIn("jobs/null", proc.stderr)

    def test_the_corrected_page_passes_with_its_checks(self):
        with open(os.path.join(HERE, "broken_page.md")) as f:
            text = f.read()
        self.assertIn("jq -r .name)", text)
        fixed = text.replace("jq -r .name)", "jq -r .job.name)") + (
            "<!-- expect: succeeded|converged -->\n\n"
            "```sh runnable\nradiosity solve nosuch.obj --out out/x\n```\n"
            "<!-- expect-exit: 3 -->\n<!-- expect: nosuch.obj -->\n")
        with tempfile.TemporaryDirectory() as d:
            page = os.path.join(d, "fixed.md")
            with open(page, "w") as f:
                f.write(fixed)
            proc = run(page)
            self.assertEqual(proc.returncode, 0, proc.stdout + proc.stderr)
            self.assertEqual(proc.stdout.count("ok "), 2, proc.stdout)
            # A check that does not hold fails the page.
            with open(page, "w") as f:
                f.write(fixed.replace("<!-- expect-exit: 3 -->", "<!-- expect-exit: 4 -->"))
            proc = run(page)
            self.assertEqual(proc.returncode, 1, proc.stdout + proc.stderr)
            self.assertIn("exited 3, expected 4", proc.stderr)


if __name__ == "__main__":
    unittest.main(argv=sys.argv[:1])
