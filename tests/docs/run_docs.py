#!/usr/bin/env python3
"""Runs the runnable shell blocks of a Markdown page, as a reader following it would.

A block is runnable when its fence's info string is `sh runnable` or `bash runnable` (a
repository host still highlights it as shell). The runnable blocks of one page run in order, in
one bash process (variables and files carry from block to block, as in a reader's terminal),
with `set -euo pipefail`, in a fresh temporary directory that looks like the repository root:
every top-level entry of the source tree is linked into it, `build/bin` is the directory of the
built programs (and `build/python` the Python client the build assembles beside it), and those
programs come first on PATH. `out/` and anything else a block writes
stay in the temporary directory. Background processes a block starts (a server) are killed
when the page ends.

Checks written after a block's closing fence, as HTML comments (invisible on the host):
  <!-- expect: REGEX -->      the block's output (stdout and stderr) matches REGEX (re.search,
                             multiline); repeatable
  <!-- expect-exit: N -->     the block exits with N (it then runs in a subshell: variables it
                             sets do not carry)
A block without expect-exit must exit 0.

Usage: run_docs.py --bin DIR --source DIR [--timeout S] [--keep] PAGE.md
Exit code 0 when every block passed; 1 naming the page, the block's first line number, its
text, its output and what failed; 2 when the page has no runnable block.
"""

import argparse
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile

from fences import fenced_blocks
EXPECT = re.compile(r"^\s*<!--\s*expect:\s?(.*?)\s*-->\s*$")
EXPECT_EXIT = re.compile(r"^\s*<!--\s*expect-exit:\s*(\d+)\s*-->\s*$")


class Block:
    def __init__(self, line, text):
        self.line = line  # 1-based line of the opening fence
        self.text = text
        self.expect = []
        self.exit_code = 0


def parse(path):
    """The runnable blocks of the page at `path`, with the checks that follow each."""
    with open(path, encoding="utf-8") as f:
        lines = f.read().split("\n")
    blocks = []
    for fenced in fenced_blocks(lines):
        info = fenced.info
        if len(info) < 2 or info[0] not in ("sh", "bash") or "runnable" not in info[1:]:
            continue
        block = Block(fenced.start + 1, "\n".join(fenced.body(lines)) + "\n")
        i = fenced.end + 1  # the checks follow the closing fence
        while i < len(lines):
            e, x = EXPECT.match(lines[i]), EXPECT_EXIT.match(lines[i])
            if e:
                block.expect.append(e.group(1))
            elif x:
                block.exit_code = int(x.group(1))
            elif lines[i].strip():
                break
            i += 1
        blocks.append(block)
    return blocks


def make_root(source, bin_dir, root):
    """A directory that looks like the repository root with the programs built."""
    for name in os.listdir(source):
        if name in ("build", "out") or name.startswith("build-") or name == ".git":
            continue
        os.symlink(os.path.join(source, name), os.path.join(root, name))
    os.makedirs(os.path.join(root, "build"))
    os.symlink(os.path.abspath(bin_dir), os.path.join(root, "build", "bin"))
    # The Python client as the build assembles it (package and generated stubs).
    python = os.path.join(os.path.dirname(os.path.abspath(bin_dir)), "python")
    if os.path.isdir(python):
        os.symlink(python, os.path.join(root, "build", "python"))


def driver(blocks, state):
    """The bash script that runs every block, recording each one's output and exit code."""
    script = ["set -uo pipefail", "cd \"$DOCS_ROOT\""]
    for n, block in enumerate(blocks):
        path = os.path.join(state, f"{n}.sh")
        with open(path, "w", encoding="utf-8") as f:
            f.write(block.text)
        log, rc = os.path.join(state, f"{n}.log"), os.path.join(state, f"{n}.rc")
        if block.exit_code == 0:
            # In this shell, so that what it sets carries to the next block; `set -e` ends the
            # page at its first failing command.
            script.append(f"set -e; source '{path}' > '{log}' 2>&1 < /dev/null; set +e")
            script.append(f"echo 0 > '{rc}'")
        else:
            script.append(f"( set -e; source '{path}' ) > '{log}' 2>&1 < /dev/null")
            script.append(f"echo $? > '{rc}'")
    return "\n".join(script) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--bin", required=True, help="directory of the built programs")
    parser.add_argument("--source", required=True, help="the repository root")
    parser.add_argument("--timeout", type=float, default=900, help="seconds for the whole page")
    parser.add_argument("--keep", action="store_true", help="keep the temporary directory")
    parser.add_argument("page")
    args = parser.parse_args()

    blocks = parse(args.page)
    if not blocks:
        print(f"{args.page}: no runnable block (```sh runnable)", file=sys.stderr)
        return 2
    tmp = tempfile.mkdtemp(prefix="radiosity-docs-")
    root, state = os.path.join(tmp, "repo"), os.path.join(tmp, "state")
    os.makedirs(root)
    os.makedirs(state)
    make_root(os.path.abspath(args.source), args.bin, root)
    env = dict(os.environ)
    env["PATH"] = os.path.abspath(args.bin) + os.pathsep + env.get("PATH", "")
    env["DOCS_ROOT"] = root
    env["TMPDIR"] = tmp
    env.pop("RADIOSITY_TOKEN", None)
    proc = subprocess.Popen(["bash", "-c", driver(blocks, state)], env=env, cwd=root,
                            start_new_session=True)
    timed_out = False
    try:
        proc.wait(timeout=args.timeout)
    except subprocess.TimeoutExpired:
        timed_out = True
    finally:
        # The page's background processes (servers) end with it.
        try:
            os.killpg(proc.pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
        proc.wait()

    failures = 0
    for n, block in enumerate(blocks):
        where = f"{args.page}:{block.line}"
        log_path, rc_path = os.path.join(state, f"{n}.log"), os.path.join(state, f"{n}.rc")
        output = open(log_path, encoding="utf-8", errors="replace").read() \
            if os.path.exists(log_path) else ""
        problems = []
        if not os.path.exists(log_path):
            if failures == 0:
                problems.append("did not run: the page timed out before it" if timed_out
                                else "did not run")
            else:
                break  # an earlier block ended the page
        elif not os.path.exists(rc_path):
            problems.append("timed out" if timed_out else
                            "failed (the page's shell ended in it: a command exited non-zero)")
        else:
            rc = int(open(rc_path).read().strip() or "-1")
            if rc != block.exit_code:
                problems.append(f"exited {rc}, expected {block.exit_code}")
            for pattern in block.expect:
                if not re.search(pattern, output, re.MULTILINE):
                    problems.append(f"output does not match /{pattern}/")
        if problems:
            failures += 1
            print(f"FAIL {where}: {'; '.join(problems)}\n--- block\n{block.text}--- output\n"
                  f"{output[-6000:]}---", file=sys.stderr)
        else:
            print(f"ok   {where}")
    if args.keep:
        print(f"kept {tmp}", file=sys.stderr)
    else:
        shutil.rmtree(tmp, ignore_errors=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
